"""The PBM-DEM check of the feed study's most surprising result (docs/validation.md, "The feed check").

The feed study (`pbmdem.coupling.studies.feed_study`) predicts with PBM-ANN the final sizes of the
grid's feeds and of the 50:50 blends of neighbouring feeds, feeds no DEM run has seen. A case with
a grid feed on either side (its *parents*, `pbmdem.config.feed_case_parents`: the two feeds of a
blend, a feed's finer and coarser neighbours) is expected to end between them. The rule:

1. A case whose final d50 lies outside the interval its parents' final d50 span ends smaller (or
   larger) than both; its surprise is the distance outside the interval over its own d50.
2. If no case lies outside, the surprise is the deviation from the parents' log-interpolation, the
   final ln d50 interpolated linearly in the ln of the feed's mass-median diameter between the
   parents: |d50 / interpolated - 1|.

Only in-domain cases count: a finite final d50, no coupling interval with the surrogate outside its
training domain (an extrapolation is no surprise). The most surprising case has the largest
surprise of the first kind that any case has; ties go to the finer case.

The DAG of the workflow is fixed before the feed study runs, so the case to check is configured
(`validation.feed_check`); `check_table` says whether it is still the most surprising one by the
rule. Its PBM-DEM replicate loops confirm the case's statement when every replicate's final d50
lies on the statement's side (below the lower parent's PBM-ANN d50, above the upper one's, or on
PBM-ANN's side of the interpolation): "yes"; "no" when none does; "partly" otherwise.
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


def _in_domain(row) -> bool:
    return bool(np.isfinite(row["d50"])) and int(row["out_of_domain_intervals"]) == 0


def surprises(study: pd.DataFrame) -> pd.DataFrame:
    """One row per case of `study` (a feed study table: feed, feed_d50, d50, out_of_domain_intervals,
    in_grid) with a parent on either side: its parents and their d50, `outside` (the distance of the
    d50 outside the parents' interval over the d50, 0 inside), `kind` (`BELOW`, `ABOVE` or `OFF`),
    `interpolated_d50` (the parents' log-interpolation at the case's feed d50), `deviation`
    (d50 / interpolated - 1) and `in_domain` (the case's PBM-ANN batch inside the training domain,
    its d50 finite)."""
    missing = [c for c in STUDY_COLUMNS if c not in study.columns]
    if missing:
        raise ValueError(f"feed study table: missing column(s) {missing}; present: {list(study.columns)}")
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
                "in_domain": _in_domain(r) and np.isfinite(a.d50) and np.isfinite(b.d50),
            }
        )
    columns = ["feed", "parent_finer", "parent_coarser", "d50", "parent_finer_d50", "parent_coarser_d50", "kind"]
    return pd.DataFrame(rows, columns=columns + ["outside", "interpolated_d50", "deviation", "in_domain"])


def most_surprising(study: pd.DataFrame) -> pd.Series | None:
    """The feed study's most surprising in-domain case by the rule (module docstring): a row of
    `surprises`, or None when no case with two parents is in domain."""
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
    """Whether each PBM-DEM final d50 of `dem_d50` lies on the side of `case`'s statement (a row of
    `surprises`): below both parents' d50, above both, or on PBM-ANN's side of the interpolation
    (nowhere when PBM-ANN lies on it)."""
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
    """The feed check in one row (`results/validation/feed_check.csv`, sizes in m): `feed` at `rpm`,
    PBM-DEM (`dem`: `dem_finals` of its loops) against PBM-ANN (`ann`: rows of
    `pbmdem.coupling.studies.run_case` for the case and its parents at `rpm`, with in_grid), the
    statement the case makes and whether PBM-DEM confirms it, and the feed study's (`study`, at
    `study_rpm`) most surprising case by the rule."""
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
        }
    for s in STATISTICS:
        row |= {
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
