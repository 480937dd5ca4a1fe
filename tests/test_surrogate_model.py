"""CollisionSurrogate: law recovery, grouped CV, domain warnings, PBM interface, baselines."""

import warnings

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.ensemble import HistGradientBoostingRegressor
from sklearn.exceptions import NotFittedError
from sklearn.metrics import mean_absolute_error, r2_score
from sklearn.model_selection import KFold

from pbmdem.surrogate import (
    FEATURE_NAMES,
    CollisionSurrogate,
    OutOfDomainWarning,
    PhysicalScaling,
    cross_validate_models,
    grouped_splits,
)
from pbmdem.surrogate._threads import single_threaded
from pbmdem.surrogate.features import TARGET_NAME, make_features, prepare_training_table
from pbmdem.surrogate.synthetic import make_synthetic_table, make_synthetic_tables, power_law
from pbmdem.surrogate.velocity import attach_velocity_bins

SMALL = dict(hidden_layer_sizes=((6,), (8,)), alpha=(0.01, 0.1), ensemble_size=3, max_iter=800,
             cv="group_kfold", n_splits=3)


@pytest.fixture(scope="module")
def table():
    # 5 rpm x 4 size distributions = 20 DEM runs, 6 class pairs each, 3 replicates with lognormal
    # noise 0.03 decades each, impact-velocity bins attached
    return attach_velocity_bins(*make_synthetic_tables(seed=1, noise_log10=0.03))


@pytest.fixture(scope="module")
def fitted(table):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return CollisionSurrogate(**SMALL).fit(table)


def run_disjoint(splits, groups):
    groups = np.asarray(groups)
    return all(not (set(groups[tr]) & set(groups[te])) for tr, te in splits)


def test_recovers_known_law_on_held_out_runs(table):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        metrics, pred = cross_validate_models(table, CollisionSurrogate(**SMALL), cv="group_kfold", n_splits=5)
    pooled = metrics[(metrics["model"] == "mlp") & (metrics["fold"] == "pooled")
                     & (metrics["target"] == "encounter_frequency")].iloc[0]
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
    law = np.log10(power_law(pred["d_i"], pred["d_j"], pred["rpm"],
                             table.set_index("point_id")["n_total"].groupby(level=0).first()
                             .reindex(pred["point_id"]).to_numpy()))
    assert r2_score(law, pred["mlp_log10"]) > 0.95


def test_fitted_attributes_and_conventions(fitted, table):
    params = fitted.get_params()
    assert params["ensemble_size"] == 3 and "alpha" in params
    assert clone(fitted).get_params() == params
    assert len(fitted.estimators_) == 3 and fitted.seeds_ == [0, 1, 2]
    assert fitted.feature_names_ == FEATURE_NAMES and fitted.n_features_in_ == len(FEATURE_NAMES)
    assert set(fitted.best_params_) == {"hidden_layer_sizes", "alpha"}
    assert len(fitted.search_results_) == 4
    pipe = fitted.estimators_[0]
    assert [name for name, _ in pipe.steps] == ["scale", "mlp"]
    with pytest.raises(NotFittedError):
        CollisionSurrogate().predict(table)
    p = fitted.predict(table, check_domain=False)
    assert p.shape == (len(table),) and (p > 0).all()
    # physical units: the geometric ensemble mean of the log10 predictions
    assert np.allclose(np.log10(p), fitted.predict_log10(table, check_domain=False))
    assert fitted.score(table) > 0.95


def test_ensemble_spread_returned(fitted, table):
    value, std = fitted.predict(table, return_std=True)
    assert value.shape == std.shape == (len(table),)
    assert (std >= 0).all() and (std > 0).any()
    members = np.stack([m.predict(make_features(table).to_numpy()) for m in fitted.estimators_])
    assert np.allclose(std, members.std(axis=0, ddof=1))


def test_search_folds_hold_out_whole_runs(fitted, table):
    folds = fitted.cv_folds_
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
    t = make_synthetic_table(seed=5, noise_log10=0.01, run_noise_log10=0.3,
                             diameters=(0.0015, 0.002, 0.0025, 0.003, 0.0035, 0.004))
    data = prepare_training_table(t)
    X = make_features(data).to_numpy()
    y = data[TARGET_NAME].to_numpy()
    groups = data["point_id"].to_numpy()

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
        fitted.predict(table)  # training rows are in domain
        frame = table[table["point_id"] == table["point_id"].iloc[0]]
        fitted.predict(frame)
    fast = table.copy()
    fast["rpm"] = 2000
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        fitted.predict(fast)
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
    # a relative margin widens the domain
    lenient = clone(fitted).set_params(domain_margin=0.5)
    for attr in ("estimators_", "feature_min_", "feature_max_", "feature_names_"):
        setattr(lenient, attr, getattr(fitted, attr))
    assert not lenient.out_of_domain(make_features(table.assign(rpm=1000))).any().any()


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
    for est in fitted.estimators_:
        original = est.predict

        def spy(X, _orig=original):
            calls.append(len(X))
            return _orig(X)

        monkeypatch.setattr(est, "predict", spy)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        fitted.frequency_matrix(np.linspace(0.002, 0.004, 5), np.full(5, 400.0), 600)
    assert calls == [15] * len(fitted.estimators_)  # K (K + 1) / 2 pairs, one call per member


def test_physical_scaling_constant(table):
    clean = table.copy()
    phys = PhysicalScaling().fit(clean)
    resid = np.log10(clean["encounter_frequency_per_pair"]) - phys.predict_log10(clean)
    assert abs(resid.mean()) < 1e-12  # least squares in log space: mean residual zero
    c = phys.frequency_matrix([0.002, 0.004], [1000, 500], 600)
    assert np.allclose(c, c.T) and c[1, 1] > c[0, 0]
    # c ~ (d_i + d_j)^2 v_tip / V_solid: ratio of the diagonal entries is ((4+4)/(2+2))^2
    assert c[1, 1] / c[0, 0] == pytest.approx(4.0)
    assert phys.frequency_matrix([0.002, 0.004], [1000, 500], 1200)[0, 0] / c[0, 0] == pytest.approx(2.0)
