"""CollisionSurrogate and EnsembleMLPRegressorCV: law recovery, grouped CV, domain warnings, PBM interface,
baselines."""

import warnings

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.ensemble import HistGradientBoostingRegressor
from sklearn.exceptions import NotFittedError
from sklearn.metrics import mean_absolute_error, r2_score
from sklearn.model_selection import GridSearchCV, KFold
from sklearn.neural_network import MLPRegressor
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from synthetic_tables import make_synthetic_table, make_synthetic_tables, power_law

from pbmdem.surrogate import (
    FEATURE_NAMES,
    CollisionSurrogate,
    EnsembleMLPRegressorCV,
    HGBBaseline,
    OutOfDomainWarning,
    PhysicalScaling,
    cross_validate_models,
    grouped_splits,
    training_data,
)
from pbmdem.surrogate import ensemble as ensemble_module
from pbmdem.surrogate._threads import single_threaded
from pbmdem.surrogate.evaluation import default_baselines
from pbmdem.surrogate.features import make_features, pair_table
from pbmdem.surrogate.velocity import attach_velocity_bins

R = 0.0265  # impeller radius (m) of the synthetic tables and models
SMALL = dict(
    hidden_layer_sizes=((6,), (8,)),
    alpha=(0.01, 0.1),
    seeds=(0, 1, 2),
    max_iter=800,
    activation="tanh",
    solver="lbfgs",
    cv="group_kfold",
    n_splits=3,
)


def surrogate(**ensemble) -> CollisionSurrogate:
    return CollisionSurrogate(
        frequency_model=EnsembleMLPRegressorCV(**{**SMALL, **ensemble}),
        impeller_radius=R,
        physics_offset="cross_section",
    )


@pytest.fixture(scope="module")
def table():
    # 5 rpm x 4 size distributions = 20 DEM runs, 6 class pairs each, 3 replicates with lognormal
    # noise 0.03 decades each, impact-velocity bins attached
    return attach_velocity_bins(*make_synthetic_tables(R, seed=1, noise_log10=0.03))


@pytest.fixture(scope="module")
def data(table):
    return training_data(table, R)


