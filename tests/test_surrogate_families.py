"""The surrogate's model families side by side: recovery of a known law, reproducibility, coverage."""

from __future__ import annotations

import dataclasses
import os
import platform
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from sklearn.base import clone
from synthetic_tables import make_synthetic_tables, power_law
from threadpoolctl import threadpool_limits

from pbmdem.config import Surrogate
from pbmdem.surrogate import (
    CollisionSurrogate,
    KrigingRegressor,
    ResponseSurface,
    cross_validate_models,
    load_surrogate,
    save_surrogate,
    select_family,
    summarise,
    training_data,
)
from pbmdem.surrogate.calibration import (
    calibration_scale,
    coverage,
    cross_fitted_coverage,
    interval_z,
    member_quantiles,
    run_calibration_scale,
)
from pbmdem.surrogate.evaluation import default_baselines, sample_scores, select_per_target
from pbmdem.surrogate.settings import FAMILIES, build_families
from pbmdem.surrogate.velocity import tail_error

R = 0.0265
#: Small but complete settings: every family, fast MLP candidates, 3 outer folds.
SETTINGS = Surrogate.from_section(
    {
        "hidden_layer_sizes": [[6]],
        "alpha": [0.1],
        "ensemble_size": 3,
        "max_iter": 1000,
        "cv": {"strategy": "group_kfold", "n_splits": 4},
        "kriging": {"n_restarts_optimizer": 2},
        "speed_law": "lognormal",  # the synthetic tables' known law
    }
).to_dict()


@pytest.fixture(scope="module")
def data():
    table, velocity = make_synthetic_tables(R, rpms=(300, 600, 900), seed=3)
    return training_data(table, R, velocity_table=velocity)


@pytest.fixture(scope="module")
def cv_result(data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cross_validate_models(
            data, {**build_families(SETTINGS, R), **default_baselines()}, cv="group_kfold", n_splits=4
        )


def test_every_family_recovers_the_known_law_on_held_out_runs(cv_result, data):
    metrics, pred = cv_result
    summary = summarise(metrics)
    floor = summary["mlp"]["noise_floor_r2_log10"]
    for name in FAMILIES:
        s = summary[name]
        print(f"{name}: held-out R2 {s['pooled_r2_log10']:.4f} (floor {floor:.4f}), MAE {s['pooled_mae_log10']:.4f}")
        # the synthetic law is smooth (a power law): each family reaches the replicate noise floor closely
        assert s["pooled_r2_log10"] > floor - 0.02, name
        assert s["pooled_mae_log10"] < 0.04, name
    # and every family beats the baselines on the same folds
    for name in FAMILIES:
        assert summary[name]["pooled_r2_log10"] > summary["hgb"]["pooled_r2_log10"]
        assert summary[name]["pooled_r2_log10"] > summary["physical"]["pooled_r2_log10"]
    # the predictions match the noise-free law (not only the noisy replicate means)
    n_total = data.table.groupby("point_id")["n_total"].first().reindex(pred["point_id"]).to_numpy()
    law = np.log10(power_law(pred["d_i"], pred["d_j"], pred["rpm"], n_total))
    for name in FAMILIES:
        assert np.mean(np.abs(pred[f"{name}_log10"] - law)) < 0.03, name
    # the impact-speed law too
    vel = summarise(metrics, "impact_velocity")
    for name in FAMILIES:
        assert vel[name]["pooled_r2_log10"] > 0.9, name


def test_families_report_coverage_and_are_selected_by_held_out_score(cv_result):
    metrics, pred = cv_result
    pooled = metrics[(metrics["fold"] == "pooled") & (metrics["target"] == "encounter_frequency")].set_index("model")
    for name in FAMILIES:
        row = pooled.loc[name]
        assert 0 < row["coverage_90"] <= 1 and 0 < row["coverage_90_calibrated"] <= 1
        assert row["uncertainty_scale"] > 0
        # the figures are what the predictions give
        obs, p, s = pred["log10_encounter_frequency_per_pair"], pred[f"{name}_log10"], pred[f"{name}_std_log10"]
        assert row["coverage_90"] == pytest.approx(coverage(obs, p, s))
        assert row["uncertainty_scale"] == pytest.approx(calibration_scale(obs, p, s))
    assert pooled.loc[["hgb", "physical"], "coverage_90"].isna().all()
    best = pooled.loc[list(FAMILIES), "r2_log10"].idxmax()
    assert select_family(metrics, FAMILIES) == best


def test_selection_prefers_the_earlier_family_on_a_tie():
    metrics = pd.DataFrame(
        {
            "target": "encounter_frequency",
            "fold": "pooled",
            "model": ["mlp", "kriging", "rsm"],
            "r2_log10": [0.95, 0.97, 0.97],
        }
    )
    assert select_family(metrics, ("mlp", "kriging", "rsm")) == "kriging"
    assert select_family(metrics, ("rsm", "kriging")) == "rsm"
    metrics.loc[0, "r2_log10"] = 0.99
    assert select_family(metrics, ("mlp", "kriging", "rsm")) == "mlp"


def test_coverage_and_calibration_on_known_noise():
    rng = np.random.default_rng(0)
    n = 20000
    mean = rng.normal(size=n)
    sigma = rng.uniform(0.05, 0.2, size=n)
    y = mean + sigma * rng.normal(size=n)
    # the right standard deviation covers the nominal 90 %
    assert coverage(y, mean, sigma) == pytest.approx(0.90, abs=0.01)
    # a standard deviation half as large covers P(|z| <= 0.82) = 59 %; calibration finds the factor 2
    assert coverage(y, mean, sigma / 2) == pytest.approx(0.588, abs=0.01)
    assert calibration_scale(y, mean, sigma / 2) == pytest.approx(2.0, rel=0.03)
    folds = np.arange(n) % 5
    assert cross_fitted_coverage(y, mean, sigma / 2, folds) == pytest.approx(0.90, abs=0.01)
    assert interval_z() == pytest.approx(1.6449, abs=1e-4)
    # rows without a usable standard deviation are left out; none left: NaN
    assert np.isnan(coverage(y[:3], mean[:3], np.zeros(3)))
    assert np.isnan(calibration_scale(y[:1], mean[:1], sigma[:1]))


@pytest.mark.parametrize("family", FAMILIES)
def test_refits_do_not_depend_on_the_thread_count(data, family):
    model = build_families(SETTINGS, R)[family]
    fits = []
    for threads in (1, 2):
        with threadpool_limits(limits=threads), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fitted = clone(model).fit(data.X, data.y, groups=data.groups, velocity=data.velocity)
            fits.append(
                (
                    fitted.predict(data.X, return_std=True, check_domain=False),
                    fitted.predict_velocity(data.X, check_domain=False),
                )
            )
    (c1, s1), (mu1, sg1) = fits[0]
    (c2, s2), (mu2, sg2) = fits[1]
    for a, b in ((c1, c2), (s1, s2), (mu1, mu2), (sg1, sg2)):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=0)


