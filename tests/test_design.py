"""The design space (grid, specification region, out-of-domain points) and the parameter
estimation (recovery of known parameters, non-identifiable pairs, measured-data errors)."""

import warnings

import numpy as np
import pandas as pd
import pytest
from conftest import config_of

from pbmdem.config import ConfigError, Specification
from pbmdem.config.design import pbm_value, with_pbm_values
from pbmdem.design.batches import MIN_POOLED_CASES, Case, run_cases
from pbmdem.design.calibration import Model, calibrate, check_measured, profile_widths, read_measured
from pbmdem.design.proof import measured_from_series, with_noise
from pbmdem.design.space import LIQUID_KEY, design_space, specification_status
from pbmdem.readers import InputFileError
from pbmdem.tables import STATISTICS

THIRD = "pbm.process.wet_massing_time"


# --------------------------------------------------------------------------- specification region
def _point(d50, d50_lo, d50_hi, d90, d90_lo, d90_hi, ood=0, failed=0):
    return {
        "d50": d50,
        "d50_member_min": d50_lo,
        "d50_member_max": d50_hi,
        "d90": d90,
        "d90_member_min": d90_lo,
        "d90_member_max": d90_hi,
        "out_of_domain_intervals": ood,
        "failed_cases": failed,
    }


def test_specification_region_on_a_hand_made_table():
    spec = Specification(d50_min=0.008, d50_max=0.010, d90_max=0.014)
    table = pd.DataFrame(
        [
            _point(0.009, 0.0085, 0.0095, 0.012, 0.011, 0.013),  # whole band inside
            _point(0.009, 0.0075, 0.0095, 0.012, 0.011, 0.013),  # d50 band below d50_min in part
            _point(0.009, 0.0085, 0.0095, 0.013, 0.012, 0.015),  # d90 band above d90_max in part
            _point(0.011, 0.0105, 0.0120, 0.012, 0.011, 0.013),  # whole d50 band above d50_max
            _point(0.007, 0.0060, 0.0079, 0.010, 0.009, 0.011),  # whole d50 band below d50_min
            _point(0.009, 0.0085, 0.0095, 0.016, 0.015, 0.017),  # whole d90 band above d90_max
            _point(0.009, 0.0085, 0.0095, 0.012, 0.011, 0.013, ood=1),  # inside, but extrapolated
            _point(0.009, 0.0085, 0.0095, 0.012, 0.011, 0.013, failed=1),  # a member failed
            _point(0.010, 0.0100, 0.0100, 0.014, 0.014, 0.014),  # on the limits: inside
        ]
    )
    status = specification_status(table, spec).tolist()
    assert status == [
        "meets",
        "uncertain",
        "uncertain",
        "fails",
        "fails",
        "fails",
        "out_of_domain",
        "failed",
        "meets",
    ]
    # without bounds every in-domain point meets it
    free = specification_status(table, Specification(d50_min=None, d50_max=None, d90_max=None)).tolist()
    assert free == ["meets"] * 6 + ["out_of_domain", "failed", "meets"]


# --------------------------------------------------------------------------- settings
def test_pbm_settings_by_config_key(tiny_config):
    pbm = tiny_config.pbm
    changed = with_pbm_values(pbm, {"pbm.aggregation.beta0": 3e-4, "pbm.aggregation.success.threshold": 0.05})
    assert changed.aggregation.beta0 == 3e-4 and changed.aggregation.success.threshold == 0.05
    assert pbm.aggregation.beta0 == 2e-4  # the settings are frozen: a copy was changed
    assert changed.process == pbm.process
    with pytest.raises(ConfigError, match="pbm.aggregation.nothing"):
        pbm_value(pbm, "pbm.aggregation.nothing")
    with pytest.raises(ConfigError, match=r"pbm.solver.method.*'ssp3'.*positive number"):
        pbm_value(pbm, "pbm.solver.method")


def test_config_refuses_bad_parameter_keys_and_ranges(tiny_mapping):
    tiny_mapping["calibration"] = {"parameters": ["pbm.aggregation.scheme"]}
    tiny_mapping["design_space"] = {"liquid_rate": {"start": 2e-7, "stop": 1e-7}}
    with pytest.raises(ConfigError) as err:
        config_of(tiny_mapping)
    text = str(err.value)
    assert "calibration.parameters[0]" in text and "pbm.aggregation.scheme" in text
    assert "design_space.liquid_rate: stop = 1e-07 must not be below start = 2e-07" in text
    # a grid of one speed: the design space's speed range is that speed
    tiny_mapping.pop("calibration")
    tiny_mapping["design_space"] = {}
    tiny_mapping["grid"]["impeller_rpm"] = [600]
    tiny_mapping["validation"]["sweep"] = {"start": 600, "stop": 900}
    assert config_of(tiny_mapping).design_space.impeller_rpm.values() == [600.0]


