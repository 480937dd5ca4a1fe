"""The surrogate's PBM-facing calls without DataFrames: `frequency_matrix` and `encounters` predict
from a feature array (`pair_features`, `EnsembleMLPRegressorCV.predict_array`) and give what the
DataFrame path (`pair_table` -> `make_features` -> `predict`) gives, with the same out-of-domain
warnings."""

import warnings
from functools import partial

import numpy as np
import pandas as pd
import pytest
from synthetic_tables import make_synthetic_tables

from pbmdem.impact import WallRates
from pbmdem.surrogate import (
    CollisionSurrogate,
    EnsembleMLPRegressorCV,
    OutOfDomainWarning,
    training_data,
)
from pbmdem.surrogate import ensemble as ensemble_module
from pbmdem.surrogate.features import (
    FEATURE_NAMES,
    make_features,
    pair_features,
    pair_table,
)
from pbmdem.surrogate.tail import law_fractions, with_speed_tail
from pbmdem.surrogate.velocity import speed_fractions
from pbmdem.surrogate.walls import diagonal_features, wall_laws

R = 0.0265


@pytest.fixture(scope="module")
def data():
    table, velocity = make_synthetic_tables(R, diameters=(0.002, 0.003, 0.004, 0.006), seed=3)
    return training_data(table, R, velocity_table=velocity)


@pytest.fixture(
    scope="module",
    params=[((8,), "tanh", "cross_section"), ((6, 6), "relu", "none"), ((5,), "logistic", "cross_section")],
    ids=["tanh", "relu", "logistic"],
)
def fitted(request, data):
    hidden, activation, offset = request.param
    est = EnsembleMLPRegressorCV(
        hidden_layer_sizes=(hidden,), alpha=(0.1,), seeds=(0, 1), max_iter=200, activation=activation, solver="lbfgs"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return CollisionSurrogate(frequency_model=est, impeller_radius=R, physics_offset=offset).fit(
            data.X, data.y, groups=data.groups, velocity=data.velocity
        )


def frame_path(model):
    """The same fitted surrogate, forced onto the DataFrame path."""
    out = CollisionSurrogate(**model.get_params(deep=False))
    out.__dict__.update({k: v for k, v in vars(model).items() if k.endswith("_")})
    out._array_path = lambda: False
    return out


def recorded(fn):
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        out = fn()
    return out, [(w.category, str(w.message)) for w in rec]


def distributions():
    rng = np.random.default_rng(7)
    for k in (1, 2, 5, 12):
        # sizes and bed sizes inside and outside the training ranges (2-6 mm, 1200-3500 particles)
        d = np.sort(rng.uniform(1.5e-3, 1.2e-2, k))
        n = rng.uniform(0.0, 800.0, k)
        n[0] += 1.0
        yield d, n, float(rng.uniform(200.0, 1000.0))


def test_pair_features_are_the_feature_frame_of_the_pair_table():
    for d, n, rpm in distributions():
        X, iu, ju = pair_features(d, n, rpm, R)
        frame, iu2, ju2 = pair_table(d, n, rpm)
        np.testing.assert_array_equal(X, make_features(frame, R).to_numpy())
        np.testing.assert_array_equal(iu, iu2)
        np.testing.assert_array_equal(ju, ju2)
        assert X.flags.c_contiguous and X.shape[1] == len(FEATURE_NAMES)
    for bad in (([0.002, -0.003], [1.0, 1.0], 600.0), ([0.002], [0.0], 600.0), ([0.002], [1.0], 0.0)):
        with pytest.raises(ValueError):
            pair_features(*bad, R)


def test_frequency_matrix_and_encounters_equal_the_frame_path_with_the_same_warnings(fitted):
    slow = frame_path(fitted)
    for d, n, rpm in distributions():
        (fast_c, fast_s), fast_warn = recorded(partial(fitted.frequency_matrix, d, n, rpm, return_std=True))
        (slow_c, slow_s), slow_warn = recorded(partial(slow.frequency_matrix, d, n, rpm, return_std=True))
        fast_e, fast_warn_e = recorded(partial(fitted.encounters, d, n, rpm))
        slow_e, slow_warn_e = recorded(partial(slow.encounters, d, n, rpm))
        assert fast_warn == slow_warn and fast_warn_e == slow_warn_e
        for a, b in (
            (fast_c, slow_c),
            (fast_s, slow_s),
            (fast_e.frequency, slow_e.frequency),
            (fast_e.velocity_fractions, slow_e.velocity_fractions),
        ):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=0.0)
    # the distributions above include out-of-domain ones: the warnings were compared, not absent
    _, messages = recorded(partial(fitted.encounters, np.array([0.002, 0.011]), np.array([10.0, 5.0]), 600.0))
    assert any(c is OutOfDomainWarning and m.startswith("d_large = 0.011") for c, m in messages)


