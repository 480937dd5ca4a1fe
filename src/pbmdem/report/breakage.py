"""The breakage finding: final granule size against impeller speed with and without breakage from
impacts, and its sensitivity to the Stokes deformation criterion (results/validation/breakage_study.csv,
pbmdem.coupling.studies.breakage_study): one figure and its words."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pbmdem.pbm.results import FLOOR_LIMIT

from .display import MM, PERCENT
from .figures import pyplot

#: line style per variant of the study
STYLES = {
    "off": ("tab:gray", "--", "aggregation only"),
    "default": ("black", "-", "breakage (configured Y, St_def*)"),
    "Y/2": ("tab:red", ":", "Y / 2"),
    "Yx2": ("tab:blue", ":", "Y x 2"),
    "St*/2": ("tab:orange", "-.", "St_def* / 2"),
    "St*x2": ("tab:green", "-.", "St_def* x 2"),
    "sharp": ("tab:purple", "-.", "sharp criterion (every impact above v* breaks)"),
}


def breakage_figure(study: pd.DataFrame):
    """Final d50 against impeller speed per variant; the members' range for breakage off and on."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8.0, 5.2))
    for name, (color, style, label) in STYLES.items():
        s = study[study.variant == name].sort_values("rpm")
        if s.empty:
            continue
        v = s.critical_speed.iloc[0]
        text = label if not np.isfinite(v) else f"{label}: v* = {v:.2g} m/s"
        ax.plot(s.rpm, MM * s.d50, style, color=color, marker="o", ms=4, label=text)
        if name in ("off", "default"):
            ax.fill_between(s.rpm, MM * s.d50_member_min, MM * s.d50_member_max, color=color, alpha=0.15, lw=0)
    ax.set_ylim(bottom=0.0)
    ax.set(
        xlabel="impeller speed (rpm)",
        ylabel="final d50 (mm)",
        title="Final d50 against impeller speed with breakage from impacts (PBM-ANN; band: members)",
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def peak_speed(s: pd.DataFrame) -> float | None:
    """The speed of the largest final d50 when it lies inside the speed range and the granules get
    smaller above it, else None. Smaller means below the surrogate's uncertainty at the peak: the
    fastest speed's d50 under the smallest member d50 at the peak (`d50_member_min`, where the
    study has it), so that a flat curve's wobble within the members is not called a peak. Speeds
    whose ensemble mean failed (d50 NaN) are left out, not taken as the peak."""
    s = s[np.isfinite(s.d50.to_numpy(float))].sort_values("rpm")
    if s.empty:
        return None
    k = int(np.argmax(s.d50.to_numpy(float)))
    if not 0 < k < len(s) - 1:
        return None
    floor = float(s.d50_member_min.iloc[k]) if "d50_member_min" in s else float("nan")
    if np.isfinite(floor) and not float(s.d50.iloc[-1]) < floor:
        return None
    return float(s.rpm.iloc[k])


def falls_throughout(s: pd.DataFrame) -> bool:
    """Whether the final d50 is largest at the lowest speed and smaller at the highest (of the
    speeds whose ensemble mean finished)."""
    d50 = s[np.isfinite(s.d50.to_numpy(float))].sort_values("rpm").d50.to_numpy(float)
    return d50.size > 1 and int(np.argmax(d50)) == 0 and d50[-1] < d50[0]


def breakage_words(study: pd.DataFrame) -> str:
    """The finding in words: d50 at the lowest and highest speed with and without breakage, and
    whether (for each variant) a speed appears above which the granules get smaller."""
    off = study[study.variant == "off"].sort_values("rpm")
    on = study[study.variant == "default"].sort_values("rpm")
    lo, hi = on.iloc[0], on.iloc[-1]
    change = (hi.d50 - lo.d50) / lo.d50
    change_off = (off.d50.iloc[-1] - off.d50.iloc[0]) / off.d50.iloc[0]
    peaks = {name: peak_speed(s) for name, s in study.groupby("variant")}
    with_peak = [f"{name} ({rpm:g} rpm)" for name, rpm in peaks.items() if rpm is not None]
    falling = [name for name, s in study.groupby("variant") if falls_throughout(s)]
    n = float(on.strength_porosity_exponent.iloc[0]) if "strength_porosity_exponent" in on else 0.0
    v_star = f"v* = {on.critical_speed.iloc[0]:.2g} m/s"
    if n > 0:  # v* of a fresh granule; consolidation raises it
        v_star += f" for a fresh granule, rising as it consolidates (strength ~ ((1 - eps)/eps)^{n:g})"
    return (
        f"**Breakage.** With breakage from impacts (St_def = rho v^2 / (2 Y) > St_def*, critical speed "
        f"{v_star}) the final d50 goes from {MM * lo.d50:.2f} mm at {lo.rpm:g} rpm "
        f"to {MM * hi.d50:.2f} mm at {hi.rpm:g} rpm ({PERCENT * change:+.1f} %); without breakage "
        f"{PERCENT * change_off:+.1f} %. "
        + (
            f"The final d50 peaks inside the speed range and falls above it for: {', '.join(with_peak)}. "
            if with_peak
            else "No variant shows a speed above which the granules get smaller within the speeds studied. "
        )
        + (f"It falls from the lowest speed studied on for: {', '.join(falling)}. " if falling else "")
        + "Impacts break granules where the fastest of them, at the impeller and between granules, approach or "
        "exceed their v*."
    )


def _batch_name(study: str, row: dict, member: bool) -> str:
    """'the breakage study's Y/2 batch at 1200 rpm, feed fine (an ensemble member)'."""
    variant = f" {row['variant']}" if isinstance(row.get("variant"), str) else ""
    who = "an ensemble member" if member else "the ensemble mean"
    return f"the {study}'s{variant} batch at {float(row['rpm']):g} rpm, feed {row.get('feed', '?')} ({who})"


def clipping_words(studies: dict[str, pd.DataFrame]) -> str:
    """The grid floor of the PBM-ANN studies' batches in words: 'clipping: none' when no breakage
    fragment fell below the first pivot in any batch (ensemble means and members), else the
    largest share of a batch's granules merged there (``merged_fraction``, the ensemble mean's, and
    ``merged_fraction_member_max``; pbmdem.pbm.results.grid_floor) and the batches above
    FLOOR_LIMIT (1 %), flagged. ``studies``: name -> study table (speed, feed, breakage)."""
    cases = []  # (share, batch)
    batches = 0
    for name, table in studies.items():
        if table is None or "merged_fraction" not in table:
            continue
        for row in table.to_dict("records"):
            batches += 1
            for column, member in (("merged_fraction", False), ("merged_fraction_member_max", True)):
                share = float(row.get(column, float("nan")))
                if np.isfinite(share):
                    cases.append((share, _batch_name(name, row, member)))
    head = "**Clipping at the grid floor.** "
    if not batches:
        return head + "clipping: not measured (the studies' tables have no merged_fraction column)."
    merged = sorted((c for c in cases if c[0] > 0), reverse=True)
    if not merged:
        return head + (
            f"clipping: none: no breakage fragment fell below the grid's first pivot in any of the {batches} "
            "PBM-ANN batches of the studies (ensemble means and members)."
        )
    share, worst = merged[0]
    flagged = [c for c in merged if c[0] > FLOOR_LIMIT]
    text = head + (
        f"clipping: breakage fragments merged at the grid floor amount to {PERCENT * share:.3g} % of the final "
        f"number of granules in {worst}, the most of any batch: fragments smaller than the grid's first pivot "
        "are counted as first-pivot granules (their solid kept, their number not). Batch results that merged "
        f"some: {len(merged)} of {len(cases)} (ensemble means, and the members' largest); "
    )
    if flagged:
        names = "; ".join(f"{b}: {PERCENT * s:.3g} %" for s, b in flagged[:5])
        more = f" and {len(flagged) - 5} more" if len(flagged) > 5 else ""
        return text + (
            f"FLAGGED: {len(flagged)} above {PERCENT * FLOOR_LIMIT:g} % of their final number ({names}{more}); "
            "a smaller pbm.grid.min_diameter gives their fragments bins of their own."
        )
    return text + f"none above {PERCENT * FLOOR_LIMIT:g} % of its final number."