# --------------------------------------------------------------------------- measured data
HEADER = "rpm,time,d10,d50,d90,d10_sd,d50_sd,d90_sd\n"
GOOD = "600,2,0.002,0.0026,0.0032,1e-5,1e-5,1e-5\n600,4,0.002,0.0027,0.0033,1e-5,1e-5,1e-5\n"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "rpm,time,d10,d50,d90,d10_sd,d50_sd\n600,2,0.002,0.0026,0.0032,1e-5,1e-5\n",
            r"missing column\(s\) \['d90_sd'\]",
        ),
        (
            HEADER + GOOD + "600,6,0.002,-0.003,0.0033,1e-5,1e-5,1e-5\n",
            r"row 3, column 'd50' = -0.003: a finite number > 0",
        ),
        (HEADER + GOOD + "600,6,0.002,abc,0.0033,1e-5,1e-5,1e-5\n", r"row 3, column 'd50' = 'abc'"),
        (
            HEADER + GOOD + "600,4,0.002,0.0028,0.0034,1e-5,1e-5,1e-5\n",
            r"row 3, column 'time' = 4: the times of rpm 600",
        ),
        (
            HEADER + GOOD + "600,99,0.002,0.0028,0.0034,1e-5,1e-5,1e-5\n",
            r"row 3, column 'time' = 99: allowed 0 .. 20 s",
        ),
        (
            HEADER + GOOD + "900,2,0.003,0.0026,0.0032,1e-5,1e-5,1e-5\n",
            r"row 3, column 'd50' = 0.0026: must be at least d10",
        ),
        (HEADER + GOOD + "900,2,0.002,0.0026,0.0032,,1e-5,1e-5\n", r"row 3, column 'd10_sd'"),
        (HEADER, "no data rows"),
    ],
)
def test_bad_measured_data_is_refused_with_file_row_and_column(tmp_path, text, message):
    path = tmp_path / "measured.csv"
    path.write_text(text)
    with pytest.raises(InputFileError, match=message) as err:
        read_measured(path, end_time=20.0)
    assert str(path) in str(err.value)


def test_good_measured_data_and_noise(tmp_path):
    path = tmp_path / "measured.csv"
    path.write_text(HEADER + GOOD + "900,2,0.002,0.0026,0.0032,0,0,0\n")
    table = read_measured(path, end_time=20.0)
    assert len(table) == 3 and list(table.rpm) == [600, 600, 900]
    noisy = with_noise(table, 0.05, seed=3)
    assert (noisy[["d10_sd", "d50_sd", "d90_sd"]].to_numpy() > 0).all()
    assert not np.allclose(noisy.d50, table.d50)
    check_measured(noisy, "noisy", 20.0)  # still a valid measured table
    assert with_noise(table, 0.05, seed=3).equals(noisy)  # seeded


# --------------------------------------------------------------------------- calibration
def _constant_data(loop, rpms, times, noise, seed):
    outcomes = run_cases(loop, None, [Case(r, kernel="constant") for r in rpms])
    series = {o.case.rpm: [pd.DataFrame(o.sizes, columns=list(STATISTICS)).assign(time=o.times)] for o in outcomes}
    return with_noise(measured_from_series(series, times), noise, seed)


def test_calibration_recovers_known_parameters_within_intervals(tiny_config):
    """Data of PBM-constant at the tiny config's beta0 and threshold, with 2 % noise; the fit
    starts 50 % off and must end with each true value inside its 95 % interval."""
    loop = tiny_config.coupled_loop()
    settings = tiny_config.calibration
    keys = settings.parameters
    truth = {k: pbm_value(loop.batch.pbm, k) for k in keys}
    data = _constant_data(loop, (600.0, 900.0), np.arange(2.0, 20.1, 2.0), 0.02, seed=11)
    start = {k: 1.5 * v for k, v in truth.items()}
    est = calibrate(Model(loop, None, keys, "constant"), data, settings, start)
    table = est.table.set_index("parameter")
    for key, true in truth.items():
        assert table.loc[key, "ci_low"] <= true <= table.loc[key, "ci_high"], (key, table.loc[key].to_dict())
        # an informative interval: the estimate inside it, within a factor 2 of the truth at most
        assert table.loc[key, "ci_low"] < table.loc[key, "estimate"] < table.loc[key, "ci_high"]
        assert table.loc[key, "ci_high"] / table.loc[key, "ci_low"] < 2.0, table.loc[key].to_dict()
    assert est.unidentifiable == [] and est.info["full_rank"]
    assert 0.3 < est.info["chi2_reduced"] < 2.0  # the noise level the data were made with
    assert est.correlation.shape == (2, 2) and np.allclose(np.diag(est.correlation), 1.0)
    assert set(est.residuals.statistic) == set(STATISTICS) and len(est.residuals) == data.size // 8 * 3