@pytest.fixture(scope="module")
def fitted(data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return surrogate().fit(data.X, data.y, groups=data.groups, velocity=data.velocity)


def run_disjoint(splits, groups):
    groups = np.asarray(groups)
    return all(not (set(groups[tr]) & set(groups[te])) for tr, te in splits)


def test_recovers_known_law_on_held_out_runs(table, data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        metrics, pred = cross_validate_models(
            data, {"mlp": surrogate(), **default_baselines()}, cv="group_kfold", n_splits=5
        )
    pooled = metrics[
        (metrics["model"] == "mlp") & (metrics["fold"] == "pooled") & (metrics["target"] == "encounter_frequency")
    ].iloc[0]
    print(f"held-out grouped R2(log10) mlp = {pooled['r2_log10']:.4f}, MAE = {pooled['mae_log10']:.4f}")
    assert pooled["r2_log10"] > 0.95
    assert pooled["mae_log10"] < 0.06
    # every row predicted exactly once, by a model that never saw its run
    assert (pred["fold"] >= 0).all() and pred["mlp_log10"].notna().all()
    assert set(metrics["model"]) == {"mlp", "hgb", "physical"}
    # the replicate noise floor is reported next to the held-out R2 and lies above it here
    assert 0.95 < pooled["noise_floor_r2_log10"] <= 1.0
    assert {"pooled", "mean"} <= set(metrics["fold"])
    # the noise-free law is matched too (geometric mean of the ensemble)
    law = np.log10(
        power_law(
            pred["d_i"],
            pred["d_j"],
            pred["rpm"],
            table.set_index("point_id")["n_total"].groupby(level=0).first().reindex(pred["point_id"]).to_numpy(),
        )
    )
    assert r2_score(law, pred["mlp_log10"]) > 0.95


def test_fitted_attributes_and_conventions(fitted, data, table):
    params = fitted.get_params()
    assert params["frequency_model__seeds"] == (0, 1, 2) and params["impeller_radius"] == R
    assert clone(fitted).get_params(deep=False).keys() == params.keys() - {k for k in params if "__" in k}
    freq = fitted.frequency_model_
    assert freq is not fitted.frequency_model and not hasattr(fitted.frequency_model, "estimators_")  # cloned
    assert len(freq.estimators_) == 3 and list(freq.n_iter_ >= 1) == [True] * 3
    assert list(fitted.feature_names_in_) == list(FEATURE_NAMES) and fitted.n_features_in_ == len(FEATURE_NAMES)
    assert set(freq.best_params_) == {"hidden_layer_sizes", "alpha"}
    assert len(freq.cv_results_["params"]) == 4
    # the chosen candidate lies within one standard error of the best score (one-standard-error rule)
    scores = freq.cv_results_["mean_test_score"]
    top = int(np.argmax(scores))
    se = freq.cv_results_["std_test_score"][top] / np.sqrt(len(freq.cv_folds_))
    assert scores[top] - se <= freq.best_score_ <= scores[top]
    assert [name for name, _ in freq.estimators_[0].steps] == ["scale", "mlp"]
    assert fitted.has_velocity_model() and fitted.velocity_model_.n_outputs_ == 2
    assert fitted.n_training_rows_ == fitted.n_velocity_rows_ == len(data.y)
    assert fitted.training_point_ids_ == sorted(table["point_id"].unique())
    with pytest.raises(NotFittedError):
        surrogate().predict(data.X)
    # sklearn conventions: predict is in the units of y (log10 1/s), score is R2 on y
    p = fitted.predict(data.X, check_domain=False)
    assert p.shape == (len(data.y),)
    assert r2_score(data.y, p) == pytest.approx(fitted.score(data.X, data.y)) and fitted.score(data.X, data.y) > 0.95
    # a collision table gives the same as its feature frame
    np.testing.assert_array_equal(
        fitted.predict_log10(table, check_domain=False), fitted.predict(make_features(table, R), check_domain=False)
    )


def test_ensemble_spread_returned(fitted, data):
    value, std = fitted.predict(data.X, return_std=True)
    assert value.shape == std.shape == (len(data.y),)
    assert (std >= 0).all() and (std > 0).any()
    members = np.stack([m.predict(data.X.to_numpy()) for m in fitted.frequency_model_.estimators_])
    assert np.allclose(std, members.std(axis=0, ddof=1))
    # the physics offset is added back: members learn log10 c - 2 log10(d_small + d_large in mm)
    offset = 2 * np.log10(1e3 * (data.X["d_small"] + data.X["d_large"])).to_numpy()
    assert np.allclose(value, members.mean(axis=0) + offset)


def test_search_folds_hold_out_whole_runs(fitted, table):
    folds = fitted.frequency_model_.cv_folds_
    assert len(folds) == 3
    held = [pid for fold in folds for pid in fold]
    assert sorted(held) == sorted(table["point_id"].unique())  # every run tested exactly once
    groups = table["point_id"].to_numpy()
    for strategy in ("leave_one_group_out", "group_kfold"):
        splits = grouped_splits(groups, strategy, n_splits=4)
        assert run_disjoint(splits, groups)
        assert all(len(set(groups[te])) >= 1 for _, te in splits)
    # the check itself would catch a plain KFold leak
    leaky = list(KFold(5, shuffle=True, random_state=0).split(groups))
    assert not run_disjoint(leaky, groups)


def test_leaked_cv_is_over_optimistic_grouped_cv_is_not():
    # a per-run random offset (0.3 decades) that no feature explains: a model can only learn it
    # from rows of the same run, i.e. when runs leak between train and test (6 classes: 21 rows
    # per run, so a leaked fold has seen most of every run)
    t = make_synthetic_table(
        R, seed=5, noise_log10=0.01, run_noise_log10=0.3, diameters=(0.0015, 0.002, 0.0025, 0.003, 0.0035, 0.004)
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # frequency-only table
        d = training_data(t, R)
    X, y, groups = d.X.to_numpy(), d.y, d.groups

    def cv_mae(splits):  # features from the complete runs, then split rows
        err = []
        for tr, te in splits:
            with single_threaded():  # tiny data: threads only add contention
                m = HistGradientBoostingRegressor(min_samples_leaf=2, random_state=0).fit(X[tr], y[tr])
                err.append(mean_absolute_error(y[te], m.predict(X[te])))
        return float(np.mean(err))

    grouped = cv_mae(grouped_splits(groups, "group_kfold", 5))
    leaked = cv_mae(list(KFold(5, shuffle=True, random_state=0).split(X)))
    assert leaked < 0.5 * grouped, (leaked, grouped)


def test_out_of_domain_warning(fitted, table):
    with warnings.catch_warnings():
        warnings.simplefilter("error", OutOfDomainWarning)
        fitted.predict_log10(table)  # training rows are in domain
        frame = table[table["point_id"] == table["point_id"].iloc[0]]
        fitted.predict_log10(frame)
    fast = table.copy()
    fast["rpm"] = 2000
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        fitted.predict_log10(fast)
    messages = [str(w.message) for w in rec if issubclass(w.category, OutOfDomainWarning)]
    # rpm is not a feature (it duplicates tip speed); tip speed carries the warning
    v_lo, v_hi = fitted.feature_ranges()["tip_speed"]
    assert any(m.startswith("tip_speed = 5.5") and f"[{v_lo:.6g}, {v_hi:.6g}]" in m for m in messages)
    assert not any(m.startswith("d_small") for m in messages)  # only the offending features
    lo, hi = fitted.feature_ranges()["d_large"]
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        fitted.frequency_matrix([0.002, 0.003, 0.008], [1500, 800, 100], 600)
    messages = [str(w.message) for w in rec if issubclass(w.category, OutOfDomainWarning)]
    assert any(m.startswith("d_large = 0.008") and f"[{lo:.6g}, {hi:.6g}]" in m for m in messages)
    assert issubclass(OutOfDomainWarning, UserWarning)
    # sklearn's predict on the feature matrix warns the same way
    with pytest.warns(OutOfDomainWarning, match="tip_speed = 5.5"):
        fitted.predict(make_features(fast, R))
    # a relative margin widens the domain
    lenient = clone(fitted).set_params(domain_margin=0.5)
    lenient.__dict__.update({k: v for k, v in vars(fitted).items() if k.endswith("_")})
    assert fitted.out_of_domain(make_features(table.assign(rpm=1000), R)).any().any()
    assert not lenient.out_of_domain(make_features(table.assign(rpm=1000), R)).any().any()


def test_frequency_matrix_shape_symmetry_positivity(fitted):
    d = np.array([0.002, 0.003, 0.004])
    n = np.array([1500.0, 700.0, 300.0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        c, s = fitted.frequency_matrix(d, n, 600, return_std=True)
        c_rev = fitted.frequency_matrix(d[::-1], n[::-1], 600)
        c_call = fitted(d, n, 600)
    assert c.shape == s.shape == (3, 3)
    assert np.allclose(c, c.T) and np.allclose(s, s.T)
    assert (c > 0).all() and np.isfinite(c).all()
    assert np.allclose(c_rev, c[::-1, ::-1])  # class order does not matter
    assert np.allclose(c_call, c)
    # the PBM kernel is 10 ** predict on the pairs' features (1/s per pair)
    frame, iu, ju = pair_table(d, n, 600)
    assert np.allclose(c[iu, ju], 10.0 ** fitted.predict(make_features(frame, R), check_domain=False))
    # bigger pairs collide more often at this law, faster impeller too
    assert c[2, 2] > c[0, 0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        assert (fitted.frequency_matrix(d, n, 900) > c).all()
        one = fitted.frequency_matrix([0.003], [2000], 600)
    assert one.shape == (1, 1)
    with pytest.raises(ValueError):
        fitted.frequency_matrix(d, n[:2], 600)


def test_frequency_matrix_is_one_vectorised_predict(fitted, monkeypatch):
    calls = []
    original = ensemble_module._members_forward

    def spy(ensemble, X):
        calls.append((ensemble.n_members_, len(X)))
        return original(ensemble, X)

    monkeypatch.setattr(ensemble_module, "_members_forward", spy)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        fitted.frequency_matrix(np.linspace(0.002, 0.004, 5), np.full(5, 400.0), 600)
    # K (K + 1) / 2 pairs, one pass over all members
    assert calls == [(len(fitted.frequency_model_.estimators_), 15)]


def test_invalid_fit_inputs_are_refused_before_fitting(data):
    with pytest.raises(ValueError, match=r"named features \['d_small', 'd_large', 'tip_speed'\]"):
        surrogate().fit(data.X.to_numpy(), data.y)
    with pytest.raises(ValueError, match="physics_offset = 'kinetic'; allowed"):
        surrogate().set_params(physics_offset="kinetic").fit(data.X, data.y)
    with pytest.raises(ValueError, match=r"velocity must have shape \(n_samples, 2\)"):
        surrogate().fit(data.X, data.y, velocity=data.velocity[:, :1])
    with pytest.raises(ValueError, match="groups must be 1-d with one entry per sample"):
        surrogate().fit(data.X, data.y, groups=data.groups[:-1])


def test_physical_scaling_constant(data):
    phys = PhysicalScaling().fit(data.X, data.y, groups=data.groups, velocity=data.velocity)
    resid = data.y - phys.predict(data.X)
    assert abs(resid.mean()) < 1e-12  # least squares in log space: mean residual zero
    assert list(phys.feature_names_in_) == list(FEATURE_NAMES)
    frame, iu, ju = pair_table([0.002, 0.004], [1000, 500], 600)
    c = 10.0 ** phys.predict(make_features(frame, R))
    # c ~ (d_i + d_j)^2 v_tip: ratio of the diagonal entries is ((4+4)/(2+2))^2, doubling the speed doubles c
    assert c[2] / c[0] == pytest.approx(4.0)
    faster = 10.0 ** phys.predict(make_features(pair_table([0.002, 0.004], [1000, 500], 1200)[0], R))
    assert np.allclose(faster / c, 2.0)
    # one log-normal speed law for all pairs: median proportional to the tip speed
    mu, sigma = phys.predict_velocity(data.X)
    assert np.allclose(mu - np.log10(data.X["tip_speed"]), phys.log10_speed_ratio_) and np.ptp(sigma) == 0
    # an array is read as the columns FEATURE_NAMES; other arrays are refused, naming the features
    np.testing.assert_array_equal(
        PhysicalScaling().fit(data.X.to_numpy(), data.y).predict(data.X.to_numpy()), phys.predict(data.X)
    )
    with pytest.raises(ValueError, match=r"needs the features \['d_small', 'd_large', 'tip_speed'\]"):
        PhysicalScaling().fit(data.X.to_numpy()[:, :3], data.y)
    with pytest.raises(ValueError, match="lacks \\['tip_speed'\\]"):
        PhysicalScaling().fit(data.X.drop(columns="tip_speed"), data.y)
    with pytest.raises(ValueError, match="without impact-velocity targets"):
        PhysicalScaling().fit(data.X, data.y).predict_velocity(data.X)


def test_hgb_baseline_on_the_feature_matrix(data):
    hgb = HGBBaseline(random_state=0).fit(data.X, data.y, groups=data.groups)
    assert hgb.n_features_in_ == len(FEATURE_NAMES) and hgb.score(data.X, data.y) > 0.9
    # the trees themselves, with the leaf size capped at half the rows
    tiny = HGBBaseline().fit(data.X.iloc[:6], data.y[:6])
    assert tiny.model_.min_samples_leaf == 3


def test_ensemble_search_is_a_grouped_grid_search(data):
    """EnsembleMLPRegressorCV: the same search as GridSearchCV on explicit grouped folds, then one
    member per seed with the chosen values."""
    est = EnsembleMLPRegressorCV(
        hidden_layer_sizes=((4,), (6,)),
        alpha=(0.01, 1.0),
        seeds=(7, 8),
        max_iter=300,
        activation="tanh",
        solver="lbfgs",
        cv="group_kfold",
        n_splits=3,
    )
    X, y = data.X.to_numpy(), data.y
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est.fit(X, y, groups=data.groups)
        pipe = Pipeline(
            [
                ("scale", StandardScaler()),
                ("mlp", MLPRegressor(activation="tanh", solver="lbfgs", max_iter=300, random_state=7)),
            ]
        )
        ref = GridSearchCV(
            pipe,
            {"mlp__hidden_layer_sizes": [(4,), (6,)], "mlp__alpha": [0.01, 1.0]},
            cv=grouped_splits(data.groups, "group_kfold", 3),
            scoring="neg_mean_squared_error",
            refit=False,
        ).fit(X, y)
        # the one-standard-error rule on the search's scores: the simplest candidate within one
        # standard error of the best (written out here: fewest weights, then the largest alpha)
        mean, std = ref.cv_results_["mean_test_score"], ref.cv_results_["std_test_score"]
        top = int(np.argmax(mean))
        near = [k for k in range(len(mean)) if mean[k] >= mean[top] - std[top] / np.sqrt(3)]
        cand = ref.cv_results_["params"]
        k = min(near, key=lambda k: (cand[k]["mlp__hidden_layer_sizes"][0], -cand[k]["mlp__alpha"]))
        member = (
            clone(pipe)
            .set_params(
                mlp__hidden_layer_sizes=cand[k]["mlp__hidden_layer_sizes"],
                mlp__alpha=cand[k]["mlp__alpha"],
                mlp__random_state=8,
            )
            .fit(X, y)
        )
    assert est.best_score_ == mean[k]
    assert est.best_params_ == {
        "hidden_layer_sizes": cand[k]["mlp__hidden_layer_sizes"],
        "alpha": cand[k]["mlp__alpha"],
    }
    np.testing.assert_array_equal(est.cv_results_["mean_test_score"], ref.cv_results_["mean_test_score"])
    np.testing.assert_array_equal(est.estimators_[1].predict(X), member.predict(X))
    assert not hasattr(est, "feature_names_in_") and est.n_features_in_ == X.shape[1]


def test_ensemble_without_groups_uses_the_first_candidate_and_takes_2d_targets(data):
    est = EnsembleMLPRegressorCV(
        hidden_layer_sizes=((4,), (6,)), alpha=(0.1, 1.0), seeds=(0, 1), max_iter=300, activation="tanh", solver="lbfgs"
    )
    Y = np.column_stack([data.y, 2 * data.y])
    with pytest.warns(UserWarning, match="no groups given: no grouped hyperparameter search"):
        est.fit(data.X, Y)
    assert est.best_params_ == {"hidden_layer_sizes": (4,), "alpha": 0.1} and est.cv_results_ is None
    assert np.isnan(est.best_score_) and est.cv_folds_ == [] and est.n_outputs_ == 2
    mean, std = est.predict(data.X, return_std=True)
    assert mean.shape == std.shape == Y.shape and (std > 0).any()
    assert list(est.feature_names_in_) == list(FEATURE_NAMES)
    with pytest.warns(UserWarning, match="only one group"):
        clone(est).fit(data.X, Y, groups=np.full(len(Y), "rpm600_a"))
    with pytest.raises(ValueError, match="cv must be one of"):
        clone(est).set_params(cv="kfold").fit(data.X, Y)
    with pytest.raises(ValueError, match="seeds needs at least one seed"):
        clone(est).set_params(seeds=()).fit(data.X, Y)
