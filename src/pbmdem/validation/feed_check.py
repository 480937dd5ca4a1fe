"""The PBM-DEM check of the feed study's most surprising result: the rule that picks the case
(`most_surprising`), its statement and PBM-DEM's verdict (`check_table`; docs/validation.md,
"The feed check").
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.config import feed_case_parents
from pbmdem.readers import InputFileError, read_table
from pbmdem.tables import STATISTICS

#: the kinds of statement, in the order of the rule
BELOW, ABOVE, OFF = "below_parents", "above_parents", "off_interpolation"
STUDY_COLUMNS = ("feed", "feed_d50", "d50", "out_of_domain_intervals", "in_grid")
#: the columns of the feed check's table (`check_table`, results/validation/feed_check.csv)
CHECK_COLUMNS = (
    "feed",
    "rpm",
    "kind",
    "statement",
    "dem_replicates",
    "dem_replicates_confirming",
    "dem_confirms",
    *(f"dem_{s}_{k}" for s in STATISTICS for k in ("mean", "min", "max")),
    *(f"ann_{s}{k}" for s in STATISTICS for k in ("", "_member_min", "_member_max")),
    "ann_d50_outside_dem_range",
    "ann_out_of_domain_intervals",
    "ann_intervals",
    *(f"parent_{p}{k}" for p in ("finer", "coarser") for k in ("", "_ann_d50", "_out_of_domain_intervals")),
    "interpolated_d50",
    "ann_deviation",
    "dem_deviation",
    "feed_study_rpm",
    "most_surprising",
    "most_surprising_statement",
    "is_most_surprising",
)


def surprises(study: pd.DataFrame) -> pd.DataFrame:
    """One row per case of `study` (`STUDY_COLUMNS`, checked where it is read) with a parent on
    either side: its parents and their d50, how far outside their interval it lies, its `kind`, the
    parents' log-interpolation, its deviation from it and whether it is in domain (the rule: docs)."""
    s = study.sort_values("feed_d50", kind="stable").reset_index(drop=True)
    by_name = s.set_index("feed")
    parents = feed_case_parents(zip(s.feed, s.in_grid.astype(bool)))
    rows = []
    for _, r in s.iterrows():
        if r.feed not in parents:
            continue
        a, b = (by_name.loc[p] for p in parents[r.feed])
        d50, lo, hi = float(r.d50), min(a.d50, b.d50), max(a.d50, b.d50)
        w = (math.log(r.feed_d50) - math.log(a.feed_d50)) / (math.log(b.feed_d50) - math.log(a.feed_d50))
        interpolated = math.exp((1 - w) * math.log(a.d50) + w * math.log(b.d50))
        kind = BELOW if d50 < lo else ABOVE if d50 > hi else OFF
        rows.append(
            {
                "feed": r.feed,
                "parent_finer": parents[r.feed][0],
                "parent_coarser": parents[r.feed][1],
                "d50": d50,
                "parent_finer_d50": float(a.d50),
                "parent_coarser_d50": float(b.d50),
                "kind": kind,
                "outside": max(lo - d50, d50 - hi, 0.0) / d50,
                "interpolated_d50": interpolated,
                "deviation": d50 / interpolated - 1.0,
                "in_domain": bool(np.isfinite(d50))
                and int(r.out_of_domain_intervals) == 0
                and np.isfinite(a.d50)
                and np.isfinite(b.d50),
            }
        )
    columns = ["feed", "parent_finer", "parent_coarser", "d50", "parent_finer_d50", "parent_coarser_d50", "kind"]
    return pd.DataFrame(rows, columns=columns + ["outside", "interpolated_d50", "deviation", "in_domain"])


def most_surprising(study: pd.DataFrame) -> pd.Series | None:
    """The feed study's most surprising in-domain case by the rule (a row of `surprises`), or None."""
    s = surprises(study)
    s = s[s.in_domain.astype(bool)]
    if s.empty:
        return None
    score = s.outside if (s.outside > 0).any() else s.deviation.abs()
    return s.loc[score.idxmax()]  # idxmax: the first of equal scores, the finer case


def statement(case: pd.Series) -> str:
    """What is surprising about `case` (a row of `surprises`), in words (sizes in mm)."""
    parents = f"``{case.parent_finer}`` {1e3 * case.parent_finer_d50:.2f} mm, ``{case.parent_coarser}`` "
    parents += f"{1e3 * case.parent_coarser_d50:.2f} mm"
    if case.kind in (BELOW, ABOVE):
        word = "smaller" if case.kind == BELOW else "larger"
        return f"``{case.feed}`` ends {word} than either parent ({parents})"
    side = "below" if case.deviation < 0 else "above"
    return (
        f"``{case.feed}`` ends {100 * abs(case.deviation):.1f} % {side} the log-interpolation of its parents "
        f"({1e3 * case.interpolated_d50:.2f} mm from {parents})"
    )


