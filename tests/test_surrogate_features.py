"""Features and target preparation of the collision-frequency surrogate."""

import math
import warnings

import numpy as np
import pandas as pd
import pytest

from pbmdem.surrogate.features import (
    FEATURE_NAMES,
    TARGET_NAME,
    CollisionTableError,
    make_features,
    pair_table,
    prepare_training_table,
    run_descriptors,
    tip_speed,
)
from pbmdem.surrogate.synthetic import make_synthetic_table


def one_run(diameters=(0.002, 0.003, 0.004), numbers=(600, 300, 100), rpm=600, pid="rpm600_x"):
    rows = []
    n_total = sum(numbers)
    for i in range(len(diameters)):
        for j in range(i, len(diameters)):
            pairs = numbers[i] * (numbers[i] - 1) / 2 if i == j else numbers[i] * numbers[j]
            c = 10.0 + i + j
            rows.append(dict(point_id=pid, rpm=rpm, distribution="x", class_i=i, class_j=j,
                             d_i=diameters[i], d_j=diameters[j], n_i=numbers[i], n_j=numbers[j],
                             n_total=n_total, collisions=c, sampling_time=0.2, frequency=c / 0.2,
                             frequency_per_pair=c / (pairs * 0.2)))
    return pd.DataFrame(rows)


def test_feature_columns_and_values():
    t = one_run()
    f = make_features(t, impeller_radius=0.0265)
    assert list(f.columns) == list(FEATURE_NAMES)
    assert (f["d_small"] <= f["d_large"]).all()
    d_mean = (600 * 0.002 + 300 * 0.003 + 100 * 0.004) / 1000
    assert np.allclose(f["d_mean"], d_mean)
    assert np.allclose(f["n_total"], 1000)
    row = f.iloc[1]  # classes 0, 1
    assert row["frac_small"] == pytest.approx(0.6) and row["frac_large"] == pytest.approx(0.3)
    assert np.allclose(f["tip_speed"], 2 * math.pi * 0.0265 * 600 / 60)
    assert tip_speed(600, 0.0265) == pytest.approx(1.6650, rel=1e-4)


def test_features_are_order_independent():
    t = one_run()
    # same run with the classes numbered in descending size: d_i > d_j in every off-diagonal row
    rev = one_run(diameters=(0.004, 0.003, 0.002), numbers=(100, 300, 600))
    assert (rev["d_i"] >= rev["d_j"]).all()
    key = ["d_small", "d_large"]
    a = make_features(t).sort_values(key).reset_index(drop=True)
    b = make_features(rev).sort_values(key).reset_index(drop=True)
    pd.testing.assert_frame_equal(a, b)


def test_any_number_of_classes():
    t = one_run(diameters=(0.001, 0.002, 0.003, 0.004, 0.005), numbers=(50, 40, 30, 20, 10))
    assert len(t) == 15
    f = make_features(t)
    assert f.notna().all().all()
    desc = run_descriptors(t)
    assert desc.loc["rpm600_x", "n_classes"] == 5
    single = one_run(diameters=(0.003,), numbers=(500,))
    assert len(make_features(single)) == 1


def test_zero_collisions_drop_and_floor():
    t = one_run()
    t.loc[5, ["collisions", "frequency", "frequency_per_pair"]] = 0.0
    with pytest.warns(UserWarning, match="dropping 1 row"):
        dropped = prepare_training_table(t, "drop")
    assert len(dropped) == 5 and np.isfinite(dropped[TARGET_NAME]).all()
    with pytest.warns(UserWarning, match="flooring 1 row"):
        floored = prepare_training_table(t, "floor")
    assert len(floored) == 6 and bool(floored.loc[5, "floored"])
    pairs = 100 * 99 / 2
    assert floored.loc[5, "frequency_per_pair"] == pytest.approx(0.5 / (pairs * 0.2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        clean = prepare_training_table(one_run())
    assert len(clean) == 6


def test_invalid_tables_rejected():
    t = one_run()
    with pytest.raises(CollisionTableError, match="lacks column"):
        make_features(t.drop(columns=["n_total"]))
    bad = t.copy()
    bad.loc[0, "class_i"] = 2
    with pytest.raises(CollisionTableError, match="class_i <= class_j"):
        make_features(bad)
    bad = t.copy()
    bad.loc[0, "rpm"] = 900
    with pytest.raises(CollisionTableError, match="not constant"):
        make_features(bad)


def test_pair_table_matches_training_features():
    t = one_run()
    frame, iu, ju = pair_table([0.002, 0.003, 0.004], [600, 300, 100], 600)
    assert len(frame) == 6 and (iu <= ju).all()
    a = make_features(frame).reset_index(drop=True)
    b = make_features(t).reset_index(drop=True)
    pd.testing.assert_frame_equal(a, b)


def test_synthetic_table_follows_contract():
    t = make_synthetic_table(rpms=(300, 900), seed=2, noise_log10=0.0)
    assert t["point_id"].nunique() == 8 and len(t) == 48
    assert (t.groupby("point_id")["n_total"].nunique() == 1).all()
    assert np.isfinite(np.log10(t["frequency_per_pair"])).all()