@pytest.mark.parametrize("family", FAMILIES)
def test_held_out_score_is_stable_under_tiny_target_perturbations(data, family):
    model = build_families(SETTINGS, R)[family]
    rng = np.random.default_rng(1)
    scores = []
    for eps in (0.0, 1e-9):
        perturbed = dataclasses.replace(data, y=data.y * (1 + eps * rng.standard_normal(len(data.y))))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            metrics, _ = cross_validate_models(perturbed, {family: model}, cv="group_kfold", n_splits=4)
        scores.append(summarise(metrics)[family]["pooled_r2_log10"])
    print(f"{family}: held-out R2 {scores[0]:.6f} vs {scores[1]:.6f} with targets perturbed by 1e-9")
    assert abs(scores[0] - scores[1]) <= 0.005


@pytest.mark.parametrize("cls, params", [(KrigingRegressor, {}), (ResponseSurface, {"degree": 2})])
def test_closed_form_families_give_their_predictive_spread_and_members(cls, params):
    rng = np.random.default_rng(2)
    X = rng.uniform(-1, 1, size=(60, 3))
    y = np.column_stack([1 + X[:, 0] - 0.5 * X[:, 1] ** 2, X[:, 2]]) + 0.01 * rng.normal(size=(60, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = cls(n_members=4, **params).fit(X, y)
    mean, std = model.predict(X, return_std=True)
    assert mean.shape == std.shape == (60, 2) and (std > 0).all()
    assert np.sqrt(np.mean((mean - y) ** 2)) < 0.05  # the quadratic law is within reach of both
    np.testing.assert_allclose(model.predict_array(X), mean, rtol=1e-12)
    single = cls(**params).fit(X, y[:, 0])
    assert single.predict(X).shape == (60,) and single.n_members_ == 5 and model.n_members_ == 4


def test_members_follow_the_calibrated_scale(data):
    model = build_families(SETTINGS, R)["kriging"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fitted = clone(model).fit(data.X, data.y, groups=data.groups, velocity=data.velocity)
        wide = clone(model).set_params(uncertainty_scale=2.0).fit(data.X, data.y, groups=data.groups)
    d, n = np.array([0.002, 0.003, 0.004]), np.array([900.0, 600.0, 400.0])
    c, s = fitted.frequency_matrix(d, n, 600, return_std=True, check_domain=False)
    cw, sw = wide.frequency_matrix(d, n, 600, return_std=True, check_domain=False)
    np.testing.assert_allclose(cw, c, rtol=1e-12)
    np.testing.assert_allclose(sw, 2 * s, rtol=1e-12)
    z = member_quantiles(fitted.n_members)
    for k in (0, fitted.n_members - 1):
        ck = fitted.member(k).frequency_matrix(d, n, 600, check_domain=False)
        cwk = wide.member(k).frequency_matrix(d, n, 600, check_domain=False)
        np.testing.assert_allclose(np.log10(ck), np.log10(c) + z[k] * s, rtol=1e-9)
        np.testing.assert_allclose(np.log10(cwk), np.log10(c) + 2 * z[k] * s, rtol=1e-9)
    with pytest.raises(ValueError, match="member 9"):
        fitted.member(9)
    with pytest.raises(ValueError, match="uncertainty_scale"):
        clone(model).set_params(uncertainty_scale=0.0).fit(data.X, data.y)


@pytest.mark.parametrize("family", ["kriging", "rsm"])
def test_closed_form_families_round_trip_through_the_model_files(data, family, tmp_path):
    model = build_families(SETTINGS, R)[family].set_params(uncertainty_scale=1.3, velocity_uncertainty_scale=0.8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fitted = model.fit(data.X, data.y, groups=data.groups, velocity=data.velocity)
    meta = save_surrogate(fitted, tmp_path / "model.skops")
    assert meta["family"] == family and meta["params"]["uncertainty_scale"] == 1.3
    loaded = load_surrogate(tmp_path / "model.skops")
    assert isinstance(loaded, CollisionSurrogate) and loaded.n_members == fitted.n_members
    d, n = np.array([0.002, 0.003, 0.004]), np.array([900.0, 600.0, 400.0])
    for a, b in zip(
        fitted.frequency_matrix(d, n, 600, return_std=True, check_domain=False),
        loaded.frequency_matrix(d, n, 600, return_std=True, check_domain=False),
    ):
        np.testing.assert_array_equal(a, b)
    ea, eb = fitted.encounters(d, n, 600, check_domain=False), loaded.encounters(d, n, 600, check_domain=False)
    np.testing.assert_array_equal(ea.velocity_fractions, eb.velocity_fractions)
    np.testing.assert_array_equal(
        fitted.member(0).frequency_matrix(d, n, 600, check_domain=False),
        loaded.member(0).frequency_matrix(d, n, 600, check_domain=False),
    )


def test_response_surface_chooses_its_degree_by_grouped_cv():
    rng = np.random.default_rng(4)
    groups = np.repeat(np.arange(12), 6).astype(str)
    X = rng.uniform(-1, 1, size=(72, 2))
    linear = 1 + 2 * X[:, 0] - X[:, 1] + 0.01 * rng.normal(size=72)
    curved = linear + 1.5 * X[:, 0] * X[:, 1]
    model = ResponseSurface(degree=(1, 2), n_splits=4).fit(X, np.column_stack([linear, curved]), groups=groups)
    # a linear law keeps degree 1 (a tie or better goes to the lower degree); an interaction needs 2
    assert model.degrees_ == [1, 2]
    assert set(model.cv_mse_[1]) == {1, 2} and model.cv_mse_[1][2] < model.cv_mse_[1][1]
    # without groups: the lowest candidate, no search
    assert ResponseSurface(degree=(2, 1)).fit(X, curved).degrees_ == [1]
    with pytest.raises(ValueError, match="degree"):
        ResponseSurface(degree=(0, 2)).fit(X, curved)


REFIT = r"""
import sys, warnings
sys.path.insert(0, sys.argv[2])  # the tests folder, home of synthetic_tables
import numpy as np
from pbmdem.surrogate import training_data
from pbmdem.surrogate.settings import build_families
from synthetic_tables import make_synthetic_tables
from pbmdem.config import Surrogate
R = 0.0265
table, velocity = make_synthetic_tables(R, rpms=(300, 600, 1200), sample_velocities=True)
settings = Surrogate.from_section({}).to_dict()  # the defaults
data = training_data(table, R, velocity_table=velocity, speed_law=settings["speed_law"])
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    for name in ("kriging", "rsm"):
        model = build_families(settings, R)[name].fit(data.X, data.y, groups=data.groups, velocity=data.velocity)
        np.save(f"{sys.argv[1]}/{name}.npy", np.concatenate([
            model.predict(data.X, check_domain=False), model.predict_velocity(data.X, check_domain=False)[0]]))
"""


@pytest.mark.skipif(platform.machine() != "x86_64", reason="OpenBLAS core types are named for x86-64")
def test_closed_form_families_do_not_depend_on_the_blas_kernel(tmp_path):
    # The MLP's lbfgs path does (docs/surrogate.md, "Reproducibility"); the default kernel source must
    # not. Prescott is OpenBLAS' generic x86-64 kernel: every x86-64 processor runs it.
    runs = {}
    for kernel in ("Prescott", None):
        env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE")}
        if kernel:
            env["OPENBLAS_CORETYPE"] = kernel
        out = tmp_path / str(kernel)
        out.mkdir()
        subprocess.run([sys.executable, "-c", REFIT, str(out), str(Path(__file__).parent)], env=env, check=True)
        runs[kernel] = {name: np.load(out / f"{name}.npy") for name in ("kriging", "rsm")}
    for name in ("kriging", "rsm"):
        np.testing.assert_allclose(runs["Prescott"][name], runs[None][name], rtol=1e-6, atol=0)


def test_each_target_gets_its_own_family_by_the_evidence_the_pbm_needs():
    # pooled: the MLP has the best R2 of log10 c, Kriging the closest fast tail of the impact speeds
    metrics = pd.DataFrame(
        {
            "target": ["encounter_frequency"] * 3 + ["impact_velocity"] * 3,
            "fold": "pooled",
            "model": ["mlp", "kriging", "rsm"] * 2,
            "r2_log10": [0.97, 0.95, 0.90, 0.8, 0.8, 0.8],
            "tv_distance": [np.nan] * 3 + [0.10, 0.05, 0.20],
        }
    )
    for col in ("mae_log10", "noise_floor_r2_log10", "coverage_90", "coverage_90_calibrated", "uncertainty_scale"):
        metrics[col] = np.nan
    metrics = pd.concat([metrics, metrics.assign(fold="mean")], ignore_index=True)
    # no active-learning runs: the frequency by the pooled R2
    pooled = {name: {"velocity_tail_log10": tail} for name, tail in zip(FAMILIES, (0.3, 0.2, 0.4))}
    choice = select_per_target(metrics, FAMILIES, pooled=pooled)
    assert (choice["frequency"], choice["speed_law"]) == ("mlp", "kriging")
    assert "pooled held-out R2" in choice["frequency_reason"] and "kriging 0.200" in choice["speed_law_reason"]
    # without the tail's scores the speed law follows the frequency
    assert select_per_target(metrics, FAMILIES)["speed_law"] == "mlp"
    # on the PBM's own samples Kriging's frequency is closer: it wins there
    pbm = {name: {"n_runs": 3, "mae_log10": mae} for name, mae in zip(FAMILIES, (0.041, 0.032, 0.054))}
    choice = select_per_target(metrics, FAMILIES, pbm, pooled)
    assert choice["frequency"] == "kriging" and "3 active-learning runs" in choice["frequency_reason"]
    assert "kriging 0.032" in choice["frequency_reason"]


def test_sample_scores_are_the_held_out_errors_on_the_named_runs(cv_result):
    metrics, pred = cv_result
    runs = sorted(pred["point_id"].unique())[:2]
    scores = sample_scores(pred, FAMILIES, runs)
    rows = pred[pred["point_id"].isin(runs)]
    obs = rows["log10_encounter_frequency_per_pair"]
    for name in FAMILIES:
        s = scores[name]
        assert s["n_runs"] == 2 and s["n_rows"] == len(rows)
        assert s["mean_error_log10"] == pytest.approx(np.mean(rows[f"{name}_log10"] - obs))
        assert s["mae_log10"] == pytest.approx(np.mean(np.abs(rows[f"{name}_log10"] - obs)))
        assert s["uncertainty_scale"] == pytest.approx(
            calibration_scale(obs, rows[f"{name}_log10"], rows[f"{name}_std_log10"])
        )
        vobs = rows["velocity_mu_log10"]
        assert s["velocity_mae_log10"] == pytest.approx(np.mean(np.abs(rows[f"{name}_velocity_mu_log10"] - vobs)))
    # every run: the pooled MAE of the metrics
    pooled = summarise(metrics)
    for name in FAMILIES:
        assert sample_scores(pred, [name])[name]["mae_log10"] == pytest.approx(pooled[name]["pooled_mae_log10"])
    assert sample_scores(pred, FAMILIES, ["no_such_run"]) == {}


def test_members_are_quantiles_shared_by_frequency_and_speed_law_with_the_mean_in_the_middle(data):
    families = build_families(SETTINGS, R)
    # the frequency of the MLP, the impact-speed law of Kriging, as `auto` may choose
    model = clone(families["mlp"]).set_params(
        velocity_model=clone(families["kriging"].velocity_model), uncertainty_scale=2.0, velocity_uncertainty_scale=0.5
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fitted = model.fit(data.X, data.y, groups=data.groups, velocity=data.velocity)
    n = fitted.n_members
    assert n == 3
    d, counts = np.array([0.002, 0.003, 0.004]), np.array([900.0, 600.0, 400.0])
    c, s = fitted.frequency_matrix(d, counts, 600, return_std=True, check_domain=False)
    mean = fitted.encounters(d, counts, 600, check_domain=False)
    X = data.X.iloc[:7]
    mu, _, mu_std, _ = fitted.predict_velocity(X, return_std=True, check_domain=False)
    z = member_quantiles(n)
    for k in range(n):
        one = fitted.member(k)
        np.testing.assert_allclose(
            np.log10(one.frequency_matrix(d, counts, 600, check_domain=False)), np.log10(c) + z[k] * s, atol=1e-12
        )
        np.testing.assert_allclose(one.predict_velocity(X, check_domain=False)[0], mu + z[k] * mu_std, atol=1e-12)
    # the middle member is the mean prediction: PBM-ANN's mean lies inside its members' range
    middle = fitted.member(n // 2).encounters(d, counts, 600, check_domain=False)
    np.testing.assert_array_equal(middle.frequency, mean.frequency)
    np.testing.assert_array_equal(middle.velocity_fractions, mean.velocity_fractions)
    # member 0 predicts the fewest encounters, the last the most
    low, high = (fitted.member(k).frequency_matrix(d, counts, 600, check_domain=False) for k in (0, n - 1))
    assert np.all(low < c) and np.all(high > c)


def test_the_tail_error_compares_the_fractions_of_fast_impacts():
    from pbmdem.impact import VELOCITY_EDGES

    lo = np.asarray(VELOCITY_EDGES[:-1])
    observed = np.zeros((3, len(lo)))
    observed[:, lo == 0.1] = 0.9
    observed[:, lo == 1.0] = 0.08  # 1-1.78 m/s
    observed[:, np.isclose(lo, 10**0.5)] = 0.02  # 3.16-5.62 m/s
    predicted = observed.copy()
    predicted[1] *= 1.0  # identical: no error
    predicted[0, lo == 0.1], predicted[0, np.isclose(lo, 10**0.5)] = 0.9 + 0.02 - 0.2, 0.2  # 10x the fastest
    predicted[2] = 0.0
    predicted[2, lo == 0.1] = 1.0  # no fast impact at all: a finite, large error
    err = tail_error(predicted, observed)
    # above 1 and 1.78 m/s: 0.28 / 0.1 and 0.2 / 0.02; above 3.16: 0.2 / 0.02; above 5.62 nothing observed
    expected = np.mean([np.log10(0.28 / 0.1), np.log10(0.2 / 0.02), np.log10(0.2 / 0.02)])
    np.testing.assert_allclose(err[:2], [expected, 0.0], atol=1e-12)
    assert err[2] > 100
    assert np.isnan(tail_error(predicted[:1], np.eye(1, len(lo))))[0]  # no observed fast impact: no score


@pytest.mark.parametrize("degree", (1, 2, 3))
def test_response_surface_predicts_as_its_pipelines_do(degree):
    # the response surface evaluates its fitted pipelines by their own arithmetic (no per-step
    # validation): the mean and the predictive standard deviation equal the pipelines' predict,
    # on SI-sized features (diameters in m, speeds in m/s) and on points outside the fitted range
    rng = np.random.default_rng(11)
    X = np.column_stack([rng.uniform(1e-3, 8e-3, 80), rng.uniform(0.0, 1.0, 80), rng.uniform(0.5, 6.0, 80)])
    y = np.column_stack([np.log10(X[:, 0]) + X[:, 1] ** 2, np.sin(X[:, 2]) + X[:, 0] * 1e3])
    model = ResponseSurface(degree=degree).fit(X, y + 0.01 * rng.standard_normal(y.shape))
    X_new = np.vstack([X[:7] * 1.3, rng.uniform(0.0, 1.0, (5, 3)) * [1e-2, 2.0, 8.0]])
    mean, std = model.predict_array(X_new, return_std=True)
    for j, est in enumerate(model.estimators_):
        m_ref, s_ref = est.predict(X_new, return_std=True)
        assert np.allclose(mean[:, j], m_ref, rtol=1e-12, atol=1e-12)
        assert np.allclose(std[:, j], s_ref, rtol=1e-12, atol=0.0)
    assert np.array_equal(model.predict(X_new), model.predict_array(X_new))
    # the two outputs (one degree, the same rows) share the terms of one prediction: those of each alone
    from pbmdem.surrogate._terms import polynomial_terms

    shared = {}
    first = polynomial_terms(model.estimators_[0], X_new, shared)
    second = polynomial_terms(model.estimators_[1], X_new, shared)
    assert second is first and np.array_equal(second, polynomial_terms(model.estimators_[1], X_new))


def test_kriging_mean_predicts_as_its_pipelines_do():
    # Kriging predicts from the fitted pipelines' attributes (no per-step validation):
    # mean and standard deviation bit for bit the pipelines' predict, on SI-sized features, inside
    # and outside the fitted range
    rng = np.random.default_rng(12)
    X = np.column_stack([rng.uniform(1e-3, 8e-3, 60), rng.uniform(0.0, 1.0, 60), rng.uniform(0.5, 6.0, 60)])
    y = np.column_stack([np.log10(X[:, 0]) + X[:, 1] ** 2, np.sin(X[:, 2]) + X[:, 0] * 1e3])
    model = KrigingRegressor(n_restarts_optimizer=0).fit(X, y + 0.01 * rng.standard_normal(y.shape))
    X_new = np.vstack([X[:7] * 1.3, rng.uniform(0.0, 1.0, (5, 3)) * [1e-2, 2.0, 8.0]])
    mean = model.predict_array(X_new)
    for j, est in enumerate(model.estimators_):
        assert np.array_equal(mean[:, j], est.predict(X_new))
    mean_std, std = model.predict_array(X_new, return_std=True)
    assert np.array_equal(mean, mean_std)
    for j, est in enumerate(model.estimators_):
        assert np.array_equal(std[:, j], est.predict(X_new, return_std=True)[1])
    single = KrigingRegressor(n_restarts_optimizer=0).fit(X, y[:, 0])
    assert single.predict_array(X_new).shape == (len(X_new),)
    assert np.array_equal(single.predict_array(X_new), single.estimators_[0].predict(X_new))

    # and without the linear trend
    plain = KrigingRegressor(n_restarts_optimizer=0, linear_trend=False).fit(X, y[:, 0])
    assert np.array_equal(plain.predict_array(X_new), plain.estimators_[0].predict(X_new))


def test_cross_kernel_is_the_kernels_call_to_the_bit():
    # Kriging's cross-covariance by scikit-learn's lines of each term (families.cross_kernel): the
    # kernel's own call bit for bit, for sums and products of its terms, and a kernel of other terms
    # (a Matern) or of a constant or white noise alone is called
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, DotProduct, Matern, WhiteKernel

    from pbmdem.surrogate.families import cross_kernel

    rng = np.random.default_rng(3)
    Y = rng.normal(size=(30, 3)) * [1e-3, 1.0, 5.0]
    kernels = [
        ConstantKernel(2.0) * RBF([1e-3, 2.0, 3.0]) + ConstantKernel(0.3) * DotProduct(1.0) + WhiteKernel(0.1),
        RBF(1.5),
        ConstantKernel(0.3) * DotProduct(0.7) + ConstantKernel(1.1),
        RBF(1.0) * DotProduct(1.0) + WhiteKernel(0.1) * RBF(2.0),
        ConstantKernel(2.0) * Matern(1.0) + WhiteKernel(0.1),
        WhiteKernel(0.2),
        ConstantKernel(2.0),
    ]
    for kernel in kernels:
        for n in (1, 7):
            X = rng.normal(size=(n, 3)) * [1e-3, 1.0, 5.0]
            assert np.array_equal(cross_kernel(kernel, X, Y), kernel(X, Y)), kernel


def test_run_calibration_scale_is_the_row_scale_of_the_runs_means():
    # three pairs per run; within a run the errors cancel, between runs they do not: the run-level
    # factor is that of the runs' mean errors over their mean std, smaller than the rows'
    runs = np.repeat(["a", "b", "c", "d", "e"], 3)
    shared = np.repeat([0.02, -0.04, 0.01, 0.03, -0.02], 3)
    pair = np.tile([0.1, -0.1, 0.0], 5)
    y, mean, std = np.zeros(15), shared + pair, np.full(15, 0.05)
    per_run = calibration_scale(np.zeros(5), shared[::3], np.full(5, 0.05))
    assert run_calibration_scale(runs, y, mean, std) == pytest.approx(per_run, rel=1e-12)
    assert per_run == pytest.approx(0.04 / 0.05 / interval_z(), rel=1e-12)  # the 90 % quantile of 5: the largest
    assert calibration_scale(y, mean, std) > 2 * per_run


def test_terms_of_two_factors_equal_the_product_over_every_feature(monkeypatch):
    # a response-surface term of at most two features of nonzero power is computed as their one
    # product (_terms.two_factors): the product over all features (the exact 1s of power 0
    # included, in any order) to the bit, on random features of every sign and scale; degree 3
    # has terms of three factors and keeps the product over all features
    from sklearn.preprocessing import PolynomialFeatures

    from pbmdem.surrogate._terms import term_products, two_factors

    rng = np.random.default_rng(3)
    for degree, n_features in ((1, 8), (2, 8), (2, 3), (3, 4)):
        powers = PolynomialFeatures(degree, include_bias=False).fit(np.zeros((1, n_features))).powers_
        factors = two_factors(powers)
        assert (factors is None) == (degree == 3)
        if factors is None:
            continue
        x = rng.standard_normal((50, n_features)) * 10.0 ** rng.uniform(-150, 150, (50, n_features))
        x[:3] = [0.0, -0.0, 1.0][0]
        table = x[:, :, None] ** np.arange(powers.max() + 1)
        fast = term_products(table, powers, factors)
        assert np.array_equal(fast, term_products(table, powers, None)) and fast.flags.c_contiguous
    # a fitted response surface predicts the same numbers with every term as the product over all features
    from pbmdem.surrogate import _terms

    X = rng.uniform(0.5, 2.0, (60, 4))
    model = ResponseSurface(degree=2).fit(X, np.column_stack([X @ [1.0, -2.0, 0.5, 3.0], np.log(X).sum(axis=1)]))
    X_new = rng.uniform(0.2, 3.0, (9, 4))
    fast = model.predict_array(X_new, return_std=True)
    monkeypatch.setattr(_terms, "POWERS", _terms.weakref.WeakKeyDictionary())
    monkeypatch.setattr(_terms, "two_factors", lambda powers: None)
    for a, b in zip(fast, model.predict_array(X_new, return_std=True), strict=True):
        assert np.array_equal(a, b)


def test_the_terms_of_a_pipeline_fitted_again_in_place_are_those_of_its_new_fit():
    # _terms.POWERS keeps a pipeline's powers and sharing key while its scalers are the ones it saw:
    # two outputs fitted on the same rows share their terms until one is fitted again on others
    from pbmdem.surrogate._terms import polynomial_terms

    rng = np.random.default_rng(5)
    X = rng.uniform(0.5, 2.0, (40, 3))
    a, b = ResponseSurface(degree=2).fit(X, np.column_stack([X.sum(axis=1), X[:, 0]])).estimators_
    X_new = rng.uniform(0.5, 2.0, (6, 3))
    shared = {}
    assert polynomial_terms(a, X_new, shared) is polynomial_terms(b, X_new, shared)
    a.fit(3.0 * X + 1.0, X.sum(axis=1))
    shared = {}
    polynomial_terms(b, X_new, shared)
    np.testing.assert_allclose(polynomial_terms(a, X_new, shared), a[:-1].transform(X_new), rtol=1e-12, atol=1e-12)
