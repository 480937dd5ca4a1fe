"""Impact-velocity model, the one-call `encounters` interface and the replicate noise floor."""

import math
import warnings

import numpy as np
import pytest
from synthetic_tables import make_synthetic_table, make_synthetic_tables, velocity_law

from pbmdem.impact import N_VELOCITY_BINS, EncounterRates
from pbmdem.surrogate import (
    CollisionSurrogate,
    EnsembleMLPRegressorCV,
    OutOfDomainWarning,
    VelocityModelMissingError,
    cross_validate_models,
    noise_floor_r2,
    summarise,
    training_data,
)
from pbmdem.surrogate.evaluation import default_baselines
from pbmdem.surrogate.features import TARGET_NAME, pair_table
from pbmdem.surrogate.velocity import attach_velocity_bins, speed_fractions

R = 0.0265  # impeller radius (m) of the synthetic tables and models
SMALL = dict(
    hidden_layer_sizes=((6,), (8,)),
    alpha=(0.001, 0.01),
    seeds=(0, 1, 2),
    max_iter=1500,
    activation="tanh",
    solver="lbfgs",
    cv="group_kfold",
    n_splits=3,
)
TINY = dict(hidden_layer_sizes=((4,),), alpha=(0.01,), seeds=(0, 1), max_iter=2000, activation="tanh", solver="lbfgs")


def surrogate(**ensemble) -> CollisionSurrogate:
    return CollisionSurrogate(
        frequency_model=EnsembleMLPRegressorCV(**ensemble), impeller_radius=R, physics_offset="cross_section"
    )


def fit(model, data):
    return model.fit(data.X, data.y, groups=data.groups, velocity=data.velocity)


@pytest.fixture(scope="module")
def table():
    # 20 runs x 6 pairs; velocity bins are multinomial samples of every replicate's encounters
    return attach_velocity_bins(*make_synthetic_tables(R, seed=11, noise_log10=0.03, sample_velocities=True))


@pytest.fixture(scope="module")
def data(table):
    return training_data(table, R)


