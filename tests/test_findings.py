"""The findings the report opens with (feed blends, the PBM-ANN study tables in words and figures)
and the report's display fixes: readable log ticks, hyperparameters in words."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pbmdem.config import SizeDistribution
from pbmdem.coupling.studies import blend, feed_cases
from pbmdem.report import findings
from pbmdem.report.provenance import hyperparameters, kernel_source
from pbmdem.report.training import training_set, training_words

FINE = SizeDistribution(diameters=(0.002, 0.003, 0.004), number_fractions=(0.5, 0.3, 0.2))
COARSE = SizeDistribution(diameters=(0.0032, 0.005, 0.008), number_fractions=(0.3, 0.4, 0.3))


def test_a_blend_holds_each_feed_by_mass_and_lies_between_them():
    mix = blend(FINE, COARSE, 0.5)
    assert list(mix.diameters) == sorted(set(FINE.diameters) | set(COARSE.diameters))
    assert sum(mix.number_fractions) == pytest.approx(1.0)
    mass = np.asarray(mix.number_fractions) * np.asarray(mix.diameters) ** 3
    from_fine = sum(m for d, m in zip(mix.diameters, mass) if d in FINE.diameters)
    assert from_fine / mass.sum() == pytest.approx(0.5)
    assert FINE.mass_median < mix.mass_median < COARSE.mass_median
    with pytest.raises(ValueError, match="allowed 0 < share < 1"):
        blend(FINE, COARSE, 1.0)


def test_feed_cases_put_a_blend_between_neighbours():
    cases = feed_cases({"coarse": COARSE, "fine": FINE})
    assert [(name, in_grid) for name, _, in_grid in cases] == [
        ("fine", True),
        ("fine+coarse", False),
        ("coarse", True),
    ]


def _study(x, d50, **extra) -> pd.DataFrame:
    d50 = np.asarray(d50, float)
    frame = pd.DataFrame({**x, "d10": 0.7 * d50, "d50": d50, "d90": 1.3 * d50, "out_of_domain_intervals": 0})
    for s in ("d10", "d50", "d90"):
        frame[f"{s}_member_min"] = frame[s] - 1e-5
        frame[f"{s}_member_max"] = frame[s] + 2e-5
    return frame.assign(**extra)


def _one_speed_comparison() -> pd.DataFrame:
    """A comparison table of one validation speed, PBM-ANN just inside the PBM-DEM band."""
    return pd.DataFrame(
        [
            {
                "rpm": 300.0,
                "in_training_grid": True,
                "n_dem_replicates": 3,
                "d50_end_ann_mm": 4.01,
                "d50_end_dem_mm": 4.0,
                "d50_end_dem_min_mm": 3.98,
                "d50_end_dem_max_mm": 4.02,
                "ann_d50_outside_band_max": 0.003,
                "cpu_time_ratio_dem_over_ann": 5000.0,
            }
        ]
    )


def test_findings_state_the_answers_with_their_numbers(tmp_path):
    speed = _study({"rpm": [300.0, 600.0, 1200.0]}, [0.004, 0.0042, 0.0045], in_grid_range=True, dem_speed=True)
    speed.loc[2, "out_of_domain_intervals"] = 1
    feed = _study(
        {"feed": ["fine", "fine+coarse", "coarse"], "feed_d50": [0.003, 0.004, 0.006]},
        [0.0040, 0.0050, 0.0070],
        in_grid=[True, False, True],
    )
    comparison = _one_speed_comparison()
    for name in ("speed.png", "feed.png"):
        fig = (
            findings.speed_figure(speed, "fine", 480.0) if name == "speed.png" else findings.feed_figure(feed, 600, 480)
        )
        fig.savefig(tmp_path / name)
        findings.pyplot().close(fig)
    text = findings.findings_rst(
        speed,
        feed,
        comparison,
        speed_feed="fine",
        feed_rpm=600.0,
        batch_s=480.0,
        speed_png=tmp_path / "speed.png",
        feed_png=tmp_path / "feed.png",
        training="The surrogate was trained on 9 DEM runs.",
    )
    assert "from 300 to 1200 rpm changes the granule size after the 8 min batch from d50 = 4.00 mm to 4.50 mm" in text
    assert "(+12.5 %)" in text and "disagree on the final d50 by at most 0.03 mm" in text
    assert "left its training domain at 1 of 3 speeds (1200 rpm)" in text
    assert "goes from 4.00 mm for the finest feed, ``fine``" in text and "7.00 mm for the coarsest, ``coarse``" in text
    assert "a coarser feed gives larger granules at every step" in text
    assert "The blend between the grid's feeds (``fine+coarse``) was not in the DEM grid" in text
    assert "at 300 rpm (a speed of the DEM grid) PBM-ANN's final d50 is 4.01 mm against 4.00 mm" in text
    # the figures travel inside the text (Snakemake's report includes it), as data URIs
    assert text.count(".. image:: data:image/png;base64,") == 2
    # the glossary closes the findings
    assert "* **PBM-ANN**: the PBM with the surrogate" in text
    assert text.index("**How far to trust them.**") < text.index("Glossary\n--------")
    # what the surrogate was trained on follows the validation, before the glossary
    learned = text.index("**What the surrogate was trained on.** The surrogate was trained on 9 DEM runs.")
    assert text.index("**How far to trust them.**") < learned < text.index("Glossary\n--------")


def test_the_report_states_the_surrogates_training_set_beside_its_accuracy(tmp_path):
    """The training set (DEM runs, operating points, replicates, speeds, feeds) is read from the
    table the surrogate was trained on, the accuracy from its metadata: a real (tiny) training."""
    import warnings

    from synthetic_tables import make_synthetic_tables

    from pbmdem.config import Surrogate
    from pbmdem.readers import InputFileError
    from pbmdem.surrogate.train import train_and_report
    from pbmdem.tables import GRID_PAIRS

    radius = 0.0265
    fractions = {"fine": [0.6, 0.3, 0.1], "coarse": [0.2, 0.3, 0.5]}
    table, _ = make_synthetic_tables(radius, rpms=(300, 600, 900), distributions=fractions, n_replicates=3, seed=5)
    csv = tmp_path / "collisions.csv"
    table.to_csv(csv, index=False)
    settings = {
        "hidden_layer_sizes": [[4]],
        "alpha": [0.1],
        "ensemble_size": 2,
        "seeds": [3, 4],
        "max_iter": 300,
        "cv": {"strategy": "group_kfold", "n_splits": 3},
        "model": "mlp",
    }
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meta = train_and_report(
            csv, tmp_path / "model.skops", settings=Surrogate.from_section(settings).to_dict(), impeller_radius=radius
        )
    grid = GRID_PAIRS.read(csv, need=("point_id", "rpm", "distribution", "n_replicates"))
    training = training_set(grid, str(csv), meta["training_point_ids"])
    assert (training["runs"], training["points"], training["replicates"]) == (18, 6, (3,))
    words = training_words(training, meta, "results/dem/collisions.csv")
    assert words.startswith(
        "The surrogate was trained on 18 DEM runs: 6 operating points (impeller speeds 300, 600 and 900 rpm; "
        "feeds coarse and fine) with 3 replicates each (DEM insertion seeds), the table "
        "``results/dem/collisions.csv``."
    ), words
    held_out = meta["cv_scores"]["outer_summary"]["mlp"]
    assert "(group kfold cross-validation, 3 folds, whole points held out)" in words
    assert "its kernel source, the MLP ensemble (ANN), predicts log10 of the encounter frequency" in words
    assert f"R2 = {held_out['pooled_r2_log10']:.3f}" in words
    assert f"mean absolute error of {held_out['pooled_mae_log10']:.3f} decades" in words
    assert f"allows R2 = {held_out['noise_floor_r2_log10']:.3f} at best" in words
    # single-replicate points: the metadata holds no noise floor (None), and the words say so
    import copy

    single = copy.deepcopy(meta)
    single["cv_scores"]["outer_summary"]["mlp"]["noise_floor_r2_log10"] = None
    words = training_words(training, single, "results/dem/collisions.csv")
    assert "the noise floor is not known (no point was run more than once)" in words
    assert f"R2 = {held_out['pooled_r2_log10']:.3f}" in words
    # a point the surrogate was trained on that the table lacks: the table changed after training
    with pytest.raises(InputFileError, match=r"collisions.csv: the surrogate was trained on operating point\(s\) "
                                             r"\['rpm1500_fine'\] that it lacks"):  # fmt: skip
        training_set(grid, str(csv), [*meta["training_point_ids"], "rpm1500_fine"])


def test_a_speed_above_which_the_granules_get_smaller_is_named():
    """With breakage the final d50 can peak inside the speed range: the words say where, not that more
    collisions make larger granules; a fall within the members' spread is not called a peak."""
    speed = _study({"rpm": [150.0, 600.0, 900.0, 1200.0]}, [0.0058, 0.0103, 0.0105, 0.0075])
    words = findings.speed_paragraph(speed, "fine", 480.0)
    assert "grows with the speed up to 900 rpm (d50 = 10.50 mm) and falls above it" in words
    assert "more collisions make larger granules" not in words
    flat = _study({"rpm": [150.0, 600.0, 900.0, 1200.0]}, [0.0058, 0.0103, 0.0105, 0.010495])
    words = findings.speed_paragraph(flat, "fine", 480.0)
    assert "falls above it" not in words and "more collisions make larger granules" in words


