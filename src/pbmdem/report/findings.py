"""The findings the report and the README open with: how impeller speed and the feed size
distribution change granule growth, in plain words and one figure each, then how far to trust them.

* `speed_figure`: final d10/d50/d90 (mm) against impeller speed (PBM-ANN ensemble mean, with the
  ensemble members' range as a band; speeds beyond the DEM grid and intervals outside the
  surrogate's training domain marked);
* `feed_figure`: the same against the feed (the grid's feeds and the blends between them), with
  the feed's own d50 for comparison;
* `findings_rst`: the text (reStructuredText, included at the top of Snakemake's report): the
  answers with their numbers, then the validation's verdicts, then
  the glossary of the terms the report uses.

Sizes in mm. Inputs: the tables of `pbmdem.coupling.studies` and the comparison table.
"""

from __future__ import annotations

import base64
import math
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.plotting import pyplot

from .breakage import peak_speed
from .display import MM, PERCENT

STATS = (("d90", "^", "tab:red"), ("d50", "o", "black"), ("d10", "v", "tab:blue"))

#: the terms the report uses, explained once (the end of the findings, in both reports)
GLOSSARY = (
    ("d10, d50, d90", "the granule diameters below which 10 %, 50 % (the median) and 90 % of the granule mass lie."),
    ("feed", "the size distribution of the granules (primary particles) at the start of the batch."),
    (
        "encounter",
        "an impact of two granules that were apart since their previous contact (DEM contacts that merely "
        "persist or rattle are not counted); the collision frequency the PBM uses counts encounters.",
    ),
    ("collision frequency c_ij", "encounters per second per pair of granules of size classes i and j."),
    (
        "surrogate",
        "the regression model that predicts c_ij from the sizes, the size distribution and the impeller "
        "speed, in place of a DEM run: of the seed study's model families (a neural-network ensemble, "
        "Kriging, a response surface), the one with the smallest error on held-out DEM runs.",
    ),
    ("PBM", "population balance model: the granule size distribution over the batch, grown by aggregation."),
    ("PBM-ANN", "the PBM with the surrogate's collision frequencies."),
    ("PBM-DEM", "the same PBM with LIGGGHTS run at every coupling interval (the reference)."),
    ("PBM-constant", "the same PBM with one collision frequency for every pair of granules."),
    (
        "training domain",
        "the sizes, distributions and tip speeds the DEM grid covered; outside it the surrogate extrapolates.",
    ),
    (
        "surrogate members",
        "predictions spread as the surrogate's held-out-calibrated uncertainty (the networks of the "
        "ensemble, or quantiles of Kriging's posterior); their disagreement is its uncertainty.",
    ),
    (
        "replicate band",
        "the range (min-max) of PBM-DEM runs that differ only by their DEM insertion seeds: the reference's own noise.",
    ),
    ("noise floor", "how well one DEM replicate predicts another; no surrogate can be more accurate."),
    (
        "Sobol' indices S1, ST",
        "the share of the variance of an output over the factors' stated ranges that a factor causes alone (first "
        "order, S1) or alone and together with the other factors (total, ST).",
    ),
    (
        "tip speed, Froude number",
        "impeller tip speed (m/s) and the ratio of centrifugal to gravity acceleration at the tip.",
    ),
)


def _band(ax, x, frame: pd.DataFrame, stat: str, color: str) -> None:
    lo, hi = MM * frame[f"{stat}_member_min"], MM * frame[f"{stat}_member_max"]
    ax.fill_between(x, lo, hi, color=color, alpha=0.18, lw=0)


def _domain_marks(ax, x, frame: pd.DataFrame) -> bool:
    outside = frame.out_of_domain_intervals.to_numpy(int) > 0
    for stat, _, _ in STATS:
        ax.scatter(
            np.asarray(x)[outside],
            MM * frame[stat].to_numpy(float)[outside],
            s=140,
            facecolors="none",
            edgecolors="tab:purple",
            lw=1.6,
            zorder=5,
        )
    return bool(outside.any())