@pytest.fixture(scope="module")
def fitted(data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fit(surrogate(**SMALL), data)


def test_held_out_velocity_distribution_recovers_known_law(data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        metrics, pred = cross_validate_models(
            data, {"mlp": surrogate(**SMALL), **default_baselines()}, cv="group_kfold", n_splits=5
        )
    vel = summarise(metrics, "impact_velocity")
    assert set(vel) == {"mlp", "physical"}
    mlp, phys = vel["mlp"], vel["physical"]
    print(
        f"held-out median impact speed: MAE {mlp['pooled_mae_log10']:.4f} decades "
        f"(physical {phys['pooled_mae_log10']:.4f}), TV distance {mlp['pooled_tv_distance']:.4f} "
        f"(physical {phys['pooled_tv_distance']:.4f})"
    )
    assert mlp["pooled_mae_log10"] < 0.03
    assert mlp["pooled_tv_distance"] < 0.12
    assert mlp["pooled_mae_log10"] < phys["pooled_mae_log10"]
    assert mlp["pooled_tv_distance"] < phys["pooled_tv_distance"]
    # held-out predictions against the noise-free law itself: closer to it than the sampled DEM
    # bins are (the ensemble averages the sampling noise out), and the size-ratio and rpm
    # dependence is learned, which one tip-speed ratio (physical baseline) cannot do
    mu_law, sigma_law = velocity_law(pred["d_i"], pred["d_j"], pred["rpm"], R)
    err_mlp = np.abs(pred["mlp_velocity_mu_log10"] - mu_law).mean()
    err_obs = np.abs(pred["velocity_mu_log10"] - mu_law).mean()
    err_phys = np.abs(pred["physical_velocity_mu_log10"] - mu_law).mean()
    print(f"median vs law (decades): mlp {err_mlp:.4f}, DEM-like bins {err_obs:.4f}, physical {err_phys:.4f}")
    assert err_mlp < 0.02 and err_mlp < err_obs and err_mlp < 0.5 * err_phys
    assert np.abs(np.log10(pred["mlp_velocity_sigma"] / sigma_law)).mean() < 0.05
    # every row with bins was predicted once, in the impact-velocity rows of the metrics
    assert pred["mlp_velocity_mu_log10"].notna().all()
    rows = metrics[metrics["target"] == "impact_velocity"]
    assert set(rows["model"]) == {"mlp", "physical"} and {"pooled", "mean"} <= set(rows["fold"])


def test_encounters_one_call_consistent(fitted):
    d = np.array([0.002, 0.003, 0.004])
    n = np.array([900.0, 700.0, 400.0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        rates = fitted.encounters(d, n, 600)
        c = fitted.frequency_matrix(d, n, 600)
        rev = fitted.encounters(d[::-1], n[::-1], 600)
    assert isinstance(rates, EncounterRates)
    assert rates.frequency.shape == (3, 3) and rates.velocity_fractions.shape == (3, 3, N_VELOCITY_BINS)
    assert np.allclose(rates.frequency, c)  # the PBM kernel contract returns the encounter frequency
    assert np.allclose(rates.frequency, rates.frequency.T)
    assert np.allclose(rates.velocity_fractions, rates.velocity_fractions.transpose(1, 0, 2))
    assert (rates.velocity_fractions >= 0).all()
    assert np.allclose(rates.velocity_fractions.sum(axis=-1), 1.0)
    assert np.allclose((rates.frequency[:, :, None] * rates.velocity_fractions).sum(axis=-1), rates.frequency)
    assert np.allclose(rev.velocity_fractions, rates.velocity_fractions[::-1, ::-1])
    # the fractions are those of the predicted log-normal law of every pair
    frame, iu, ju = pair_table(d, n, 600)
    mu, sigma = fitted.predict_velocity(frame, check_domain=False)
    assert np.allclose(rates.velocity_fractions[iu, ju], speed_fractions(mu, sigma, "lognormal"))
    # a faster impeller gives faster impacts (median ~ tip speed in the known law)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        mu_fast, _ = fitted.predict_velocity(pair_table(d, n, 900)[0])
    assert (mu_fast > mu).all()
    mu_law, _ = velocity_law(frame["d_i"], frame["d_j"], 600, R)
    assert np.abs(mu - mu_law).max() < 0.06


def test_encounters_warns_out_of_domain_once_per_feature(fitted):
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        fitted.encounters([0.002, 0.003], [900, 700], 2000)
    messages = [str(w.message) for w in rec if issubclass(w.category, OutOfDomainWarning)]
    assert len([m for m in messages if m.startswith("tip_speed")]) == 1


def test_without_velocity_bins_frequency_only():
    t = make_synthetic_table(R, rpms=(300, 600, 900), seed=3)
    with pytest.warns(UserWarning, match="no impact-velocity bins"):
        d = training_data(t, R)
    model = fit(surrogate(**TINY), d)
    assert not model.has_velocity_model() and model.velocity_model_ is None and model.n_velocity_rows_ == 0
    # no velocity targets at all: the same frequency model
    np.testing.assert_array_equal(surrogate(**TINY).fit(d.X, d.y, groups=d.groups).predict(d.X), model.predict(d.X))
    c = model.frequency_matrix([0.002, 0.003], [900, 700], 600, check_domain=False)
    assert c.shape == (2, 2)
    with pytest.raises(VelocityModelMissingError, match="impact_velocity.csv"):
        model.encounters([0.002, 0.003], [900, 700], 600)
    with pytest.raises(VelocityModelMissingError, match="impact_velocity.csv"):
        model.predict_velocity(d.X)


def test_noise_floor_hand_made():
    y = np.array([0.0, 1.0, 2.0, 3.0])  # population variance 1.25
    assert noise_floor_r2(y, np.full(4, 0.01)) == pytest.approx(1.0 - 0.01 / 1.25)
    assert noise_floor_r2(y, [0.01, 0.03, 0.01, 0.03]) == pytest.approx(1.0 - 0.02 / 1.25)
    # rows with unknown noise (one replicate) are left out; nothing known -> NaN
    assert noise_floor_r2(np.append(y, 9.0), [0.01] * 4 + [np.nan]) == pytest.approx(1.0 - 0.01 / 1.25)
    assert math.isnan(noise_floor_r2(y, np.full(4, np.nan)))
    assert math.isnan(noise_floor_r2(np.ones(4), np.full(4, 0.01)))


def test_noise_floor_from_replicate_se_in_metrics():
    t, v = make_synthetic_tables(R, rpms=(300, 600, 900), seed=4, n_replicates=3, noise_log10=0.05)
    # delta method by hand: var(log10 c) = (SE / (c ln 10))^2
    c, se = t["encounter_frequency_per_pair"], t["encounter_frequency_per_pair_se"]
    y = np.log10(c)
    expected = 1.0 - np.mean((se / (c * np.log(10))) ** 2) / np.var(y)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        metrics, pred = cross_validate_models(
            training_data(t, R, velocity_table=v),
            {"mlp": surrogate(**TINY), **default_baselines()},
            cv="group_kfold",
            n_splits=3,
        )
    freq = metrics[metrics["target"] == "encounter_frequency"]
    pooled = freq[freq["fold"] == "pooled"]
    assert np.allclose(pooled["noise_floor_r2_log10"], expected)  # same value beside every model
    assert np.allclose(pred[TARGET_NAME], y)
    # per-fold floors are computed on the fold's own rows
    fold0 = freq[(freq["fold"] == "0") & (freq["model"] == "mlp")].iloc[0]
    ids = fold0["test_point_ids"].split(";")
    sel = t["point_id"].isin(ids).to_numpy()
    exp0 = 1.0 - np.mean(((se / (c * np.log(10))) ** 2)[sel]) / np.var(y[sel])
    assert fold0["noise_floor_r2_log10"] == pytest.approx(exp0)
    # one replicate: no SE, no floor
    one = make_synthetic_table(R, rpms=(300, 600, 900), seed=4, n_replicates=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m1, _ = cross_validate_models(
            training_data(one, R), {"mlp": surrogate(**TINY), **default_baselines()}, cv="group_kfold", n_splits=3
        )
    assert m1["noise_floor_r2_log10"].isna().all()
    assert (m1["target"] == "encounter_frequency").all()  # no velocity bins, no velocity rows
