"""The global sensitivity analysis (pbmdem.design.sensitivity): the project's sampling and
evaluation recover the known Sobol' indices of the Ishigami function; the `sensitivity:` section
is validated; PBM-ANN runs in SALib's shape, one batch per sample row."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from conftest import config_of

from pbmdem.config import ConfigError, SobolFactor
from pbmdem.design.batches import Case, run_case
from pbmdem.design.sensitivity import COLUMNS, PbmAnnOutputs, salib_problem, sample, sobol_study

# Ishigami-Homma with a = 7, b = 0.1 on [-pi, pi]^3: the analytical indices (Saltelli et al. 2008,
# "Global Sensitivity Analysis: The Primer"; SALib's test function)
ISHIGAMI_S1 = (0.3139, 0.4424, 0.0)
ISHIGAMI_ST = (0.5576, 0.4424, 0.2437)


def ishigami(x: np.ndarray, a: float = 7.0, b: float = 0.1) -> pd.DataFrame:
    """The Ishigami function as a model in SALib's shape: one row of outputs per sample row."""
    y = np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])
    return pd.DataFrame({"y": y})


def test_sobol_indices_recover_the_ishigami_function():
    """The study the rule runs (`sobol_study`: SALib's Saltelli sample, the model, SALib's
    estimator), with the Ishigami function as the model: each of the six indices lies within its
    own 95 % interval of the analytical value. N = 1024 (5120 evaluations) makes the intervals
    narrow enough (half-widths <= 0.09, asserted) that the test can fail; scrambled Sobol'
    sampling errs less than the bootstrap interval, which assumes independent random samples."""
    factors = [SobolFactor(key=f"x{k}", low=-np.pi, high=np.pi, scale="linear") for k in (1, 2, 3)]
    calls = []

    def model(x):
        calls.append(x.shape)
        return ishigami(x)

    study = sobol_study(factors, {"mean": model}, ["y"], base_samples=1024, seed=1, confidence=0.95, resamples=1000)
    assert calls == [(1024 * (3 + 2), 3)]  # one call, N (D + 2) rows of the three factors
    assert np.abs(study.samples).max() <= np.pi
    table = study.table.set_index("parameter")
    assert list(study.table.columns) == list(COLUMNS) and set(study.table.member) == {"mean"}
    assert (table.S1_conf < 0.09).all() and (table.ST_conf < 0.09).all(), table
    for k, name in enumerate(("x1", "x2", "x3")):
        row = table.loc[name]
        assert abs(row.S1 - ISHIGAMI_S1[k]) <= row.S1_conf, (name, row.to_dict())
        assert abs(row.ST - ISHIGAMI_ST[k]) <= row.ST_conf, (name, row.to_dict())
    # the same seed, the same table; x3 acts only through its interaction with x1
    again = sobol_study(factors, {"mean": ishigami}, ["y"], base_samples=1024, seed=1, confidence=0.95, resamples=1000)
    pd.testing.assert_frame_equal(again.table, study.table)
    assert table.loc["x3", "ST"] - table.loc["x3", "S1"] > 0.2


def test_log_scale_samples_uniformly_in_ln_and_units_do_not_matter():
    """A log-scaled factor is uniform in ln between its bounds, whatever its unit: the same range in
    other units (x 1e6) gives the same sample, scaled."""
    factors = [
        SobolFactor(key="pbm.aggregation.beta0", low=1e-4, high=4e-4, scale="log"),
        SobolFactor(key="b", low=5e3, high=1e5, scale="log"),
    ]
    x = sample(salib_problem(factors), 256, seed=3)
    assert x.shape == (256 * 4, 2)
    assert (x[:, 0] >= 1e-4).all() and (x[:, 0] <= 4e-4).all()
    below_middle = np.mean(x[:, 0] < 2e-4)  # the geometric middle of [1e-4, 4e-4]
    assert abs(below_middle - 0.5) < 0.02, below_middle
    scaled = [
        SobolFactor(key="pbm.aggregation.beta0", low=1e2, high=4e2, scale="log"),
        SobolFactor(key="b", low=5e9, high=1e11, scale="log"),
    ]
    np.testing.assert_allclose(sample(salib_problem(scaled), 256, seed=3), x * 1e6, rtol=1e-12)


