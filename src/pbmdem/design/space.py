"""The design space: PBM-ANN's final d10/d50/d90 over impeller speed x binder rate x a third
factor, with the surrogate's uncertainty band, and the region that meets a specification.

Every grid point runs PBM-ANN with the surrogate's ensemble mean and once per ensemble member
(`batches.run_cases`); the members' range of each statistic is the uncertainty band (as in the
validation, docs/validation.md). A point meets the specification only if the whole band does;
`spec_status` says, per point:

* `meets`: every member's d50 lies in [d50_min, d50_max] and every member's d90 <= d90_max;
* `uncertain`: the band straddles a limit (some members meet it, or the mean does, not all);
* `fails`: no member meets it;
* `out_of_domain`: the surrogate was evaluated outside its training domain in some coupling
  interval of the mean or of a member: the prediction is an extrapolation and is not judged;
* `failed`: the PBM of the mean or of a member did not finish (e.g. granules outgrew its grid).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.config import CoupledLoop, DesignSpace, Specification
from pbmdem.coupling.lumping import LIQUID_KEY
from pbmdem.surrogate import load_surrogate

from .batches import STATISTICS, Case, outcomes_table, run_cases

log = logging.getLogger(__name__)

STATUSES = ("meets", "uncertain", "fails", "out_of_domain", "failed")


def grid_cases(design: DesignSpace, n_members: int) -> list[Case]:
    """The cases of the design space: every speed x binder rate x third-factor value, each with the
    ensemble mean and every member."""
    cases = []
    for third in design.third_factor.values:
        for rate in design.liquid_rate.values():
            for rpm in design.impeller_rpm.values():
                values = ((LIQUID_KEY, rate), (design.third_factor.key, float(third)))
                cases += [Case(rpm, values, member) for member in (None, *range(n_members))]
    return cases


def point_table(outcomes: pd.DataFrame, third_key: str) -> pd.DataFrame:
    """One row per grid point from the table of its cases (`batches.outcomes_table`): the mean's
    final d10/d50/d90, the members' min and max of each, the out-of-domain intervals (the most of
    any case of the point) and the failed cases."""
    keys = ["rpm", LIQUID_KEY, third_key]
    rows = []
    for (rpm, rate, third), group in outcomes.groupby(keys, sort=False):
        mean = group[group.member < 0].iloc[0]
        members = group[group.member >= 0]
        row = {"rpm": rpm, "liquid_rate": rate, third_key: third}
        for s in STATISTICS:
            row[s] = mean[s]
            values = members[s].to_numpy(float)
            ok = np.isfinite(values)
            row[f"{s}_member_min"] = float(values[ok].min()) if ok.any() else float("nan")
            row[f"{s}_member_max"] = float(values[ok].max()) if ok.any() else float("nan")
        row["out_of_domain_intervals"] = int(group.out_of_domain_intervals.max())
        row["failed_cases"] = int((group.failed.astype(str) != "").sum())
        row["members"] = len(members)
        rows.append(row)
    return pd.DataFrame(rows)


def _within(d50, d90, spec: Specification) -> np.ndarray:
    ok = np.ones(np.shape(d50), bool)
    if spec.d50_min is not None:
        ok &= d50 >= spec.d50_min
    if spec.d50_max is not None:
        ok &= d50 <= spec.d50_max
    if spec.d90_max is not None:
        ok &= d90 <= spec.d90_max
    return ok


def specification_status(table: pd.DataFrame, spec: Specification) -> pd.Series:
    """The status of every point of `table` (columns of `point_table`) against `spec`."""
    lo50, hi50 = table.d50_member_min.to_numpy(float), table.d50_member_max.to_numpy(float)
    lo90, hi90 = table.d90_member_min.to_numpy(float), table.d90_member_max.to_numpy(float)
    # the whole band: the lowest d50 and the highest d90 (and the highest d50) all meet it
    robust = _within(lo50, hi90, spec) & _within(hi50, hi90, spec)
    # some part of the band meets it: an interval of d50 that overlaps the range, the lowest d90
    d50_min = -np.inf if spec.d50_min is None else spec.d50_min
    d50_max = np.inf if spec.d50_max is None else spec.d50_max
    d90_max = np.inf if spec.d90_max is None else spec.d90_max
    possible = (hi50 >= d50_min) & (lo50 <= d50_max) & (lo90 <= d90_max)
    possible |= _within(table.d50.to_numpy(float), table.d90.to_numpy(float), spec)
    status = np.where(robust, "meets", np.where(possible, "uncertain", "fails"))
    status = np.where(table.out_of_domain_intervals.to_numpy() > 0, "out_of_domain", status)
    status = np.where(table.failed_cases.to_numpy() > 0, "failed", status)
    return pd.Series(status, index=table.index, name="spec_status")


def design_space(loop: CoupledLoop, model_path: str | Path, design: DesignSpace) -> tuple[pd.DataFrame, dict]:
    """The design-space table (one row per grid point, with `spec_status`) and its figures of
    merit: the batches run, their wall time and the points of each status."""
    n_members = load_surrogate(model_path).n_members
    cases = grid_cases(design, n_members)
    t0 = time.perf_counter()
    outcomes = run_cases(loop, model_path, cases, design.n_jobs)
    wall = time.perf_counter() - t0
    table = point_table(outcomes_table(outcomes), design.third_factor.key)
    table["spec_status"] = specification_status(table, design.specification)
    counts = {s: int((table.spec_status == s).sum()) for s in STATUSES}
    per_minute = 60.0 * len(cases) / wall if wall > 0 else float("nan")
    info = {
        "batches": len(cases),
        "wall_time_s": wall,
        "batches_per_minute": per_minute,
        "n_jobs": design.n_jobs,
        "points": len(table),
        **counts,
    }
    log.info(
        "design space: %d PBM-ANN batches (%d points x (mean + %d members)) in %.1f s on %d process(es), "
        "%.0f batches per minute: %s",
        len(cases),
        len(table),
        n_members,
        wall,
        design.n_jobs,
        per_minute,
        ", ".join(f"{v} {k}" for k, v in counts.items()),
    )
    if counts["out_of_domain"]:
        log.warning(
            "design space: at %d of %d points the surrogate was evaluated outside its training domain; they are "
            "marked out_of_domain and not judged against the specification",
            counts["out_of_domain"],
            len(table),
        )
    if counts["failed"]:
        log.warning("design space: the PBM failed at %d of %d points (marked failed)", counts["failed"], len(table))
    return table, info
