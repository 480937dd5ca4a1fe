"""The breakage finding: final granule size against impeller speed with and without breakage from
impacts, and its sensitivity to the Stokes deformation criterion (results/validation/breakage_study.csv,
pbmdem.coupling.studies.breakage_study): one figure and its words."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pbmdem.pbm.results import FLOOR_LIMIT
from pbmdem.plotting import pyplot

from . import words
from .display import MM

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
    """The speed of the largest final d50 (of the speeds whose mean finished) when it lies inside the
    speed range and the fastest speed's d50 falls below the smallest member's d50 there (where the
    study has members: a flat curve's wobble within them is no peak), else None."""
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
    peaks = {name: peak_speed(s) for name, s in study.groupby("variant")}
    return words.paragraph(
        "breakage",
        lo={"rpm": lo.rpm, "d50": lo.d50},
        hi={"rpm": hi.rpm, "d50": hi.d50},
        change=(hi.d50 - lo.d50) / lo.d50,
        change_off=(off.d50.iloc[-1] - off.d50.iloc[0]) / off.d50.iloc[0],
        critical_speed=on.critical_speed.iloc[0],
        exponent=float(on.strength_porosity_exponent.iloc[0]) if "strength_porosity_exponent" in on else 0.0,
        peaks=[(name, rpm) for name, rpm in peaks.items() if rpm is not None],
        falling=[name for name, s in study.groupby("variant") if falls_throughout(s)],
    )


def _batch_name(study: str, row: dict, member: bool) -> str:
    """'the breakage study's Y/2 batch at 1200 rpm, feed fine (an ensemble member)'."""
    variant = row.get("variant")
    batch = {
        "study": study,
        "variant": variant if isinstance(variant, str) else None,
        "rpm": float(row["rpm"]),
        "feed": row.get("feed", "?"),
        "member": member,
    }
    return words.macro("_parts", "batch")(batch)


def clipping_words(studies: dict[str, pd.DataFrame]) -> str:
    """The grid floor of the PBM-ANN studies' batches (``studies``: name -> table) in words: the
    largest shares of a batch's granules merged there (pbmdem.pbm.results.grid_floor), if any."""
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
    merged = sorted((c for c in cases if c[0] > 0), reverse=True)
    return words.paragraph("clipping", batches=batches, results=len(cases), merged=merged, limit=FLOOR_LIMIT)
