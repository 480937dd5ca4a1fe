"""The findings the report and the README open with: how impeller speed and the feed change granule
growth (a figure and words each), the other studies' findings, then how far to trust them
(`write_findings`, rule report_findings; docs/validation.md, "Report").
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.atomic import write_text
from pbmdem.coupling.lumping import CASE_COLUMNS, LIQUID_COLUMNS
from pbmdem.design.sensitivity import COLUMNS as SOBOL_COLUMNS
from pbmdem.plotting import SIZE_STYLES, final_sizes, pyplot, save_figure
from pbmdem.readers import InputFileError, read_table
from pbmdem.surrogate.persistence import read_metadata
from pbmdem.tables import GRID_PAIRS
from pbmdem.validation.feed_check import CHECK_COLUMNS

from . import words
from .breakage import breakage_figure, breakage_words, clipping_words, peak_speed
from .display import MM
from .figures import legend_below
from .lumping import lumping_figure, lumping_table, lumping_words, turn_speeds
from .sensitivity import sensitivity_words
from .training import training_set, training_words
from .words import write_titled_table


def _domain_marks(ax, x, frame: pd.DataFrame) -> None:
    """Circles on the sizes of the batches with intervals outside the training domain, and their legend entry."""
    outside = frame.out_of_domain_intervals.to_numpy(int) > 0
    for stat, _, _ in SIZE_STYLES:
        ax.scatter(
            np.asarray(x)[outside],
            MM * frame[stat].to_numpy(float)[outside],
            s=140,
            facecolors="none",
            edgecolors="tab:purple",
            lw=1.6,
            zorder=5,
        )
    if outside.any():
        ax.scatter(
            [], [], s=140, facecolors="none", edgecolors="tab:purple", label="surrogate outside its training domain"
        )


def speed_figure(study: pd.DataFrame, feed: str, batch_s: float):
    """Final d10/d50/d90 against impeller speed, with the ensemble-member band."""
    plt = pyplot()
    s = study.sort_values("rpm")
    fig, ax = plt.subplots(figsize=(8.0, 5.6))
    final_sizes(ax, s.rpm, s, band=True)
    ax.fill_between([], [], [], color="0.5", alpha=0.25, label="range of the surrogate's members")
    dem = s[s.dem_speed.astype(bool)]
    ax.scatter(dem.rpm, np.full(len(dem), 0.0), marker="|", s=300, color="0.3", clip_on=False, zorder=6)
    outside_range = s[~s.in_grid_range.astype(bool)]
    for rpm in outside_range.rpm:
        ax.axvspan(rpm - 0.5 * _step(s.rpm), rpm + 0.5 * _step(s.rpm), color="tab:purple", alpha=0.08, lw=0)
    _domain_marks(ax, s.rpm, s)
    ax.set_ylim(bottom=0.0)
    if len(s) <= 12:
        ax.set_xticks(s.rpm, [f"{v:g}" for v in s.rpm])
    ax.set(
        xlabel="impeller speed (rpm)   (| = speeds with DEM runs)",
        title=f"Granule size after the {batch_text(batch_s)} batch against impeller speed (PBM-ANN, feed {feed})",
    )
    _legend_below(fig, ax)
    return fig


def _legend_below(fig, ax) -> None:
    ax.title.set_fontsize(10.5)
    legend_below(fig, ax, 2, 0.13)


def batch_text(seconds: float) -> str:
    """'8 min' or '20 s': the batch length in words."""
    return f"{seconds / 60:.3g} min" if seconds >= 120 else f"{seconds:.3g} s"


def _step(values) -> float:
    v = np.sort(np.asarray(values, float))
    return float(np.min(np.diff(v))) if len(v) > 1 else 1.0


def feed_figure(study: pd.DataFrame, rpm: float, batch_s: float):
    """Final d10/d50/d90 against the feed (ordered by the feed's mass-median diameter)."""
    plt = pyplot()
    s = study.sort_values("feed_d50").reset_index(drop=True)
    x = np.arange(len(s))
    fig, ax = plt.subplots(figsize=(8.0, 5.6))
    for stat, marker, color in SIZE_STYLES:
        lo = MM * (s[stat] - s[f"{stat}_member_min"])
        hi = MM * (s[f"{stat}_member_max"] - s[stat])
        ax.errorbar(
            x,
            MM * s[stat],
            yerr=np.vstack([lo.clip(lower=0), hi.clip(lower=0)]),
            marker=marker,
            color=color,
            lw=1.8,
            capsize=4,
            label=f"final {stat} (bars: surrogate members' range)",
        )
    ax.plot(x, MM * s.feed_d50, "s", color="0.55", ms=7, label="feed d50 (before granulation)")
    _domain_marks(ax, x, s)
    labels = [f"{f}\n(not in DEM grid)" if not g else f for f, g in zip(s.feed, s.in_grid.astype(bool))]
    ax.set_xticks(x, labels, fontsize=8)
    ax.set_ylim(bottom=0.0)
    ax.set(
        xlabel="feed size distribution (ordered by its d50; a+b = 50:50 blend by mass)",
        ylabel="granule size (mm)",
        title=f"Granule size after the {batch_text(batch_s)} batch against the feed (PBM-ANN, {rpm:g} rpm)",
    )
    ax.grid(alpha=0.3, axis="y")
    _legend_below(fig, ax)
    return fig


def _spread(frame: pd.DataFrame) -> float:
    """The members' largest disagreement on the final d50 (m)."""
    return max(float(r["d50_member_max"] - r["d50_member_min"]) for _, r in frame.iterrows())


def _outside(frame: pd.DataFrame, column: str) -> list:
    return list(frame[frame.out_of_domain_intervals > 0][column])


def _sizes(row, names) -> dict:
    return {name: row[name] for name in names}


def speed_paragraph(speed: pd.DataFrame, speed_feed: str, batch_s: float) -> str:
    """The answer to "how does the impeller speed change the granules?" (`speed`: one row per speed)."""
    s = speed.sort_values("rpm")
    lo, hi = s.iloc[0], s.iloc[-1]
    peak = peak_speed(s)
    return words.paragraph(
        "speed",
        feed=speed_feed,
        batch=batch_text(batch_s),
        lo=_sizes(lo, ("rpm", "d10", "d50", "d90")),
        hi=_sizes(hi, ("rpm", "d10", "d50", "d90")),
        change=(hi.d50 - lo.d50) / lo.d50 if lo.d50 else float("nan"),
        peak=peak,
        peak_d50=s[s.rpm == peak].iloc[0].d50 if peak is not None else None,
        spread=_spread(s),
        outside=_outside(s, "rpm"),
        n=len(s),
    )


def _dips(f: pd.DataFrame) -> list[str] | None:
    """None when the final d50 rises from each feed to the next coarser one (`f` ordered by the
    feed's d50), else the feeds whose final d50 is at most the next finer feed's."""
    d50 = f.d50.to_numpy(float)
    if np.all(np.diff(d50) > 0):
        return None
    return [str(f.feed.iloc[k + 1]) for k in range(len(d50) - 1) if d50[k + 1] <= d50[k]]


def feed_paragraph(feed: pd.DataFrame, feed_rpm: float) -> str:
    """The answer to "how does the feed size distribution change the granules?" (`feed`: one row per feed)."""
    f = feed.sort_values("feed_d50")
    growth = (f.d50 / f.feed_d50).to_numpy(float)
    return words.paragraph(
        "feed",
        rpm=feed_rpm,
        lo=_sizes(f.iloc[0], ("feed", "feed_d50", "d50")),
        hi=_sizes(f.iloc[-1], ("feed", "feed_d50", "d50")),
        dips=_dips(f),
        growth_min=np.nanmin(growth),
        growth_max=np.nanmax(growth),
        blends=list(f[~f.in_grid.astype(bool)].feed),
        spread=_spread(f),
        outside=[str(v) for v in _outside(f, "feed")],
        n=len(f),
    )


def feed_check_words(check) -> str:
    """The PBM-DEM check of the feed study's most surprising result in one paragraph (`check`: the
    row of results/validation/feed_check.csv, `pbmdem.validation.feed_check.check_table`)."""
    return words.paragraph("feed_check", check=dict(check))


def findings_rst(
    speed: pd.DataFrame,
    feed: pd.DataFrame,
    comparison: pd.DataFrame,
    *,
    speed_feed: str,
    feed_rpm: float,
    batch_s: float,
    speed_png: str,
    feed_png: str,
    extra: tuple[str, ...] = (),
    training: str | None = None,
    feed_check=None,
) -> str:
    """The findings as reStructuredText (template findings.rst.j2), the figures embedded as data URIs
    (Snakemake's own `embeddedimage` directive does not embed); `extra`: further findings (rst lines)."""
    return words.render(
        "findings.rst",
        speed=speed_paragraph(speed, speed_feed, batch_s),
        speed_image=image_directive(speed_png),
        feed=feed_paragraph(feed, feed_rpm),
        feed_image=image_directive(feed_png),
        feed_check=feed_check_words(feed_check) if feed_check is not None else None,
        extra=extra,
        trust=trust_words(comparison),
        training=training,
    )


def image_directive(png) -> str:
    """`.. image::` with the PNG as a data URI over lines of 76 characters (docutils refuses lines
    longer than 10000 characters and joins the lines of a URI)."""
    uri = "data:image/png;base64," + base64.b64encode(Path(png).read_bytes()).decode()
    return ".. image:: " + "\n   ".join(uri[k : k + 76] for k in range(0, len(uri), 76))


def trust_words(comparison: pd.DataFrame) -> str:
    """The validation in one paragraph: PBM-ANN against the coupled PBM-DEM reference."""
    rows = []
    for r in comparison.sort_values("rpm").to_dict("records"):
        ratio = r.get("cpu_time_ratio_dem_over_ann")
        ratio = float("nan") if ratio is None else float(ratio)
        rows.append(
            {
                "rpm": r["rpm"],
                "in_grid": bool(r.get("in_training_grid")),
                "d50_ann": r["d50_end_ann_mm"],
                "d50_dem": r["d50_end_dem_mm"],
                "d50_dem_min": r["d50_end_dem_min_mm"],
                "d50_dem_max": r["d50_end_dem_max_mm"],
                "replicates": int(r["n_dem_replicates"]),
                "outside": float(r["ann_d50_outside_band_max"]),
                "ratio": ratio if np.isfinite(ratio) else None,
            }
        )
    return words.paragraph("trust", rows=rows)


def write_findings(
    *,
    speed,
    feed,
    comparison,
    speed_feed: str,
    feed_rpm: float,
    batch_s: float,
    out: dict,
    breakage=None,
    training=None,
    metadata=None,
    feed_check=None,
    sensitivity=None,
    sensitivity_info=None,
    confidence: float = 0.95,
    lumping=None,
    lumping_liquid=None,
    lumping_info=None,
) -> None:
    """Rule report_findings: the figures and the text (rst) of the findings from the files of the
    studies (each optional one left out when None). `out`: speed_png, feed_png, breakage_png, rst,
    and with `lumping` lumping_png, lumping_csv, lumping_html."""
    speed_table = read_table(speed, "PBM-ANN speed study", columns=("rpm", "d10", "d50", "d90"))
    feed_table = read_table(feed, "PBM-ANN feed study", columns=("feed", "feed_d50", "d10", "d50", "d90"))
    comparison_table = read_table(comparison, "comparison table", columns=("rpm",))
    save_figure(speed_figure(speed_table, speed_feed, batch_s), out["speed_png"])
    save_figure(feed_figure(feed_table, feed_rpm, batch_s), out["feed_png"])
    extra: tuple[str, ...] = ()
    if breakage is not None:
        study = read_table(breakage, "PBM-ANN breakage study", columns=("variant", "rpm", "d50", "critical_speed"))
        save_figure(breakage_figure(study), out["breakage_png"])
        studies = {"speed study": speed_table, "feed study": feed_table, "breakage study": study}
        extra = (breakage_words(study), "", image_directive(out["breakage_png"]), "   :width: 640px", "")
        extra += (clipping_words(studies), "")
    learned = None
    if training is not None and metadata is not None:
        meta = read_metadata(metadata)
        table = GRID_PAIRS.read(training, need=("point_id", "rpm", "distribution", "n_replicates"))
        learned = training_words(training_set(table, str(training), meta["training_point_ids"]), meta, str(training))
    check = None
    if feed_check is not None:
        check_table = read_table(feed_check, "feed check table", columns=CHECK_COLUMNS)
        check = check_table.iloc[0].to_dict()
    if sensitivity is not None:
        indices = read_table(sensitivity, "Sobol' indices", columns=SOBOL_COLUMNS, dtype={"member": str})
        info = None
        if sensitivity_info is not None:
            info = json.loads(Path(sensitivity_info).read_text())
        extra = (*extra, sensitivity_words(indices, confidence, info), "")
    if lumping is not None:
        extra = (*extra, *_lumping_section(lumping, lumping_liquid, lumping_info, out))
    text = findings_rst(
        speed_table,
        feed_table,
        comparison_table,
        speed_feed=speed_feed,
        feed_rpm=feed_rpm,
        batch_s=batch_s,
        speed_png=str(out["speed_png"]),
        feed_png=str(out["feed_png"]),
        extra=extra,
        training=learned,
        feed_check=check,
    )
    write_text(out["rst"], text)


def _lumping_section(cases, liquid, info, out: dict) -> tuple[str, ...]:
    """The lumping study's figure and display table written, and its words with the figure (rst lines)."""
    what = "lumping study (1-D against 2-D PBM)"
    table = read_table(cases, what, columns=CASE_COLUMNS, dtype={"feed": str, "failed": str})
    table["failed"] = table.failed.fillna("")
    per_size = read_table(liquid, "lumping study's liquid per size class", columns=LIQUID_COLUMNS)
    facts = {}
    if info is not None:
        try:
            facts = json.loads(Path(info).read_text())
        except (OSError, ValueError) as exc:
            raise InputFileError(f"lumping study's cost {info} cannot be read as JSON: {exc}") from None
    save_figure(lumping_figure(table, per_size), out["lumping_png"])
    turn1, turn2 = turn_speeds(table)
    write_titled_table(
        out["lumping_csv"], out["lumping_html"], lumping_table(table), "lumping", {"turns": [turn1, turn2]}, keys=2
    )
    return (
        lumping_words(table, per_size, facts),
        "",
        image_directive(out["lumping_png"]),
        "   :width: 640px",
        "   :alt: final d50 of the lumped and the two-dimensional PBM against speed, binder rate and feed",
        "",
    )