def test_a_feed_that_breaks_the_trend_is_named():
    feed = _study(
        {"feed": ["fine", "fine+coarse", "coarse"], "feed_d50": [0.003, 0.004, 0.006]},
        [0.0097, 0.0068, 0.0132],
        in_grid=[True, False, True],
    )
    assert (
        "; the final size does not simply follow the feed: it is smaller for ``fine+coarse`` than for the next "
        "finer feed. "
    ) in findings.feed_paragraph(feed, 900.0)


def test_findings_figures_name_axes_speed_feed_and_uncertainty():
    speed = _study({"rpm": [300.0, 750.0, 1200.0]}, [0.004, 0.0042, 0.0045], in_grid_range=True, dem_speed=[1, 0, 1])
    fig = findings.speed_figure(speed, "fine", 480.0)
    ax = fig.axes[0]
    assert ax.get_ylabel() == "final granule size (mm)" and ax.get_xlabel().startswith("impeller speed (rpm)")
    assert "feed fine" in ax.get_title() and "8 min" in ax.get_title()
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "range of the surrogate's members" in labels
    findings.pyplot().close(fig)


@pytest.mark.parametrize("limits", [(0.045, 0.095), (0.03, 0.9), (0.02, 3.0), (1e-3, 10.0), (200.0, 1300.0)])
def test_log_tick_labels_never_overlap(limits):
    """matplotlib labels every minor tick of a short log axis, and the labels run together
    ("0.050.060.07..."); with log_ticks the drawn labels never overlap, at least two are shown,
    and they are plain numbers."""
    from pbmdem.plotting import log_ticks
    from pbmdem.report.figures import pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(4.0, 3.0))
    ax.loglog(limits, limits)
    ax.set_xlim(*limits)
    log_ticks(ax, "x")
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    lo, hi = ax.get_xlim()
    ticks = list(zip(ax.xaxis.get_majorticklocs(), ax.xaxis.get_majorticklabels())) + list(
        zip(ax.xaxis.get_minorticklocs(), ax.xaxis.get_minorticklabels())
    )
    drawn = sorted((loc, t) for loc, t in ticks if lo <= loc <= hi and t.get_text())
    assert len(drawn) >= 2, [t.get_text() for _, t in drawn]
    boxes = [t.get_window_extent(renderer) for _, t in drawn]
    for (a, ta), (b, tb) in zip(zip(boxes, drawn), zip(boxes[1:], drawn[1:])):
        assert a.x1 <= b.x0, (ta[1].get_text(), tb[1].get_text())
    assert all("$" not in t.get_text() and "e" not in t.get_text() for _, t in drawn)
    plt.close(fig)