def confirms(case: pd.Series, dem_d50) -> np.ndarray:
    """Whether each PBM-DEM final d50 of `dem_d50` lies on the side of `case`'s statement (a row of `surprises`)."""
    d = np.asarray(dem_d50, float)
    lo, hi = min(case.parent_finer_d50, case.parent_coarser_d50), max(case.parent_finer_d50, case.parent_coarser_d50)
    if case.kind == BELOW:
        return d < lo
    if case.kind == ABOVE:
        return d > hi
    return np.sign(d - case.interpolated_d50) == np.sign(case.deviation) if case.deviation else np.zeros(len(d), bool)


def verdict(confirming: np.ndarray) -> str:
    """'yes' when every replicate confirms, 'no' when none does, 'partly' otherwise."""
    return "yes" if confirming.all() else "no" if not confirming.any() else "partly"


def dem_finals(folders) -> pd.DataFrame:
    """The final d10/d50/d90 (m) of PBM-DEM loops, one row per run folder (its summary.csv)."""
    rows = []
    for k, folder in enumerate(folders):
        what = f"PBM-DEM feed-check loop {k}: summary"
        summary = read_table(Path(folder) / "summary.csv", what, columns=STATISTICS, finite=STATISTICS)
        if summary.empty:
            raise InputFileError(f"{what} {Path(folder) / 'summary.csv'} has no rows")
        rows.append({"replicate": k} | {s: float(summary[s].iloc[-1]) for s in STATISTICS})
    return pd.DataFrame(rows, columns=["replicate", *STATISTICS])


def check_table(feed: str, rpm: float, ann: pd.DataFrame, dem: pd.DataFrame, study: pd.DataFrame, study_rpm: float):
    """The feed check in one row (`CHECK_COLUMNS`, sizes in m): `feed` at `rpm`, PBM-DEM (`dem_finals`)
    against PBM-ANN (`ann`: the case and its parents), and the feed study's most surprising case."""
    if dem.empty:
        raise ValueError(f"feed check of {feed!r}: no PBM-DEM loop finished")
    found = surprises(ann).set_index("feed")
    if feed not in found.index:
        raise ValueError(
            f"PBM-ANN feed-check table: {feed!r} with a parent on either side is missing; feeds: {list(ann.feed)}"
        )
    case = found.loc[feed].copy()
    case["feed"] = feed
    rows = ann.set_index("feed")
    mean = rows.loc[feed]
    confirming = confirms(case, dem.d50)
    top = most_surprising(study)
    row = {
        "feed": feed,
        "rpm": float(rpm),
        "kind": case.kind,
        "statement": statement(case),
        "dem_replicates": len(dem),
        "dem_replicates_confirming": int(confirming.sum()),
        "dem_confirms": verdict(confirming),
    }
    for s in STATISTICS:
        row |= {
            f"dem_{s}_mean": float(dem[s].mean()),
            f"dem_{s}_min": float(dem[s].min()),
            f"dem_{s}_max": float(dem[s].max()),
            f"ann_{s}": float(mean[s]),
            f"ann_{s}_member_min": float(mean[f"{s}_member_min"]),
            f"ann_{s}_member_max": float(mean[f"{s}_member_max"]),
        }
    lo, hi = row["dem_d50_min"], row["dem_d50_max"]
    row["ann_d50_outside_dem_range"] = max(lo - row["ann_d50"], row["ann_d50"] - hi, 0.0) / row["dem_d50_mean"]
    row["ann_out_of_domain_intervals"] = int(mean.out_of_domain_intervals)
    row["ann_intervals"] = int(mean.intervals)
    for side in ("finer", "coarser"):
        name = case[f"parent_{side}"]
        row |= {
            f"parent_{side}": name,
            f"parent_{side}_ann_d50": float(rows.loc[name].d50),
            f"parent_{side}_out_of_domain_intervals": int(rows.loc[name].out_of_domain_intervals),
        }
    row |= {
        "interpolated_d50": float(case.interpolated_d50),
        "ann_deviation": float(case.deviation),
        "dem_deviation": row["dem_d50_mean"] / float(case.interpolated_d50) - 1.0,
        "feed_study_rpm": float(study_rpm),
        "most_surprising": "" if top is None else top.feed,
        "most_surprising_statement": "" if top is None else statement(top),
        "is_most_surprising": top is not None and top.feed == feed,
    }
    return pd.DataFrame([row], columns=list(CHECK_COLUMNS))