def test_config_refuses_bad_sensitivity_settings(tiny_mapping):
    """Every problem of the section named with its key, value and what is allowed."""
    tiny_mapping["sensitivity"] = {
        "impeller_rpm": {"low": 900, "high": 600},
        "parameters": [
            {"key": "pbm.aggregation.beta0", "low": 4e-4, "high": 1e-4},
            {"key": "pbm.aggregation.scheme", "low": 1.0, "high": 2.0},
            {"key": "pbm.aggregation.beta0", "low": 1e-4, "high": 2e-4},
        ],
        "base_samples": 100,
    }
    with pytest.raises(ConfigError) as err:
        config_of(tiny_mapping)
    text = str(err.value)
    assert "sensitivity.impeller_rpm: high = 600 must not be below low = 900" in text
    assert "sensitivity.parameters[0] (pbm.aggregation.beta0): high = 0.0001 must exceed low = 0.0004" in text
    assert "sensitivity.parameters[1].key: config key 'pbm.aggregation.scheme' = 'cell_average'" in text
    assert "sensitivity.parameters[2].key = 'pbm.aggregation.beta0': named twice" in text
    assert "sensitivity.base_samples = 100: allowed: a power of 2" in text
    # what the schema checks: positive bounds, the scales, the seed
    tiny_mapping["sensitivity"] = {
        "parameters": [{"key": "pbm.aggregation.beta0", "low": -1e-4, "high": 1e-4, "scale": "cubic"}],
        "seed": 0,
    }
    with pytest.raises(ConfigError) as err:
        config_of(tiny_mapping)
    text = str(err.value)
    assert "config key sensitivity.parameters[0].low = -0.0001" in text and "> 0" in text
    assert "config key sensitivity.parameters[0].scale = 'cubic'" in text and "['linear', 'log']" in text
    assert "config key sensitivity.seed = 0" in text and ">= 1" in text


def test_speed_range_defaults_to_the_dem_grid_and_a_fixed_speed_is_no_factor(tiny_config, tiny_mapping):
    factors = tiny_config.sensitivity.factors()
    assert factors[0] == SobolFactor(key="impeller_rpm", low=600.0, high=1200.0, scale="linear")  # the grid's speeds
    assert [f.key for f in factors[1:]] == [p.key for p in tiny_config.sensitivity.parameters]
    tiny_mapping["sensitivity"]["impeller_rpm"] = {"low": 700, "high": 700}
    assert [f.key for f in config_of(tiny_mapping).sensitivity.factors()] == [f.key for f in factors[1:]]


def test_pbm_ann_in_salibs_shape_is_one_batch_per_sample_row(tiny_config, tiny_surrogate):
    """Each row of the sample matrix is the batch of its values (the speed and the pbm settings
    in the factors' order), for the mean and for a member."""
    loop = tiny_config.coupled_loop()
    keys = ("impeller_rpm", "pbm.liquid_addition.rate", "pbm.aggregation.beta0")
    x = np.array([[700.0, 1.1e-7, 1.5e-4], [800.0, 1.3e-7, 3.0e-4]])
    for member in (None, 1):
        y = PbmAnnOutputs(loop, str(tiny_surrogate), keys, member, 1, 600.0)(x)
        assert len(y) == 2 and (y.failed == "").all()
        for row, out in zip(x, y.to_dict("records")):
            case = Case(row[0], ((keys[1], row[1]), (keys[2], row[2])), member)
            assert run_case(loop, tiny_surrogate, case).final() == {s: out[s] for s in ("d10", "d50", "d90")}
        assert y.d50[1] > y.d50[0]  # more binder and a larger beta0: larger granules


def test_sensitivity_rule_files_of_the_tiny_batch(tiny_config, tiny_surrogate, tmp_path):
    """Rule sensitivity's library call on the tiny config (N = 4): the indices of d10/d50/d90 of
    every factor for the mean and each member, the bars, and the figures of merit."""
    from pbmdem.design.outputs import write_sensitivity

    settings = tiny_config.sensitivity
    paths = [tmp_path / "sensitivity.csv", tmp_path / "sensitivity.png", tmp_path / "sensitivity.json"]
    write_sensitivity(tiny_config.coupled_loop(), tiny_surrogate, settings, *paths)
    table = pd.read_csv(paths[0], dtype={"member": str})
    factors = [f.key for f in settings.factors()]
    assert list(table.columns) == list(COLUMNS)
    assert len(table) == len(factors) * 3 * 3  # factors x outputs x (mean + 2 members)
    assert set(table.member) == {"mean", "0", "1"} and set(table.output) == {"d10", "d50", "d90"}
    d50 = table[table.output == "d50"]
    assert np.isfinite(d50[["S1", "ST", "S1_conf", "ST_conf"]].to_numpy()).all(), d50
    assert (d50.ST_conf >= 0).all()
    assert paths[1].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    info = json.loads(paths[2].read_text())
    samples = settings.base_samples * (len(factors) + 2)
    assert info["samples"] == samples and info["batches"] == 3 * samples
    assert set(info["out_of_domain_samples"]) == {"mean", "0", "1"}
    # the tiny surrogate saw 600-900 rpm: the faster half of the samples extrapolate, and say so
    assert info["out_of_domain_samples"]["mean"] > 0