def test_kernel_source_in_words():
    mlp = {
        "family": "mlp",
        "cv_scores": {"selection": "surrogate.model = mlp"},
        "frequency_state": {"n_outputs": 1, "best_params": {"hidden_layer_sizes": [8], "alpha": 0.1}},
    }
    assert kernel_source(mlp) == (
        "Kernel source: mlp (surrogate.model = mlp); selected hyperparameters hidden layers (neurons per layer) 8, "
        "L2 penalty alpha 0.1"
    )
    kriging = {"family": "kriging", "cv_scores": {"selection": "auto"}, "frequency_state": {"fitted": ["1**2 * RBF"]}}
    assert kernel_source(kriging) == "Kernel source: kriging (auto); fitted 1**2 * RBF"
    assert kernel_source({}) == "Kernel source: not recorded (not recorded); fitted not recorded"
    mixed = {**kriging, "velocity_family": "mlp", "cv_scores": {"selection": "auto", "speed_law_selection": "tv"}}
    assert kernel_source(mixed) == "Kernel source: kriging (auto); fitted 1**2 * RBF; impact-speed law: mlp (tv)"
    tail = {"from_m_s": 1.7782794100389228, "a": 11.385, "beta": 0.6077, "sd_ln_a_between_runs": 0.1425}
    assert kernel_source({**kriging, "speed_tail": tail}) == (
        "Kernel source: kriging (auto); fitted 1**2 * RBF; pair impacts faster than 1.78 m/s: one tail for every "
        "pair and run, P(V > v) falling as exp(-11.4 (v / v_tip)^0.61), the members' scale spread by 0.14 in ln a "
        "(the scatter between DEM beds)"
    )