def test_predict_array_equals_predict(fitted):
    X, _, _ = pair_features(np.array([0.002, 0.003, 0.005]), np.array([900.0, 500.0, 200.0]), 600.0, R)
    for est in (fitted.frequency_model_, fitted.velocity_model_):
        mean, std = est.predict_array(X, return_std=True)
        ref_mean, ref_std = est.predict(pd.DataFrame(X, columns=list(FEATURE_NAMES)), return_std=True)
        np.testing.assert_allclose(mean, ref_mean, rtol=1e-12, atol=0.0)
        np.testing.assert_allclose(std, ref_std, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(est.predict_array(X), ref_mean, rtol=1e-12, atol=0.0)
    with pytest.raises(ValueError, match=rf"X must be \(n, {len(FEATURE_NAMES)}\)"):
        fitted.frequency_model_.predict_array(X[:, :5])


def test_array_path_is_one_stacked_forward_pass_per_model(fitted, monkeypatch):
    rows = []
    original = ensemble_module._members_forward

    def spy(ensemble, X):
        rows.append(len(X))
        return original(ensemble, X)

    monkeypatch.setattr(ensemble_module, "_members_forward", spy)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        fitted.encounters(np.linspace(0.002, 0.004, 5), np.full(5, 400.0), 600.0)
    assert rows == [15, 15]  # K (K + 1) / 2 pairs, one pass over all members of each model


def test_the_stacked_members_give_each_members_forward_pass_to_the_bit(fitted):
    # every member in one pass over the stacked weights (_members_forward) against each member's
    # scikit-learn predict, for each activation, one row and many
    rng = np.random.default_rng(5)
    for est in (fitted.frequency_model_, fitted.velocity_model_):
        for n in (1, 15, 120):
            X = rng.normal(0.0, 2.0, (n, est.n_features_in_))
            each = np.stack([m.predict(X) for m in est.estimators_])
            stacked = ensemble_module._members_forward(est, X)
            assert stacked.shape == each.shape and stacked.tobytes() == each.tobytes()


def test_a_surrogate_fitted_on_an_array_keeps_the_frame_path(data):
    est = EnsembleMLPRegressorCV(
        hidden_layer_sizes=((6,),), alpha=(0.1,), seeds=(0,), max_iter=200, activation="tanh", solver="lbfgs"
    )
    plain = CollisionSurrogate(frequency_model=est, impeller_radius=R)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain.fit(data.X.to_numpy(), data.y, groups=data.groups)
    assert not plain._array_path()
    d, n = np.array([0.002, 0.003]), np.array([800.0, 600.0])
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        c = plain.frequency_matrix(d, n, 600.0)
    # scikit-learn's feature-name warning of the frame path is still raised
    assert any("feature names" in str(w.message) for w in rec)
    frame, iu, ju = pair_table(d, n, 600.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        np.testing.assert_allclose(c[iu, ju], 10.0 ** plain.predict(make_features(frame, R).to_numpy()), rtol=1e-12)


@pytest.fixture(scope="module", params=["mlp", "kriging", "rsm"])
def with_walls(request, data):
    """A surrogate of each family whose wall models (bowl, impeller) are fitted like its pair model
    (on the pair tables, rescaled: what matters here is the path, not the data)."""
    from pbmdem.surrogate.families import KrigingRegressor, ResponseSurface

    def family():
        if request.param == "kriging":
            return KrigingRegressor(n_restarts_optimizer=0, n_members=3)
        if request.param == "rsm":
            return ResponseSurface(degree=(1, 2), n_members=3)
        return EnsembleMLPRegressorCV(
            hidden_layer_sizes=((6,),), alpha=(0.1,), seeds=(0, 1), max_iter=200, activation="relu", solver="lbfgs"
        )

    def fit(shift):
        model = CollisionSurrogate(frequency_model=family(), impeller_radius=R, physics_offset="cross_section")
        return model.fit(data.X, data.y + shift, groups=data.groups, velocity=data.velocity)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pairs = fit(0.0)
        pairs.wall_models_ = {"bowl": fit(1.0), "impeller": fit(1.5)}
    return pairs


def wall_rates(surrogate, diameters, numbers, rpm: float, check_domain: bool = True) -> WallRates:
    """:class:`pbmdem.impact.WallRates` of the classes from the surrogate's wall models on their own
    (``walls.wall_laws`` of the diagonal pairs' features, the walls' speed laws turned into bin
    fractions in one ``tail.law_fractions``): what ``CollisionSurrogate.impacts`` must give for the walls."""
    frequency, laws = wall_laws(
        surrogate, diagonal_features(diameters, numbers, rpm, surrogate.impeller_radius), check_domain
    )
    return WallRates(frequency, np.stack(law_fractions(laws)))


def test_wall_rates_equal_the_frame_path_for_every_family(with_walls):
    slow = frame_path(with_walls)
    slow.wall_models_ = {wall: frame_path(model) for wall, model in with_walls.wall_models_.items()}
    for d, n, rpm in distributions():
        fast, fast_warn = recorded(partial(wall_rates, with_walls, d, n, rpm))
        ref, ref_warn = recorded(partial(wall_rates, slow, d, n, rpm))
        assert fast_warn == ref_warn
        np.testing.assert_allclose(fast.frequency, ref.frequency, rtol=1e-12, atol=0.0)
        np.testing.assert_allclose(fast.velocity_fractions, ref.velocity_fractions, rtol=1e-12, atol=1e-300)
    # and the pair model of every family, through impacts()
    for d, n, rpm in distributions():
        fast, _ = recorded(partial(with_walls.impacts, d, n, rpm))
        ref, _ = recorded(partial(slow.impacts, d, n, rpm))
        np.testing.assert_allclose(fast.pairs.frequency, ref.pairs.frequency, rtol=1e-12, atol=0.0)
        np.testing.assert_allclose(fast.pairs.velocity_fractions, ref.pairs.velocity_fractions, rtol=1e-12, atol=1e-300)


def test_impacts_share_the_response_surfaces_terms_and_give_the_same_numbers(with_walls):
    # impacts() predicts the pairs and both walls inside _terms.shared_terms: response surfaces
    # of equal scalers and powers at equal features compute their terms once; the rates equal
    # those of encounters() and wall_rates() called on their own, to the bit (mean and a member)
    from pbmdem.surrogate import _terms, families

    for model in (with_walls, with_walls.member(0)):
        for d, n, rpm in distributions():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                shared = model.impacts(d, n, rpm)
                pairs, walls = model.encounters(d, n, rpm), wall_rates(model, d, n, rpm)
            for a, b in ((shared.pairs.frequency, pairs.frequency), (shared.walls.frequency, walls.frequency),
                         (shared.pairs.velocity_fractions, pairs.velocity_fractions),
                         (shared.walls.velocity_fractions, walls.velocity_fractions)):  # fmt: skip
                assert np.array_equal(a, b)
    if isinstance(with_walls.frequency_model_, families.ResponseSurface):
        d, n, rpm = next(distributions())
        with warnings.catch_warnings(), _terms.shared_terms():
            warnings.simplefilter("ignore")
            wall_rates(with_walls, d, n, rpm)
            computed = len(_terms.SHARED.get())
        models = [m for w in with_walls.wall_models_.values() for m in (w.frequency_model_, w.velocity_model_)]
        assert computed < sum(len(m.estimators_) for m in models)  # both walls' models fitted on the same rows


@pytest.fixture(scope="module")
def mixed_laws():
    """A generalised-gamma pair model with its pooled tail; a bowl model of the same law with another
    tail; an impeller model of the log-normal law without one (response surfaces)."""
    from synthetic_tables import make_synthetic_tables as tables

    from pbmdem.surrogate.families import ResponseSurface

    pairs, velocities = tables(R, rpms=(600.0, 900.0, 1200.0), sample_velocities=True, seed=4)

    def fit(law, tail_from, shift):
        data = training_data(pairs, R, velocity_table=velocities, speed_law=law)
        model = CollisionSurrogate(
            frequency_model=ResponseSurface(),
            impeller_radius=R,
            physics_offset="cross_section",
            feature_transform="log",
            speed_law=law,
            speed_tail_from=tail_from,
        )
        return model.fit(
            data.X, data.y + shift, data.groups, velocity=data.velocity, velocity_counts=data.velocity_counts
        )

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit("gengamma", 1.0, 0.0)
        bowl = fit("gengamma", 1.0, 1.0)
        bowl.speed_tail_ = (bowl.speed_tail_[0], 2.0 * bowl.speed_tail_[1], 1.3 * bowl.speed_tail_[2], 0.1)
        model.wall_models_ = {"bowl": bowl, "impeller": fit("lognormal", None, 1.5)}
    assert model.speed_tail_ is not None and model.wall_models_["impeller"].speed_tail_ is None
    return model


def own_fractions(model, X):
    """A model's bin fractions on its own: its speed law's fractions, then its own pooled tail."""
    law, tip, mu, sigma, shape, tail = model._pair_law(X)
    return with_speed_tail(speed_fractions(mu, sigma, law, shape), tip, tail)


def test_impacts_batched_speed_laws_equal_each_models_own_fractions(mixed_laws):
    # impacts() turns the pairs' and walls' speed laws into fractions in one speed_fractions call
    # per law (each model's tail on its own rows) and the walls predict from the diagonal of the
    # pairs' features: the same numbers as each model's own law and tail on its own features
    from pbmdem.surrogate.walls import diagonal_features

    for model in (mixed_laws, mixed_laws.member(0), mixed_laws.member(mixed_laws.n_members - 1)):
        for d, n, rpm in distributions():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                rates = model.impacts(d, n, rpm)
                X, iu, ju = pair_features(d, n, rpm, R)
                own = own_fractions(model, X)
                diagonal = diagonal_features(d, n, rpm, R)
                walls = [own_fractions(model.wall_models_[w], diagonal) for w in ("bowl", "impeller")]
                frequency = [10.0 ** model.wall_models_[w]._pair_log10(diagonal) for w in ("bowl", "impeller")]
            np.testing.assert_allclose(rates.pairs.velocity_fractions[iu, ju], own, rtol=1e-12, atol=0.0)
            np.testing.assert_allclose(rates.walls.velocity_fractions, np.stack(walls), rtol=1e-12, atol=0.0)
            np.testing.assert_allclose(rates.walls.frequency, np.stack(frequency), rtol=1e-12, atol=0.0)
            # the tails differ: the walls' fast bins are not the pairs' law with another scale
            assert not np.allclose(rates.walls.velocity_fractions[0], rates.walls.velocity_fractions[1])
