"""Features, target preparation and the impact-velocity table of the encounter surrogate."""

import math
import warnings

import numpy as np
import pandas as pd
import pytest
from synthetic_tables import TABLE_COLUMNS, make_synthetic_table, make_synthetic_tables, velocity_law

from pbmdem.impact import N_VELOCITY_BINS, VELOCITY_EDGES
from pbmdem.surrogate.features import (
    FEATURE_NAMES,
    TARGET_NAME,
    TARGET_NOISE_VAR,
    CollisionTableError,
    duplicated_features,
    make_features,
    pair_table,
    prepare_training_table,
    run_classes,
    tip_speed,
    training_data,
)
from pbmdem.surrogate.velocity import (
    VELOCITY_COUNT_COLUMNS,
    attach_velocity_bins,
    fit_speed_law,
    speed_fractions,
    total_variation,
)
from pbmdem.tables import GRID_PAIRS

R = 0.0265  # impeller radius (m) of the synthetic tables and of their features


def one_run(diameters=(0.002, 0.003, 0.004), numbers=(600, 300, 100), rpm=600, pid="rpm600_x"):
    rows = []
    n_total = sum(numbers)
    for i in range(len(diameters)):
        for j in range(i, len(diameters)):
            pairs = numbers[i] * (numbers[i] - 1) / 2 if i == j else numbers[i] * numbers[j]
            c = 10.0 + i + j
            e = 4.0 + i + j  # encounters, mean per replicate
            rows.append(
                dict(
                    point_id=pid,
                    rpm=rpm,
                    distribution="x",
                    class_i=i,
                    class_j=j,
                    d_i=diameters[i],
                    d_j=diameters[j],
                    n_i=numbers[i],
                    n_j=numbers[j],
                    n_total=n_total,
                    collisions=c,
                    sampling_time=0.2,
                    frequency=c / 0.2,
                    frequency_per_pair=c / (pairs * 0.2) if pairs else np.nan,
                    n_replicates=2,
                    encounters=e,
                    encounter_frequency_per_pair=e / (pairs * 0.2) if pairs else np.nan,
                    encounter_frequency_per_pair_se=0.1 * e / (pairs * 0.2) if pairs else np.nan,
                    impact_velocity_median=0.2,
                )
            )
    return pd.DataFrame(rows)


def test_feature_columns_and_values():
    t = one_run()
    f = make_features(t, impeller_radius=0.0265)
    assert list(f.columns) == list(FEATURE_NAMES)
    assert (f["d_small"] <= f["d_large"]).all()
    assert np.allclose(f["n_total"], 1000)
    row = f.iloc[1]  # classes 0, 1
    assert row["frac_small"] == pytest.approx(0.6) and row["frac_large"] == pytest.approx(0.3)
    assert np.allclose(f["tip_speed"], 2 * math.pi * 0.0265 * 600 / 60)
    assert tip_speed(600, 0.0265) == pytest.approx(1.6650, rel=1e-4)
    # rpm and tip speed carry the same information at a fixed impeller: only tip speed is a feature
    assert "rpm" not in FEATURE_NAMES and "tip_speed" in FEATURE_NAMES
    assert len(set(FEATURE_NAMES)) == len(FEATURE_NAMES)


def test_impeller_radius_is_always_explicit():
    # no default radius anywhere: the caller passes granulator.impeller.blade_length
    with pytest.raises(TypeError, match="impeller_radius"):
        make_features(one_run())
    with pytest.raises(TypeError, match="impeller_radius"):
        tip_speed(600)
    for bad in (None, 0.0, -0.01, float("nan"), float("inf"), "x", True):
        with pytest.raises(ValueError, match=r"impeller_radius \(granulator.impeller.blade_length\).*> 0 m"):
            tip_speed(600, bad)
    assert np.allclose(make_features(one_run(), 0.03)["tip_speed"], 2 * math.pi * 0.03 * 600 / 60)