def speed_figure(study: pd.DataFrame, feed: str, batch_s: float):
    """Final d10/d50/d90 against impeller speed, with the ensemble-member band."""
    plt = pyplot()
    s = study.sort_values("rpm")
    fig, ax = plt.subplots(figsize=(8.0, 5.6))
    for stat, marker, color in STATS:
        _band(ax, s.rpm, s, stat, color)
        ax.plot(s.rpm, MM * s[stat], marker=marker, color=color, lw=1.8, label=f"final {stat}")
    ax.fill_between([], [], [], color="0.5", alpha=0.25, label="range of the surrogate's members")
    dem = s[s.dem_speed.astype(bool)]
    ax.scatter(dem.rpm, np.full(len(dem), 0.0), marker="|", s=300, color="0.3", clip_on=False, zorder=6)
    outside_range = s[~s.in_grid_range.astype(bool)]
    for rpm in outside_range.rpm:
        ax.axvspan(rpm - 0.5 * _step(s.rpm), rpm + 0.5 * _step(s.rpm), color="tab:purple", alpha=0.08, lw=0)
    if _domain_marks(ax, s.rpm, s):
        ax.scatter(
            [], [], s=140, facecolors="none", edgecolors="tab:purple", label="surrogate outside its training domain"
        )
    ax.set_ylim(bottom=0.0)
    if len(s) <= 12:
        ax.set_xticks(s.rpm, [f"{v:g}" for v in s.rpm])
    ax.set(
        xlabel="impeller speed (rpm)   (| = speeds with DEM runs)",
        ylabel="final granule size (mm)",
        title=f"Granule size after the {batch_text(batch_s)} batch against impeller speed (PBM-ANN, feed {feed})",
    )
    ax.grid(alpha=0.3)
    _legend_below(fig, ax)
    return fig


def _legend_below(fig, ax) -> None:
    ax.title.set_fontsize(10.5)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.13, 1, 1))


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
    for stat, marker, color in STATS:
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
    if _domain_marks(ax, x, s):
        ax.scatter(
            [], [], s=140, facecolors="none", edgecolors="tab:purple", label="surrogate outside its training domain"
        )
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


def _mm(v, decimals: int = 2) -> str:
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{MM * float(v):.{decimals}f} mm"


def _feed_trend(f: pd.DataFrame) -> str:
    """Whether the final d50 follows the feed's own d50 (rises from each feed to the next coarser
    one), and if not, which feeds break the trend."""
    d50 = f.d50.to_numpy(float)
    if np.all(np.diff(d50) > 0):
        return "a coarser feed gives larger granules at every step."
    dips = [f"``{f.feed.iloc[k + 1]}``" for k in range(len(d50) - 1) if d50[k + 1] <= d50[k]]
    return (
        "the final size does not simply follow the feed: it is smaller for "
        + ", ".join(dips)
        + " than for the next finer feed."
    )


def _disagree(spread: float) -> str:
    if not spread < 5e-6:  # NaN included
        return f"The surrogate's members disagree on the final d50 by at most {_mm(spread)}. "
    return "The surrogate's members agree on the final d50 to within 0.005 mm. "


def _spread(row) -> float:
    return float(row["d50_member_max"] - row["d50_member_min"])


def _domain_words(frame: pd.DataFrame, noun: str, column: str) -> str:
    bad = frame[frame.out_of_domain_intervals > 0]
    if bad.empty:
        return f"The surrogate stayed inside its training domain at every {noun}."
    names = ", ".join(_label(v) for v in bad[column])
    return (
        f"The surrogate left its training domain at {len(bad)} of {len(frame)} {noun}s ({names}): "
        "treat those as extrapolations."
    )


def _label(v) -> str:
    return f"{v:g} rpm" if isinstance(v, (int, float, np.floating)) else str(v)


def _speed_paragraph(speed: pd.DataFrame, speed_feed: str, batch_s: float) -> str:
    """The answer to "how does the impeller speed change the granules?" (`speed`: one row per speed)."""
    s = speed.sort_values("rpm")
    lo, hi = s.iloc[0], s.iloc[-1]
    change = (hi.d50 - lo.d50) / lo.d50 if lo.d50 else float("nan")
    peak = peak_speed(s)
    if peak is not None:
        top = s[s.rpm == peak].iloc[0]
        trend = (
            f"The final d50 grows with the speed up to {peak:g} rpm (d50 = {_mm(top.d50)}) and falls above it: "
            "faster impellers make the granules collide more often, but above that speed more of the impacts "
            "are fast enough to break the granules (breakage from impacts, the Stokes deformation criterion). "
        )
    elif abs(change) < 0.05:
        trend = (
            "Over this range of speeds the final size changes by less than 5 %: faster impellers make the "
            "granules collide more often, but a collision only grows a granule when both carry enough surface "
            "liquid. "
        )
    elif change > 0:
        trend = "Faster impellers make the granules collide more often, and more collisions make larger granules. "
    else:
        trend = "The granules end smaller at higher speeds in this model. "
    return (
        f"**Impeller speed.** With the ``{speed_feed}`` feed, raising the impeller speed from {lo.rpm:g} to "
        f"{hi.rpm:g} rpm changes the granule size after the {batch_text(batch_s)} batch from d50 = {_mm(lo.d50)} to "
        f"{_mm(hi.d50)} ({PERCENT * change:+.1f} %); d10 goes from {_mm(lo.d10)} to {_mm(hi.d10)} and d90 from "
        f"{_mm(lo.d90)} to {_mm(hi.d90)}. "
        + trend
        + _disagree(max(_spread(r) for _, r in s.iterrows()))
        + _domain_words(s, "speed", "rpm")
    )