class _FakeResiduals:
    """Residuals r(x) of a hand-made function, with the `_evaluate` the profile fits call."""

    def __init__(self, function):
        self.function = function

    def __call__(self, x):
        return np.asarray(self.function(np.asarray(x, float)), float)

    def _evaluate(self, points):
        return [self(p) for p in points]


def test_profile_interval_of_a_linear_model_is_the_analytical_one():
    """r = A x - b: the profile interval of each parameter is x_hat +- z sqrt((A^T A)^-1_ii), the
    other parameter fitted again (correlated columns); the scan's bisection errs wide by < 1/16."""
    A = np.array([[1.0, 0.5], [0.2, 1.0], [1.0, 1.0], [0.3, -0.4]]) * 40.0
    b = A @ np.array([0.1, -0.2]) + np.array([0.5, -0.3, 0.2, 0.4])
    x_hat = np.linalg.lstsq(A, b, rcond=None)[0]
    res = _FakeResiduals(lambda x: A @ x - b)
    z = 1.96
    widths = profile_widths(res, x_hat, x_hat - 2.0, x_hat + 2.0, z)
    # the sides scanned at once in two processes give the same widths, to the bit
    np.testing.assert_array_equal(profile_widths(res, x_hat, x_hat - 2.0, x_hat + 2.0, z, n_jobs=2), widths)
    expected = z * np.sqrt(np.diag(np.linalg.inv(A.T @ A)))
    for i in range(2):
        for side in range(2):
            assert expected[i] <= widths[i, side] <= expected[i] * (1 + 1 / 16), (i, side, widths, expected)


def test_profile_interval_reaches_past_a_jump_to_the_valley_behind_it():
    """A sum of squares with a wall just above the estimate (a switch of the model's output) and a
    valley behind it: the interval is the hull of the set below z^2, not the first crossing; a
    parameter the data do not constrain gets an open interval."""

    def r(x):
        wall = 10.0 if 0.01 < x[0] < 0.03 else 0.0  # +100 in the sum of squares
        return np.array([x[0] / 0.04, wall])  # quadratic part: z-width 0.0784 either side

    widths = profile_widths(_FakeResiduals(r), np.array([0.0]), np.array([-1.0]), np.array([1.0]), 1.96)
    assert 0.0784 <= widths[0, 0] <= 0.0784 * (1 + 1 / 16), widths
    assert 0.0784 <= widths[0, 1] <= 0.0784 * (1 + 1 / 16), widths  # not 0.01, where the wall begins
    flat = profile_widths(
        _FakeResiduals(lambda x: np.array([0.1])), np.array([0.0]), np.array([-1.0]), np.array([1.0]), 1.96
    )
    assert np.isinf(flat).all()