def test_no_feature_duplicates_another():
    # synthetic runs over several speeds and random distributions: no pair of features is a duplicate
    f = make_features(make_synthetic_table(R, seed=3, noise_log10=0.0), R)
    assert duplicated_features(f) == []
    # rpm and d_mean would be: tip speed is proportional to rpm, and with a fixed bed volume
    # log n_total follows log d_mean
    t = make_synthetic_table(R, seed=3, noise_log10=0.0)
    classes = run_classes(t).assign(nd=lambda c: c["n"] * c["d"]).groupby("point_id")[["nd", "n"]].sum()
    d_mean = classes["nd"] / classes["n"]  # number mean diameter of every run
    extra = f.assign(rpm=t["rpm"].to_numpy(float), d_mean=d_mean.reindex(t["point_id"]).to_numpy())
    found = {(a, b) for a, b, _ in duplicated_features(extra)}
    assert ("tip_speed", "rpm") in found and ("n_total", "d_mean") in found


def test_features_are_order_independent():
    t = one_run()
    # same run with the classes numbered in descending size: d_i > d_j in every off-diagonal row
    rev = one_run(diameters=(0.004, 0.003, 0.002), numbers=(100, 300, 600))
    assert (rev["d_i"] >= rev["d_j"]).all()
    key = ["d_small", "d_large"]
    a = make_features(t, R).sort_values(key).reset_index(drop=True)
    b = make_features(rev, R).sort_values(key).reset_index(drop=True)
    pd.testing.assert_frame_equal(a, b)


def test_any_number_of_classes():
    t = one_run(diameters=(0.001, 0.002, 0.003, 0.004, 0.005), numbers=(50, 40, 30, 20, 10))
    assert len(t) == 15
    f = make_features(t, R)
    assert f.notna().all().all()
    assert run_classes(t).groupby("point_id").size()["rpm600_x"] == 5
    single = one_run(diameters=(0.003,), numbers=(500,))
    assert len(make_features(single, R)) == 1


def test_target_is_the_encounter_frequency_with_delta_method_noise():
    t = one_run()
    data = prepare_training_table(t)
    assert np.allclose(data[TARGET_NAME], np.log10(t["encounter_frequency_per_pair"]))
    # SE is 10 % of the mean: var(log10 c) = (0.1 / ln 10)^2 by the delta method
    assert np.allclose(data[TARGET_NOISE_VAR], (0.1 / math.log(10)) ** 2)
    # the raw new-contact diagnostic is not the target
    assert not np.allclose(data[TARGET_NAME], np.log10(t["frequency_per_pair"]))


def test_zero_encounters_drop_and_floor():
    t = one_run()
    t.loc[5, ["encounters", "encounter_frequency_per_pair", "encounter_frequency_per_pair_se"]] = 0.0
    with pytest.warns(UserWarning, match="dropping 1 row"):
        dropped = prepare_training_table(t, "drop")
    assert len(dropped) == 5 and np.isfinite(dropped[TARGET_NAME]).all()
    with pytest.warns(UserWarning, match="flooring 1 row"):
        floored = prepare_training_table(t, "floor")
    assert len(floored) == 6 and bool(floored.loc[5, "floored"])
    pairs = 100 * 99 / 2
    # half an encounter over both replicates of the sampling window
    assert floored.loc[5, "encounter_frequency_per_pair"] == pytest.approx(0.5 / (2 * pairs * 0.2))
    assert np.isnan(floored.loc[5, TARGET_NOISE_VAR])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        clean = prepare_training_table(one_run())
    assert len(clean) == 6


def test_invalid_tables_rejected():
    t = one_run()
    with pytest.raises(CollisionTableError, match="lacks column"):
        make_features(t.drop(columns=["n_total"]), R)
    bad = t.copy()
    bad.loc[0, "class_i"] = 2
    with pytest.raises(CollisionTableError, match="class_i <= class_j"):
        make_features(bad, R)
    bad = t.copy()
    bad.loc[0, "rpm"] = 900
    with pytest.raises(CollisionTableError, match="not constant"):
        make_features(bad, R)