def _indices(member, st, s1):
    return [
        {"parameter": p, "output": "d50", "member": member, "S1": a, "S1_conf": 0.05, "ST": b, "ST_conf": 0.05}
        for p, a, b in zip(("impeller_rpm", "pbm.aggregation.beta0", "pbm.process.wet_massing_time"), s1, st)
    ]


def test_sensitivity_words_name_the_first_factor_and_the_members_agreement():
    from pbmdem.report.sensitivity import sensitivity_words

    rows = _indices("mean", (0.6, 0.3, 0.02), (0.5, 0.25, 0.01))
    rows += _indices("0", (0.55, 0.35, 0.02), (0.5, 0.3, 0.0))  # the mean's order
    rows += _indices("1", (0.3, 0.5, 0.03), (0.25, 0.45, 0.0))  # beta0 first
    words = sensitivity_words(pd.DataFrame(rows), 0.95)
    assert words.startswith("**Global sensitivity.**")
    assert "depends most on the impeller speed (ST = 0.60 ± 0.05, S1 = 0.50 ± 0.05; 95 % intervals)" in words
    assert "then on the coalescence fraction beta0 (ST = 0.30" in words and "not told apart" not in words
    assert "The wet-massing time causes less than 5 % of its variance." in words
    assert (
        "impeller speed comes first for 1 of 2 (ST from 0.30 to 0.55); the others put coalescence fraction beta0 first"
        in words
    )
    assert "1 of 2 rank all 3 factors as the mean does." in words
    info = {"samples": 640, "out_of_domain_samples": {"mean": 64, "0": 70}}
    assert "On 64 of the mean's 640 samples (10 %) the surrogate left its training domain" in sensitivity_words(
        pd.DataFrame(rows), 0.95, info
    )
    # overlapping intervals; every member agrees
    rows = _indices("mean", (0.45, 0.42, 0.1), (0.4, 0.4, 0.1)) + _indices("0", (0.5, 0.4, 0.1), (0.4, 0.4, 0.1))
    words = sensitivity_words(pd.DataFrame(rows), 0.95)
    assert "within their intervals these two are not told apart" in words
    assert "the surrogate's uncertainty does not change the answer" in words
    nan = pd.DataFrame(_indices("mean", (np.nan,) * 3, (np.nan,) * 3))
    assert "undefined" in sensitivity_words(nan, 0.95)


def test_an_output_without_variance_or_with_a_failed_sample_has_undefined_indices(caplog):
    """No variance to share out, or a sample without a result: NaN indices, said in the log; the
    other outputs of the same model keep theirs."""
    factors = [SobolFactor(key=f"x{k}", low=-np.pi, high=np.pi, scale="linear") for k in (1, 2, 3)]

    def model(x):
        out = ishigami(x).assign(flat=0.004, broken=ishigami(x).y)
        out.loc[5, "broken"] = np.nan
        out["failed"] = ""
        out.loc[5, "failed"] = "the PBM holds 49.6 particles"  # the failure's reason reaches the log
        return out

    study = sobol_study(
        factors, {"mean": model}, ["y", "flat", "broken"], base_samples=64, seed=2, confidence=0.95, resamples=100
    )
    t = study.table.set_index("output")
    assert np.isfinite(t.loc["y", ["S1", "ST", "S1_conf", "ST_conf"]].to_numpy()).all()
    for output in ("flat", "broken"):
        assert t.loc[output, ["S1", "ST", "S1_conf", "ST_conf"]].isna().all().all(), output
    assert "flat does not vary over the samples" in caplog.text
    reason = "its indices are undefined (first: the PBM holds 49.6"
    assert f"mean: 1 of 320 samples without a result; {reason}" in caplog.text