def test_hyperparameters_in_words():
    assert hyperparameters({"hidden_layer_sizes": [8, 8], "alpha": 0.1}) == (
        "hidden layers (neurons per layer) 8 x 8, L2 penalty alpha 0.1"
    )
    assert hyperparameters({}) == "not recorded"
    nested = hyperparameters({"frequency": {"alpha": 1.0}, "velocity": {"mlp__alpha": 0.01}})
    assert nested == "frequency: L2 penalty alpha 1; velocity: L2 penalty alpha 0.01"
    assert "{" not in nested


def test_the_breakage_finding_is_followed_by_the_clipping_line(tmp_path):
    """write_findings puts the grid floor's line (report.breakage.clipping_words) after the breakage
    finding, from the merged_fraction columns of the speed, feed and breakage studies."""
    from pbmdem.report.findings import write_findings

    speed = _study({"rpm": [300.0, 900.0]}, [0.004, 0.005], feed="fine", in_grid_range=True, dem_speed=True)
    speed = speed.assign(merged_fraction=[0.0, 0.02], merged_fraction_member_max=[0.0, 0.03])
    feed = _study({"feed": ["fine"], "feed_d50": [0.003]}, [0.004], in_grid=True, rpm=300.0)
    feed = feed.assign(merged_fraction=0.0, merged_fraction_member_max=0.0)
    breakage = pd.concat(
        [
            _study({"rpm": [300.0, 900.0]}, [0.004, d], feed="fine", variant=v, critical_speed=2.0, merged_fraction=0.0)
            for v, d in (("off", 0.005), ("default", 0.0045))
        ]
    )
    comparison = _one_speed_comparison()
    paths = {}
    for name, frame in (("speed", speed), ("feed", feed), ("breakage", breakage), ("comparison", comparison)):
        paths[name] = tmp_path / f"{name}.csv"
        frame.to_csv(paths[name], index=False)
    out = {k: tmp_path / f"{k}.png" for k in ("speed_png", "feed_png", "breakage_png")} | {"rst": tmp_path / "f.rst"}
    write_findings(
        speed=paths["speed"], feed=paths["feed"], comparison=paths["comparison"], speed_feed="fine",
        feed_rpm=300.0, batch_s=480.0, breakage=paths["breakage"], out=out,
    )  # fmt: skip
    text = out["rst"].read_text()
    line = "**Clipping at the grid floor.** clipping: breakage fragments merged at the grid floor amount to 3 %"
    assert line in text and text.index("**Breakage.**") < text.index(line) < text.index("**How far to trust them.**")
    assert "the speed study's batch at 900 rpm, feed fine (an ensemble member)" in text
    assert "FLAGGED: 2 above 1 % of their final number" in text