def test_pair_table_matches_training_features():
    t = one_run()
    frame, iu, ju = pair_table([0.002, 0.003, 0.004], [600, 300, 100], 600)
    assert len(frame) == 6 and (iu <= ju).all()
    a = make_features(frame, R).reset_index(drop=True)
    b = make_features(t, R).reset_index(drop=True)
    pd.testing.assert_frame_equal(a, b)


def test_synthetic_tables_follow_contract():
    t, v = make_synthetic_tables(R, rpms=(300, 900), seed=2, noise_log10=0.02, n_replicates=4)
    assert list(t.columns) == list(TABLE_COLUMNS)
    assert set(TABLE_COLUMNS) == {c.name for c in GRID_PAIRS.columns} - {"frequency_per_pair_se"}
    assert t["point_id"].nunique() == 8 and len(t) == 48
    assert (t.groupby("point_id")["n_total"].nunique() == 1).all()
    assert np.isfinite(np.log10(t["encounter_frequency_per_pair"])).all()
    assert (t["n_replicates"] == 4).all() and (t["encounter_frequency_per_pair_se"] > 0).all()
    assert list(v.columns) == ["point_id", "rpm", "distribution", "class_i", "class_j", "v_lo", "v_hi", "encounters"]
    assert len(v) == 48 * N_VELOCITY_BINS
    assert np.allclose(np.sort(v["v_lo"].unique()), VELOCITY_EDGES[:-1])
    # the bins of a pair add up to its encounters
    total = v.groupby(["point_id", "class_i", "class_j"])["encounters"].sum()
    assert np.allclose(
        total.to_numpy(), t.set_index(["point_id", "class_i", "class_j"])["encounters"].reindex(total.index).to_numpy()
    )
    one = make_synthetic_table(R, rpms=(600,), seed=2, n_replicates=1)
    assert one["encounter_frequency_per_pair_se"].isna().all()


def test_attach_velocity_bins():
    t, v = make_synthetic_tables(R, rpms=(300, 900), seed=2)
    merged = attach_velocity_bins(t, v.sample(frac=1.0, random_state=0))  # row order does not matter
    assert len(merged) == len(t) and all(c in merged for c in VELOCITY_COUNT_COLUMNS)
    assert np.allclose(merged[list(VELOCITY_COUNT_COLUMNS)].sum(axis=1), t["encounters"])
    # a pair whose empty bins are omitted still gets zeros there; a pair without rows gets NaN
    sparse = v[v["encounters"] > 1e-6]
    first = (t["point_id"].iloc[0], t["class_i"].iloc[0], t["class_j"].iloc[0])
    sparse = sparse[
        ~((sparse["point_id"] == first[0]) & (sparse["class_i"] == first[1]) & (sparse["class_j"] == first[2]))
    ]
    m2 = attach_velocity_bins(t, sparse)
    assert m2[list(VELOCITY_COUNT_COLUMNS)].iloc[0].isna().all()
    assert np.isfinite(m2[list(VELOCITY_COUNT_COLUMNS)].iloc[1:].to_numpy()).all()
    with pytest.raises(CollisionTableError, match="missing column"):
        attach_velocity_bins(t, v.drop(columns=["v_hi"]))
    wrong = v.copy()
    wrong.loc[wrong.index[3], "v_lo"] = 0.0042
    with pytest.raises(CollisionTableError, match="0.0042"):
        attach_velocity_bins(t, wrong)
    stray = v.copy()
    stray.loc[stray.index[0], "point_id"] = "nowhere"
    with pytest.raises(CollisionTableError, match="nowhere"):
        attach_velocity_bins(t, stray)