def _feed_paragraph(feed: pd.DataFrame, feed_rpm: float) -> str:
    """The answer to "how does the feed size distribution change the granules?" (`feed`: one row per feed)."""
    f = feed.sort_values("feed_d50")
    f_lo, f_hi = f.iloc[0], f.iloc[-1]
    growth = (f.d50 / f.feed_d50).to_numpy(float)
    blends = f[~f.in_grid.astype(bool)]
    return (
        f"**Feed size distribution.** At {feed_rpm:g} rpm the final d50 goes from {_mm(f_lo.d50)} for the finest "
        f"feed, ``{f_lo.feed}`` (feed d50 {_mm(f_lo.feed_d50)}), to {_mm(f_hi.d50)} for the coarsest, "
        f"``{f_hi.feed}`` (feed d50 {_mm(f_hi.feed_d50)}); "
        + _feed_trend(f)
        + f" The granules end {np.nanmin(growth):.2f} to {np.nanmax(growth):.2f} times as large as their feed. "
        + (
            ("The blend " if len(blends) == 1 else f"The {len(blends)} blends ")
            + "between the grid's feeds ("
            + ", ".join(f"``{b}``" for b in blends.feed)
            + (") was" if len(blends) == 1 else ") were")
            + " not in the DEM grid; PBM-ANN predicts such feeds in seconds. "
            if len(blends)
            else ""
        )
        + _disagree(max(_spread(r) for _, r in f.iterrows()))
        + _domain_words(f, "feed", "feed")
    )


#: what each kind of statement of the feed check (pbmdem.validation.feed_check) says a PBM-DEM
#: replicate does when it confirms the statement
_CONFIRMING = {
    "below_parents": "ends{} below both parents' PBM-ANN d50",
    "above_parents": "ends{} above both parents' PBM-ANN d50",
}


def _side(check) -> str:
    if check["kind"] in _CONFIRMING:
        return _CONFIRMING[check["kind"]]
    return "ends{} " + ("below" if check["ann_deviation"] < 0 else "above") + " the parents' log-interpolation"


def feed_check_words(check) -> str:
    """The PBM-DEM check of the feed study's most surprising result in one paragraph (`check`: the
    row of results/validation/feed_check.csv, `pbmdem.validation.feed_check.check_table`)."""
    n, k = int(check["dem_replicates"]), int(check["dem_replicates_confirming"])
    side = _side(check)
    verdict = {
        "yes": f"PBM-DEM confirms it: {'every' if n > 1 else 'the'} replicate " + side.format("") + ". ",
        "no": "PBM-DEM does not confirm it: "
        + ("no replicate " if n > 1 else "the replicate does not ")
        + (side.format("") if n > 1 else side.replace("ends{}", "end"))
        + ". ",
        "partly": f"PBM-DEM confirms it in part: {k} of {n} replicates " + side.replace("ends{}", "end") + ". ",
    }[check["dem_confirms"]]
    outside = float(check["ann_d50_outside_dem_range"])
    agreement = (
        "PBM-ANN's final d50 lies inside the PBM-DEM replicates' range. "
        if outside == 0
        else f"PBM-ANN's final d50 lies {PERCENT * outside:.1f} % of d50 outside the PBM-DEM replicates' range. "
    )
    domain = ""
    if int(check["ann_out_of_domain_intervals"]):
        domain += (
            f"PBM-ANN left its training domain in {int(check['ann_out_of_domain_intervals'])} of "
            f"{int(check['ann_intervals'])} intervals of this batch. "
        )
    for p in ("finer", "coarser"):
        if m := int(check[f"parent_{p}_out_of_domain_intervals"]):
            domain += (
                f"The parent ``{check[f'parent_{p}']}`` left the training domain in {m} interval{'s' if m > 1 else ''} "
                "of its batch: its d50 is partly an extrapolation. "
            )
    if check["is_most_surprising"]:
        choice = (
            "It is the feed study's most surprising in-domain result by the stated rule (the case whose final d50 "
            "lies furthest outside the interval of its parent feeds' d50, else furthest off their log-interpolation)."
        )
    elif isinstance(check["most_surprising"], str) and check["most_surprising"]:
        choice = (
            f"It was configured (``validation.feed_check.feed``) before this run; by the stated rule the feed "
            f"study's most surprising in-domain result at {float(check['feed_study_rpm']):g} rpm is now that "
            f"{check['most_surprising_statement']}: set ``validation.feed_check.feed: {check['most_surprising']}`` "
            "to check that one."
        )
    else:
        choice = "No case of the feed study with a parent feed on either side stayed inside the training domain."
    return (
        f"**PBM-DEM check of the feed result.** At {float(check['rpm']):g} rpm PBM-ANN predicts that "
        f"{check['statement']}: final d50 {_mm(check['ann_d50'])} (the surrogate's members "
        f"{MM * float(check['ann_d50_member_min']):.2f}-{_mm(check['ann_d50_member_max'])}). {n} PBM-DEM "
        f"loop{'s' if n > 1 else ''} (LIGGGHTS at every coupling interval, DEM insertion seeds apart) "
        f"end{'' if n > 1 else 's'} at d50 {_range(check, 'd50')}, d10 {_range(check, 'd10')} and d90 "
        f"{_range(check, 'd90')}. "
        + verdict
        + agreement
        + "The parents' d50 are PBM-ANN's (no PBM-DEM loop runs them). "
        + domain
        + choice
    )