def test_calibration_reports_parameters_the_data_cannot_separate(tiny_config):
    """With the constant kernel only the product beta0 x c enters the PBM: the two are flagged."""
    loop = tiny_config.coupled_loop()
    keys = ("pbm.aggregation.beta0", "pbm.aggregation.constant_frequency")
    data = _constant_data(loop, (600.0,), np.arange(2.0, 20.1, 2.0), 0.02, seed=5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow warnings from the unbounded intervals
        est = calibrate(Model(loop, None, keys, "constant"), data, tiny_config.calibration)
    assert [(a, b) for a, b, _ in est.unidentifiable] == [keys]
    assert abs(est.unidentifiable[0][2]) > 0.95
    product = est.table.estimate.prod()
    assert product == pytest.approx(pbm_value(loop.batch.pbm, keys[0]) * pbm_value(loop.batch.pbm, keys[1]), rel=0.1)


def test_batches_do_not_depend_on_the_number_of_processes(tiny_config):
    loop = tiny_config.coupled_loop()
    rates = np.linspace(1.0e-7, 1.4e-7, MIN_POOLED_CASES)  # enough cases for the process pool
    cases = [Case(600.0, ((LIQUID_KEY, rate),), kernel="constant") for rate in rates]
    one = run_cases(loop, None, cases, n_jobs=1)
    two = run_cases(loop, None, cases, n_jobs=2)
    for a, b in zip(one, two, strict=True):
        assert a.case == b.case and np.array_equal(a.sizes, b.sizes)
    finals = [o.final()["d50"] for o in one]
    assert finals[0] < finals[-1]  # more binder, larger granules


def test_a_case_records_the_summarys_sizes(tiny_config, tiny_surrogate):
    # run_case reads d10/d50/d90 without the batch's summary table: the same numbers, to the bit
    from pbmdem.coupling import pbm_ann

    loop = tiny_config.coupled_loop()
    (outcome,) = run_cases(loop, tiny_surrogate, [Case(750.0)])
    summary = pbm_ann(loop, tiny_surrogate, 750.0, None, log_each=False).result.summary()
    np.testing.assert_array_equal(outcome.times, summary.time.to_numpy(float))
    np.testing.assert_array_equal(outcome.sizes, summary[["d10", "d50", "d90"]].to_numpy(float))
    assert np.isfinite(outcome.sizes).all() and len(outcome.times) > 2


# --------------------------------------------------------------------------- design space with a surrogate
def test_design_space_marks_points_outside_the_training_domain(tiny_config, tiny_surrogate, caplog):
    design = tiny_config.design_space  # 600-1200 rpm: the surrogate saw 600-900 only
    table, info = design_space(tiny_config.coupled_loop(), tiny_surrogate, design)
    assert len(table) == 3 * 3 * 2 and info["batches"] == len(table) * 3  # mean + 2 members
    assert info["batches_per_minute"] == pytest.approx(60.0 * info["batches"] / info["wall_time_s"])
    assert set(table.rpm) == {600.0, 900.0, 1200.0} and set(table[THIRD]) == {6.0, 8.0}
    fast = table[table.rpm == 1200.0]
    assert (fast.out_of_domain_intervals > 0).all() and (fast.spec_status == "out_of_domain").all()
    # a point is judged only if no case of it left the domain
    judged = table.spec_status.isin(["meets", "uncertain", "fails"])
    assert (table.out_of_domain_intervals[judged] == 0).all()
    assert (table.spec_status[table.out_of_domain_intervals > 0] == "out_of_domain").all()
    # the band holds the members, d10 <= d50 <= d90
    ok = table[table.failed_cases == 0]
    assert (ok.d50_member_min <= ok.d50_member_max).all() and (ok.d10 <= ok.d50).all() and (ok.d50 <= ok.d90).all()
    assert "outside its training domain" in caplog.text


def test_calibration_with_pbm_ann_adds_the_surrogates_uncertainty(tiny_config, tiny_surrogate):
    """PBM-ANN's own output (ensemble mean, 1 % measurement sd) at 600 and 750 rpm, calibrated with
    PBM-ANN from 50 % off: the truth is recovered, and the interval holds a surrogate part from the
    per-member refits (two members) beside the measurement part."""
    loop = tiny_config.coupled_loop()
    settings = tiny_config.calibration
    keys = settings.parameters
    truth = {k: pbm_value(loop.batch.pbm, k) for k in keys}
    outcomes = run_cases(loop, tiny_surrogate, [Case(600.0), Case(750.0)])
    assert all(o.out_of_domain_intervals == 0 and not o.failed for o in outcomes)
    series = {o.case.rpm: [pd.DataFrame(o.sizes, columns=list(STATISTICS)).assign(time=o.times)] for o in outcomes}
    data = measured_from_series(series, np.arange(2.0, 20.1, 2.0))
    start = {k: 1.5 * v for k, v in truth.items()}
    est = calibrate(Model(loop, tiny_surrogate, keys, "ann"), data, settings, start)
    table = est.table.set_index("parameter")
    assert est.info["members"] == 2 and est.info["out_of_domain_intervals"] == 0
    for key, true in truth.items():
        assert table.loc[key, "ci_low"] <= true <= table.loc[key, "ci_high"], (key, table.loc[key].to_dict())
        assert table.loc[key, "sd_ln_surrogate"] > 0, table.to_dict()
        assert table.loc[key, "sd_ln_total"] ** 2 == pytest.approx(
            table.loc[key, "sd_ln_measurement"] ** 2 + table.loc[key, "sd_ln_surrogate"] ** 2
        )
        assert len(table.loc[key, "member_estimates"].split()) == 2


def test_calibrate_command(tiny_config, tiny_surrogate, root, tmp_path, capsys):
    """`pbmdem calibrate` on PBM-ANN's own output: estimates with intervals printed, the files
    written; a bad data file or parameter key: one line naming it, exit status 2."""
    from pbmdem.cli import main

    loop = tiny_config.coupled_loop()
    outcomes = run_cases(loop, tiny_surrogate, [Case(600.0), Case(750.0)])
    series = {o.case.rpm: [pd.DataFrame(o.sizes, columns=list(STATISTICS)).assign(time=o.times)] for o in outcomes}
    data = tmp_path / "measured.csv"
    measured_from_series(series, np.arange(2.0, 20.1, 2.0)).to_csv(data, index=False)
    common = [
        "--config",
        str(root / "config/test.yaml"),
        "--model",
        str(tiny_surrogate),
        "--out",
        str(tmp_path / "out"),
    ]
    args = ["calibrate", *common, "--data", str(data), "--parameters", "pbm.aggregation.beta0", "--jobs", "1"]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "pbm.aggregation.beta0" in printed and "ci_low" in printed
    for name in ("estimates.csv", "correlation.csv", "residuals.csv", "calibration.json", "fit.png"):
        assert (tmp_path / "out" / name).stat().st_size > 0
    estimates = pd.read_csv(tmp_path / "out" / "estimates.csv")
    assert estimates.ci_low[0] <= 2e-4 <= estimates.ci_high[0]

    bad = tmp_path / "bad.csv"
    bad.write_text(HEADER + "600,4,0.002,0.0027,0.0033,1e-5,1e-5,1e-5\n600,2,0.002,0.0026,0.0032,1e-5,1e-5,1e-5\n")
    assert main(["calibrate", *common, "--data", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "row 2, column 'time'" in err
    assert main(["calibrate", *common, "--data", str(data), "--parameters", "pbm.grid.separate_feed"]) == 2
    assert "--parameters: config key 'pbm.grid.separate_feed'" in capsys.readouterr().err


def test_design_space_command(tiny_surrogate, root, tmp_path, capsys):
    """`pbmdem design-space` writes the table, the maps and the figures of merit and prints the
    points of each status."""
    import json
    import logging

    from pbmdem.cli import main

    out = tmp_path / "design"
    args = ["design-space", "--config", str(root / "config/test.yaml"), "--model", str(tiny_surrogate)]
    level = logging.getLogger("pbmdem.coupling").level
    assert main([*args, "--out", str(out), "--jobs", "1"]) == 0
    assert logging.getLogger("pbmdem.coupling").level == level  # the loops' logs held back for the command only
    printed = json.loads(capsys.readouterr().out)
    table = pd.read_csv(out / "design_space.csv")
    assert printed["points"] == len(table) == 18
    assert sum(v for k, v in printed.items() if k not in ("out", "points")) == 18
    assert (out / "design_space.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    info = json.loads((out / "design_space.json").read_text())
    assert info["batches"] == 54 and info["n_jobs"] == 1
    assert main([*args, "--out", str(out), "--jobs", "0"]) == 2
    assert "--jobs 0: allowed 1 or more processes" in capsys.readouterr().err


def test_maps_are_drawn_for_a_grid_of_one_speed_and_for_failed_points(tmp_path):
    """Contours need two values on each axis: a grid of one speed (a DEM grid of one speed) gets
    the status markers only; NaN sizes of failed points are left blank."""
    from pbmdem.design.space import plot_design_space

    spec = Specification(d50_min=0.008, d50_max=0.010, d90_max=0.014)
    rows = []
    for rpm in (600.0, 900.0):
        for rate in (1e-7, 1.2e-7):
            d50 = float("nan") if rpm == 900.0 and rate == 1.2e-7 else 0.009
            point = _point(d50, d50 * 0.95, d50 * 1.05, 0.012, 0.011, 0.013, failed=int(d50 != d50))
            rows.append({"rpm": rpm, "liquid_rate": rate, THIRD: 8.0, **point})
    table = pd.DataFrame(rows)
    table["spec_status"] = specification_status(table, spec)
    for name, part in (("two", table), ("one", table[table.rpm == 600.0])):
        plot_design_space(part, THIRD, spec, tmp_path / f"{name}.png")
        assert (tmp_path / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert list(table.spec_status) == ["meets", "meets", "meets", "failed"]