def test_lognormal_fit_recovers_known_law():
    mu = np.log10([0.004, 0.05, 0.3, 2.0])
    sigma = np.array([0.15, 0.3, 0.5, 0.25])
    frac = speed_fractions(mu, sigma, "lognormal")
    assert frac.shape == (4, N_VELOCITY_BINS) and np.allclose(frac.sum(axis=1), 1.0) and (frac >= 0).all()
    mu_fit, sigma_fit = fit_speed_law(1000.0 * frac, "lognormal")
    assert np.allclose(mu_fit, mu, atol=1e-3) and np.allclose(sigma_fit, sigma, rtol=1e-2)
    assert np.allclose(total_variation(speed_fractions(mu_fit, sigma_fit, "lognormal"), frac), 0.0, atol=1e-3)
    # the open last bin takes the fast tail: a median at 20 m/s puts most encounters there
    assert speed_fractions(np.log10(20.0), 0.2, "lognormal")[0, -1] > 0.9
    m, s = velocity_law(0.002, 0.004, 600, R)
    assert 10**m == pytest.approx(0.12 * 2 * math.pi * R * 600 / 60 * 0.5**0.5)
    assert s == pytest.approx(0.30)


def test_rows_without_pairs_or_finite_frequency_are_dropped_with_a_warning():
    # a class with a single particle has no pair on the diagonal: the DEM table has NaN there
    t = one_run(numbers=(600, 300, 1))
    assert np.isnan(t.loc[5, "encounter_frequency_per_pair"])
    with pytest.warns(UserWarning, match="without particle pairs"):
        data = prepare_training_table(t)
    assert len(data) == 5 and np.isfinite(data[TARGET_NAME]).all()
    bad = one_run()
    bad.loc[2, "encounter_frequency_per_pair"] = np.inf
    with pytest.warns(UserWarning, match="non-finite encounter_frequency_per_pair"):
        assert len(prepare_training_table(bad)) == 5
    with pytest.raises(CollisionTableError, match="encounter_frequency_per_pair"):
        prepare_training_table(one_run().drop(columns=["encounter_frequency_per_pair"]))
    with pytest.raises(CollisionTableError, match="n_replicates"):
        prepare_training_table(one_run().assign(n_replicates=0))


def test_training_data_is_the_one_table_to_model_inputs_path():
    t, v = make_synthetic_tables(R, rpms=(300, 900), seed=2, sample_velocities=True)
    t.loc[3, ["encounters", "encounter_frequency_per_pair", "encounter_frequency_per_pair_se"]] = 0.0
    with pytest.warns(UserWarning, match="dropping 1 row"):
        data = training_data(t, R, "drop", velocity_table=v)
    kept = t.drop(index=3).reset_index(drop=True)
    assert data.n_dropped == 1 and data.n_floored == 0 and len(data.y) == len(kept) == len(data.table)
    pd.testing.assert_frame_equal(data.X, make_features(kept, R))
    assert np.array_equal(data.y, np.log10(kept["encounter_frequency_per_pair"].to_numpy()))
    assert list(data.groups) == list(kept["point_id"].astype(str))
    assert np.allclose(
        data.noise_var,
        (kept["encounter_frequency_per_pair_se"] / (kept["encounter_frequency_per_pair"] * math.log(10))) ** 2,
    )
    # impact-speed targets: the log-normal fit of every row's bins
    bins = attach_velocity_bins(t, v).drop(index=3)[list(VELOCITY_COUNT_COLUMNS)].to_numpy()
    mu, sigma = fit_speed_law(bins, "lognormal")
    assert np.array_equal(data.velocity, np.column_stack([mu, sigma]))
    # bins attached beforehand give the same; floored rows are counted
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again = training_data(attach_velocity_bins(t, v), R, "drop")
        floored = training_data(t, R, "floor", velocity_table=v)
    assert np.array_equal(again.velocity, data.velocity)
    assert floored.n_dropped == 0 and floored.n_floored == 1 and bool(floored.table.loc[3, "floored"])
    # without bins: frequency targets only, with a warning
    with pytest.warns(UserWarning, match="no impact-velocity bins"):
        bare = training_data(t.drop(index=3), R)
    assert np.isnan(bare.velocity).all() and bare.velocity.shape == (len(kept), 2)