def _range(check, stat: str) -> str:
    lo, hi, mean = (check[f"dem_{stat}_{k}"] for k in ("min", "max", "mean"))
    if int(check["dem_replicates"]) == 1:
        return _mm(mean)
    return f"{MM * float(lo):.2f}-{_mm(hi)} (mean {_mm(mean)})"


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
    """The findings as reStructuredText: the two answers with their figures (the PNGs at
    `speed_png`, `feed_png` embedded as data URIs, so that the text shows them wherever it is
    included: Snakemake's own `embeddedimage` directive does not embed), with `feed_check` (the
    row of the feed check's table, or None) its PBM-DEM check after the feed's, then `extra`
    (further findings, lines of rst), then how far to trust them: the validation and, with
    `training` (the paragraph of `pbmdem.report.training.training_words`), what the surrogate was
    trained on and its accuracy on DEM runs it never saw."""
    lines = [
        "Findings",
        "--------",
        "",
        _speed_paragraph(speed, speed_feed, batch_s),
        "",
        _image_directive(speed_png),
        "   :width: 640px",
        "   :alt: final d10, d50, d90 against impeller speed",
        "",
        _feed_paragraph(feed, feed_rpm),
        "",
        _image_directive(feed_png),
        "   :width: 640px",
        "   :alt: final d10, d50, d90 against the feed size distribution",
        "",
        *((feed_check_words(feed_check), "") if feed_check is not None else ()),
        *extra,
        "**How far to trust them.** " + trust_words(comparison),
        "",
        *(("**What the surrogate was trained on.** " + training, "") if training else ()),
        "Glossary",
        "--------",
        "",
        "\n".join(f"* **{term}**: {text}" for term, text in GLOSSARY),
        "",
    ]
    return "\n".join(lines) + "\n"


def _image_directive(png) -> str:
    """`.. image::` with the PNG as a data URI over lines of 76 characters (docutils refuses lines
    longer than 10000 characters and joins the lines of a URI)."""
    uri = data_uri(png)
    return ".. image:: " + "\n   ".join(uri[k : k + 76] for k in range(0, len(uri), 76))


def data_uri(png) -> str:
    """A PNG file as a data URI."""
    return "data:image/png;base64," + base64.b64encode(Path(png).read_bytes()).decode()


def _times(ratio) -> str:
    """A speed ratio in words ("3500 times"; "an unmeasured number of times" where it is missing)."""
    ratio = float("nan") if ratio is None else float(ratio)
    return f"{ratio:.0f} times" if np.isfinite(ratio) else "an unmeasured number of times"


def trust_words(comparison: pd.DataFrame) -> str:
    """The validation in one paragraph: PBM-ANN against the coupled PBM-DEM reference."""
    parts = []
    for r in comparison.sort_values("rpm").to_dict("records"):
        where = "a speed of the DEM grid" if bool(r.get("in_training_grid")) else "a speed between the DEM grid's"
        parts.append(
            f"at {r['rpm']:g} rpm ({where}) PBM-ANN's final d50 is {r['d50_end_ann_mm']:.2f} mm against "
            f"{r['d50_end_dem_mm']:.2f} mm for the coupled PBM-DEM model (its {int(r['n_dem_replicates'])} "
            f"replicates span {r['d50_end_dem_min_mm']:.2f}-{r['d50_end_dem_max_mm']:.2f} mm); d50(t) leaves "
            f"their band by at most {PERCENT * float(r['ann_d50_outside_band_max']):.2f} %, and a PBM-ANN batch "
            f"took {_times(r.get('cpu_time_ratio_dem_over_ann'))} less CPU time"
        )
    return (
        "The surrogate-based model (PBM-ANN) was checked against the model that runs LIGGGHTS at every coupling "
        "interval (PBM-DEM): "
        + "; ".join(parts)
        + ". Predictions are as good as the DEM grid behind the surrogate: outside its speeds and feeds they are "
        "extrapolations (marked in the figures). The validation and the details follow."
    )
