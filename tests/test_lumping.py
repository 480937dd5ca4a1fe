"""What lumping leaves out (issue 37 item 4): the 1-D against the 2-D PBM under PBM-ANN
(pbmdem.coupling.lumping), the liquid per size class, and the report's figure, table and words
(pbmdem.report.lumping). All in SI units."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from pbmdem.coupling.lumping import CASE_COLUMNS, LIQUID_COLUMNS, liquid_per_size, lumping_study
from pbmdem.pbm.setup import build_model
from pbmdem.pbm.state import State


def test_the_study_runs_both_models_on_every_case_once(tiny_config, tiny_surrogate):
    """Every study's cases in both models (a case several studies share runs once), the solid of
    the 2-D batches conserved, its default row the same batch as PBM-ANN with pbm.dimensions 2 run
    alone, the liquid table of the default batch holding all the solid and liquid of both models."""
    from pbmdem.coupling.methods import pbm_ann
    from pbmdem.coupling.studies import feed_cases

    loop = tiny_config.coupled_loop()
    rpm, speeds = 600.0, [600.0, 900.0]
    rates = [loop.batch.pbm.liquid_addition.rate, 1.1 * loop.batch.pbm.liquid_addition.rate]
    feeds = {name: tiny_config.distribution(name) for name in tiny_config.grid.size_distributions}
    cases, liquid, info = lumping_study(loop, tiny_surrogate, rpm, speeds, rates, feeds)
    assert list(cases.columns) == list(CASE_COLUMNS) and list(liquid.columns) == list(LIQUID_COLUMNS)
    n_feeds = len(feed_cases(feeds))
    assert list(cases.study.value_counts().sort_index().items()) == [
        ("binder", 2),
        ("default", 1),
        ("feed", n_feeds),
        ("speed", 2),
    ]
    # the default batch is also the speed study's 600 rpm, the first binder rate and the first feed
    assert info["cases"] == len(cases) == 5 + n_feeds and info["batches"] == 2 * (len(cases) - 3)
    assert (cases.failed == "").all()
    for m in ("1d", "2d"):
        assert np.isfinite(cases[[f"d10_{m}", f"d50_{m}", f"d90_{m}"]].to_numpy(float)).all()
        assert (cases[f"d50_{m}"] > 0.9 * loop.batch.sizes.mass_median).all()
    assert np.abs(cases.solid_rel_change_2d).max() < 1e-12
    assert np.allclose(cases.d50_rel_diff, (cases.d50_2d - cases.d50_1d) / cases.d50_1d, rtol=1e-12, atol=0)
    assert info["cpu_time_s_2d"] > 0 and info["cpu_time_s_1d"] > 0 and info["rpm"] == rpm
    default = cases[cases.study == "default"].iloc[0]
    two = loop.replace(batch=loop.batch.replace(pbm=loop.batch.pbm.replace(dimensions=2)))
    alone = pbm_ann(two, tiny_surrogate, rpm, None).result.summary().iloc[-1]
    assert default.d50_2d == pytest.approx(alone.d50, rel=1e-12)
    for m in ("1d", "2d"):
        assert liquid[f"solid_fraction_{m}"].sum() == pytest.approx(1.0, rel=1e-9)
    # the solid-weighted mean of the classes' liquid content is the batch's (both models nearly agree)
    mean2 = np.nansum(liquid.solid_fraction_2d * liquid.liquid_content_2d_mean)
    mean1 = np.nansum(liquid.solid_fraction_1d * liquid.liquid_content_1d)
    assert mean2 == pytest.approx(mean1, rel=1e-3) and mean2 > 0
    ok = liquid.dropna(subset=["liquid_content_2d_sd"])
    assert (ok.liquid_content_2d_sd >= 0).all()
    assert (ok.liquid_content_2d_min <= ok.liquid_content_2d_mean * (1 + 1e-12)).all()
    assert (ok.liquid_content_2d_max >= ok.liquid_content_2d_mean * (1 - 1e-12)).all()


class _Run:
    """What liquid_per_size reads of a Result: grid, state, and for the 2-D model classes, class_volumes."""

    def __init__(self, grid, state, classes=None, class_volumes=None):
        self.grid, self.state, self.classes, self.class_volumes = grid, state, classes, class_volumes


def test_a_size_class_half_dry_is_wet_when_lumped(tiny_config):
    """One size class of ten granules, five at liquid/solid 0.1 and five at 0.5, gas 0.2 of the
    solid: the lumped class (0.3) is wet, while in the 2-D classes the drier half holds its liquid
    in its pores (surface liquid 0) and cannot coalesce. Mean 0.3, spread 0.2, range 0.1-0.5."""
    pbm = tiny_config.pbm_batch("small").pbm
    model = build_model(pbm.replace(dimensions=2))
    grid, lg = model.grid, model.liquid_grid
    K, k = grid.bins, 3
    x = float(grid.x[k])  # m3
    one = State(0.0, np.zeros(K), np.zeros(K), np.zeros(K))
    one.number[k], one.liquid[k], one.gas[k] = 10.0, 10 * 0.3 * x, 10 * 0.2 * x
    classes = np.zeros((3, K, lg.classes))
    for ratio in (0.1, 0.5):
        e = int(lg.classify([ratio])[0])
        classes[:, k, e] = (5.0, 5 * ratio * x, 5 * 0.2 * x)
    table = liquid_per_size(_Run(grid, one), _Run(grid, None, classes[None], grid.x.copy()), threshold=0.02)
    assert len(table) == 1
    row = table.iloc[0]
    assert (row.size_class, row.kind) == (k, "aggregate") and row.diameter == pytest.approx(grid.d[k], rel=1e-12)
    assert row.liquid_content_1d == pytest.approx(0.3) and row.liquid_content_2d_mean == pytest.approx(0.3)
    assert row.liquid_content_2d_sd == pytest.approx(0.2)
    assert (row.liquid_content_2d_min, row.liquid_content_2d_max) == pytest.approx((0.1, 0.5))
    assert row.dry_solid_fraction_1d == 0.0 and row.dry_solid_fraction_2d == pytest.approx(0.5)
    # different size classes in the two runs are refused
    with pytest.raises(Exception, match="different size classes"):
        liquid_per_size(_Run(grid, one), _Run(grid, None, classes[None][:, :, :-1], grid.x[:-1]), 0.02)


def _cases(d50_1d, d50_2d, speeds=(300.0, 600.0, 900.0, 1200.0)) -> pd.DataFrame:
    """A cases table: the speed study at `speeds` and two feeds, with the given d50 (m)."""
    rows = []
    for study, rpm, feed, a, b in (
        [("default", speeds[0], "fine", d50_1d[0], d50_2d[0])]
        + [("speed", r, "fine", a, b) for r, a, b in zip(speeds, d50_1d, d50_2d)]
        + [("feed", speeds[0], "fine", d50_1d[0], d50_2d[0]), ("feed", speeds[0], "coarse", 0.009, 0.009)]
    ):
        row = {"study": study, "rpm": rpm, "liquid_rate": 6.4e-8, "feed": feed, "feed_d50": 0.003}
        for s, f in (("d10", 0.7), ("d50", 1.0), ("d90", 1.3)):
            row |= {f"{s}_1d": f * a, f"{s}_2d": f * b, f"{s}_rel_diff": (b - a) / a}
        row |= {"solid_rel_change_2d": 0.0, "out_of_domain_intervals": 0, "cpu_time_s_1d": 0.02}
        rows.append(row | {"cpu_time_s_2d": 0.5, "failed": ""})
    return pd.DataFrame(rows)[list(CASE_COLUMNS)]


def _liquid() -> pd.DataFrame:
    return pd.DataFrame(
        [
            [0, "aggregate", 0.004, 0.6, 0.6, 0.40, 0.40, 0.05, 0.3, 0.55, 0.0, 0.0],
            [1, "feed", 0.002, 0.4, 0.4, 0.60, 0.60, 0.0, 0.6, 0.6, 0.0, 0.0],
        ],
        columns=list(LIQUID_COLUMNS),
    )


INFO = {"batches": 12, "cpu_time_s_1d": 0.12, "cpu_time_s_2d": 3.0, "success_threshold": 0.02}


def test_the_words_say_where_lumping_is_adequate_and_whether_an_answer_changes():
    from pbmdem.report.lumping import lumping_table, lumping_words, turn_speeds

    same = _cases([0.006, 0.009, 0.010, 0.007], [0.006, 0.009, 0.010, 0.007 * 1.001])
    assert turn_speeds(same) == (900.0, 900.0)
    words = lumping_words(same, _liquid(), INFO)
    assert "differ by at most 0.1 %" in words and "speed study 0.1 % (largest at 1200 rpm)" in words
    assert "900 rpm with the lumped model and 900 rpm with the two-dimensional one (unchanged)" in words
    assert "the feeds end in the same order of final d50 (fine, coarse)" in words
    assert "spreads by a standard deviation of up to 0.050 (at 4.00 mm" in words
    assert "Less than 1e-06 of the batch's solid is below the success threshold" in words
    assert "adequate (sizes within 1 %" in words and "It is not for" not in words
    assert "0.12 s of CPU for the lumped and 3.0 s for the two-dimensional model (25x)" in words
    # the 2-D model turns at 600 rpm and ends 5 % smaller at 900 rpm: an answer changes, and is said to
    changed = _cases([0.006, 0.009, 0.010, 0.007], [0.006, 0.0095, 0.0095, 0.007])
    assert turn_speeds(changed) == (900.0, 600.0)
    words = lumping_words(changed, _liquid().assign(dry_solid_fraction_2d=[0.5, 0.0]), INFO)
    assert "900 rpm with the lumped model and 600 rpm with the two-dimensional one (CHANGED)" in words
    assert "It is not for: speed study: use ``pbm.dimensions: 2`` there." in words
    assert "30 % of the batch's solid is below the success threshold (surface liquid fraction 0.02)" in words
    table = lumping_table(changed)
    assert list(table.columns[:4]) == ["study", "case", "d50 1-D (mm)", "d50 2-D (mm)"]
    assert table.loc[table.case == "600 rpm", "d50 2-D vs 1-D (%)"].item() == "5.6"
    assert table.loc[table.case == "600 rpm", "d50 2-D (mm)"].item() == "9.500"


def test_the_figure_and_the_findings_section(tmp_path):
    """The figure's axes and units; write_findings with the study: its words and figure in the
    findings before 'How far to trust them', its display table as CSV and HTML."""
    from test_findings import _one_speed_comparison, _study

    from pbmdem.report.findings import write_findings
    from pbmdem.report.lumping import lumping_figure

    cases = _cases([0.006, 0.009, 0.010, 0.007], [0.006, 0.009, 0.010, 0.007])
    cases = pd.concat([cases, cases[cases.study == "default"].assign(study="binder")], ignore_index=True)
    fig = lumping_figure(cases, _liquid())
    labels = [(ax.get_xlabel(), ax.get_ylabel()) for ax in fig.axes]
    assert labels == [
        ("impeller speed (rpm)", "final d10, d50, d90 (mm)"),
        ("binder rate (mL/min)", "final d10, d50, d90 (mm)"),
        ("feed d50 (mm)", "final d10, d50, d90 (mm)"),
        ("granule diameter (mm)", "liquid content L/S (m3 liquid / m3 solid)"),
    ]
    line = next(ln for ln in fig.axes[0].get_lines() if ln.get_label() == "2-D (size x liquid)")
    np.testing.assert_allclose(line.get_ydata(), [6.0, 9.0, 10.0, 7.0])  # mm
    fig.clf()
    paths = {}
    speed = _study({"rpm": [300.0, 900.0]}, [0.004, 0.005], feed="fine", in_grid_range=True, dem_speed=True)
    feed = _study({"feed": ["fine"], "feed_d50": [0.003]}, [0.004], in_grid=True, rpm=300.0)
    for name, frame in (("speed", speed), ("feed", feed), ("comparison", _one_speed_comparison())):
        paths[name] = tmp_path / f"{name}.csv"
        frame.to_csv(paths[name], index=False)
    cases.to_csv(tmp_path / "lumping.csv", index=False)
    _liquid().to_csv(tmp_path / "liquid.csv", index=False)
    (tmp_path / "lumping.json").write_text(json.dumps(INFO))
    out = {k: tmp_path / f"{k}.png" for k in ("speed_png", "feed_png", "breakage_png", "lumping_png")}
    out |= {"rst": tmp_path / "f.rst", "lumping_csv": tmp_path / "t.csv", "lumping_html": tmp_path / "t.html"}
    write_findings(
        speed=paths["speed"], feed=paths["feed"], comparison=paths["comparison"], speed_feed="fine",
        feed_rpm=300.0, batch_s=480.0, out=out, lumping=tmp_path / "lumping.csv",
        lumping_liquid=tmp_path / "liquid.csv", lumping_info=tmp_path / "lumping.json",
    )  # fmt: skip
    text = out["rst"].read_text()
    head = "**What lumping leaves out.** The PBM gives every size class one mean liquid content"
    assert head in text and text.index(head) < text.index("**How far to trust them.**")
    assert text.count(".. image:: data:image/png;base64,") == 3 and out["lumping_png"].stat().st_size > 0
    shown = pd.read_csv(out["lumping_csv"])
    assert len(shown) == len(cases) and "d50 2-D vs 1-D (%)" in shown.columns
    page = out["lumping_html"].read_text()
    assert "the speed above which the granules get smaller: 900 rpm and 900 rpm (1-D and 2-D)" in page


def test_a_broken_lumping_table_or_cost_file_is_named(tmp_path):
    """write_findings refuses a lumping table without its columns and an unreadable cost file,
    naming the file (no traceback of pandas or json)."""
    from test_findings import _one_speed_comparison, _study

    from pbmdem.readers import InputFileError
    from pbmdem.report.findings import write_findings

    speed = _study({"rpm": [300.0, 900.0]}, [0.004, 0.005], feed="fine", in_grid_range=True, dem_speed=True)
    feed = _study({"feed": ["fine"], "feed_d50": [0.003]}, [0.004], in_grid=True, rpm=300.0)
    for name, frame in (("speed", speed), ("feed", feed), ("comparison", _one_speed_comparison())):
        frame.to_csv(tmp_path / f"{name}.csv", index=False)
    cases = _cases([0.006, 0.009, 0.010, 0.007], [0.006, 0.009, 0.010, 0.007])
    cases.drop(columns="d50_2d").to_csv(tmp_path / "bad.csv", index=False)
    cases.to_csv(tmp_path / "lumping.csv", index=False)
    _liquid().to_csv(tmp_path / "liquid.csv", index=False)
    (tmp_path / "lumping.json").write_text("{not json")
    out = {k: tmp_path / f"{k}.png" for k in ("speed_png", "feed_png", "breakage_png", "lumping_png")}
    out |= {"rst": tmp_path / "f.rst", "lumping_csv": tmp_path / "t.csv", "lumping_html": tmp_path / "t.html"}
    common = {"speed": tmp_path / "speed.csv", "feed": tmp_path / "feed.csv", "comparison": tmp_path / "comparison.csv"}
    common |= {"speed_feed": "fine", "feed_rpm": 300.0, "batch_s": 480.0, "out": out}
    common |= {"lumping_liquid": tmp_path / "liquid.csv", "lumping_info": tmp_path / "lumping.json"}
    with pytest.raises(InputFileError, match=r"bad.csv: missing column\(s\) \['d50_2d'\]"):
        write_findings(**common, lumping=tmp_path / "bad.csv")
    with pytest.raises(InputFileError, match="lumping.json cannot be read as JSON"):
        write_findings(**common, lumping=tmp_path / "lumping.csv")
    assert not out["rst"].exists()
