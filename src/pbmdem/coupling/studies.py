"""The PBM-ANN studies behind the report's findings: final granule sizes against impeller speed and
against the feed (the grid's distributions and 50:50 blends by mass of neighbours), each with the
ensemble members' spread and the intervals outside the training domain (docs/validation.md)."""

from __future__ import annotations

import logging
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.config import BLEND_JOIN, CoupledLoop, SizeDistribution, feed_case_names, feed_case_parents
from pbmdem.pbm.errors import PBMError
from pbmdem.pbm.impact_breakage import critical_speed
from pbmdem.surrogate import load_surrogate
from pbmdem.tables import STATISTICS

from .loop import CouplingError
from .methods import pbm_ann

log = logging.getLogger(__name__)


def blend(a: SizeDistribution, b: SizeDistribution, mass_share_a: float = 0.5) -> SizeDistribution:
    """A mix of two feeds by mass (`mass_share_a` of the mass from `a`): the union of their classes."""
    if not 0.0 < mass_share_a < 1.0:
        raise ValueError(f"mass_share_a = {mass_share_a}: allowed 0 < share < 1")
    mass: dict[float, float] = {}
    for sizes, share in ((a, mass_share_a), (b, 1.0 - mass_share_a)):
        d = np.asarray(sizes.diameters, float)
        m = np.asarray(sizes.number_fractions, float) * d**3
        for dk, mk in zip(d, share * m / m.sum(), strict=True):
            mass[float(dk)] = mass.get(float(dk), 0.0) + float(mk)
    diameters = sorted(mass)
    numbers = np.array([mass[dk] / dk**3 for dk in diameters])
    return SizeDistribution(
        diameters=tuple(diameters), number_fractions=tuple(float(x) for x in numbers / numbers.sum())
    )


def feed_cases(distributions: dict[str, SizeDistribution]) -> list[tuple[str, SizeDistribution, bool]]:
    """(name, sizes, in the DEM grid) of the grid's feeds ordered by mass-median diameter, with a
    50:50 blend by mass between each pair of neighbours ("fine+medium"): the cases and their names
    are `pbmdem.config.feed_case_names`."""
    cases = []
    for name, in_grid in feed_case_names(distributions):
        if in_grid:
            cases.append((name, distributions[name], True))
        else:
            finer, coarser = name.split(BLEND_JOIN)
            cases.append((name, blend(distributions[finer], distributions[coarser]), False))
    return cases


def feed_case(distributions: dict[str, SizeDistribution], name: str) -> SizeDistribution:
    """The sizes of the feed study's case `name` (a feed or a blend, `feed_cases`)."""
    cases = feed_cases(distributions)
    for case, sizes, _ in cases:
        if case == name:
            return sizes
    raise ValueError(f"feed {name!r} is not a case of the feed study; its cases: {[c for c, _, _ in cases]}")


def with_feed(loop: CoupledLoop, name: str, sizes: SizeDistribution) -> CoupledLoop:
    """The coupled loop `loop` started from the feed `sizes` (named `name`)."""
    return loop.replace(batch=loop.batch.replace(distribution=name, sizes=sizes))


def final_statistics(summary: pd.DataFrame) -> dict:
    """The final d10/d50/d90 (m) of a PBM run's summary (its last row)."""
    last = summary.iloc[-1]
    return {s: float(last[s]) for s in STATISTICS}


def run_case(loop: CoupledLoop, model_path: str | Path, rpm: float, feed: str, sizes: SizeDistribution) -> dict:
    """PBM-ANN for one (speed, feed): final d10/d50/d90 (m) of the ensemble mean, the members'
    min and max of each, the members that failed, the intervals outside the training domain and
    the wall time."""
    case = with_feed(loop, feed, sizes)
    n_members = load_surrogate(model_path).n_members
    row: dict = {"rpm": float(rpm), "feed": feed, "feed_d50": sizes.mass_median}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        try:
            outcome = pbm_ann(case, model_path, rpm, Path(tmp) / "mean")
        except (PBMError, CouplingError) as exc:  # reported as a failed case, its sizes empty
            log.warning("PBM-ANN at %g rpm, feed %s, ensemble mean failed: %s", rpm, feed, exc)
            row.update({s: float("nan") for s in STATISTICS} | {"mean_failed": True})
            row.update({"out_of_domain_intervals": 0, "intervals": 0})
        else:
            row.update(final_statistics(outcome.result.summary()) | {"mean_failed": False})
            row["out_of_domain_intervals"] = int(outcome.totals.get("out_of_domain_intervals", 0))
            row["intervals"] = int(outcome.totals.get("intervals", loop.coupling_intervals))
            row["merged_fraction"] = float(outcome.totals["grid_floor"]["merged_fraction"])
        finals, failed = [], 0
        for k in range(n_members):
            try:
                member = pbm_ann(case, model_path, rpm, Path(tmp) / f"member{k}", member=k)
            except (PBMError, CouplingError) as exc:
                log.warning("PBM-ANN at %g rpm, feed %s, ensemble member %d failed: %s", rpm, feed, k, exc)
                failed += 1
                continue
            finals.append(
                final_statistics(member.result.summary()) | {"merged": member.totals["grid_floor"]["merged_fraction"]}
            )
    for s in STATISTICS:
        values = [f[s] for f in finals]
        row[f"{s}_member_min"] = min(values) if values else float("nan")
        row[f"{s}_member_max"] = max(values) if values else float("nan")
    # breakage fragments merged at the grid floor, as a share of the final number (Result.grid_floor)
    row.setdefault("merged_fraction", float("nan"))
    row["merged_fraction_member_max"] = max((f["merged"] for f in finals), default=float("nan"))
    row["members"] = n_members
    row["members_failed"] = failed
    row["wall_time_s"] = time.perf_counter() - t0
    log.info(
        "PBM-ANN study: %g rpm, feed %s: final d50 %.3f mm (members %.3f-%.3f), %d of %d interval(s) outside "
        "the training domain, %.1f s",
        rpm,
        feed,
        1e3 * row["d50"],
        1e3 * row["d50_member_min"],
        1e3 * row["d50_member_max"],
        row["out_of_domain_intervals"],
        row["intervals"],
        row["wall_time_s"],
    )
    return row


def speed_study(loop: CoupledLoop, model_path: str | Path, speeds, grid_speeds) -> pd.DataFrame:
    """Final sizes against impeller speed for the loop's feed, one row per speed of `speeds`;
    `in_grid_range`: the speed lies within the DEM grid's speeds."""
    lo, hi = min(grid_speeds), max(grid_speeds)
    rows = []
    for rpm in speeds:
        row = run_case(loop, model_path, float(rpm), loop.batch.distribution, loop.batch.sizes)
        row["in_grid_range"] = bool(lo <= float(rpm) <= hi)
        row["dem_speed"] = float(rpm) in {float(s) for s in grid_speeds}
        rows.append(row)
    return pd.DataFrame(rows)


def feed_study(
    loop: CoupledLoop, model_path: str | Path, rpm: float, distributions: dict[str, SizeDistribution]
) -> pd.DataFrame:
    """Final sizes against the feed at `rpm`: the grid's feeds and blends between them (`feed_cases`);
    `in_grid`: a feed the DEM runs used."""
    rows = []
    for name, sizes, in_grid in feed_cases(distributions):
        row = run_case(loop, model_path, rpm, name, sizes)
        row["in_grid"] = in_grid
        rows.append(row)
    return pd.DataFrame(rows)


def feed_case_study(
    loop: CoupledLoop, model_path: str | Path, rpm: float, distributions: dict[str, SizeDistribution], name: str
) -> pd.DataFrame:
    """:func:`feed_study`'s rows of the case `name` and of its parents (the grid feeds on either
    side, `pbmdem.config.feed_case_parents`) at `rpm`, in the feed study's order: what the feed
    check compares PBM-DEM with."""
    cases = feed_cases(distributions)
    parents = feed_case_parents([(case, in_grid) for case, _, in_grid in cases])
    if name not in parents:
        raise ValueError(
            f"feed {name!r}: not a case of the feed study with a grid feed on either side; such cases: {list(parents)}"
        )
    rows = []
    for case, sizes, in_grid in cases:
        if case == name or case in parents[name]:
            rows.append(run_case(loop, model_path, rpm, case, sizes) | {"in_grid": in_grid})
    return pd.DataFrame(rows)


#: step guard of one batch of the breakage study: 30x the default batch's ~170 steps. In the default
#: run of 2026-12-02 most ensemble members of every breakage variant collapsed to feed size and
#: stopped at the guard (133 member batches at 20,000 steps, 2.5 s each: 5.5 of the study's 6.8 min)
BREAKAGE_STUDY_MAX_STEPS = 5_000


def breakage_variants(pbm) -> dict:
    """The breakage settings the breakage study compares (name -> pbm.breakage): breakage off
    (aggregation only), the configured criterion, the dynamic yield strength Y halved and doubled,
    and, with a spread of granule strengths configured, the sharp criterion (``strength_spread`` 0:
    every impact above v* breaks). The criterion depends on Y and St_def* only through
    v* ~ sqrt(Y St_def*): halving or doubling St_def* gives the Y variants' results, so it is not
    run again."""
    brk = pbm.breakage.replace(enabled=True)
    variants = {
        "off": pbm.breakage.replace(enabled=False),
        "default": brk,
        "Y/2": brk.replace(yield_strength=0.5 * brk.yield_strength),
        "Yx2": brk.replace(yield_strength=2.0 * brk.yield_strength),
    }
    if brk.strength_spread > 0:
        variants["sharp"] = brk.replace(strength_spread=0.0)
    return variants


def breakage_study(
    loop: CoupledLoop, model_path: str | Path, speeds, grid_speeds, variants: dict | None = None
) -> pd.DataFrame:
    """:func:`speed_study` once per breakage variant (``variants``, name -> pbm.breakage; None:
    :func:`breakage_variants`, without breakage, with it, with Y halved and doubled and with the sharp
    criterion): final sizes against impeller speed; columns ``variant``, ``yield_strength``,
    ``critical_stokes``, ``strength_spread``, ``strength_porosity_exponent``, ``critical_speed`` (m/s,
    v* = sqrt(2 Y St_def* / rho) of a granule at the reference size and porosity) beside the speed study's."""
    pbm = loop.batch.pbm
    # a variant whose breakage is so fast that the explicit solver's positivity limit takes
    # 30x the default batch's ~170 steps is reported as failed after BREAKAGE_STUDY_MAX_STEPS,
    # instead of spending minutes per ensemble member on the way to the solver's own guard
    solver = pbm.solver.replace(max_steps=min(pbm.solver.max_steps, BREAKAGE_STUDY_MAX_STEPS))
    frames = []
    for name, brk in (breakage_variants(pbm) if variants is None else variants).items():
        case = loop.replace(batch=loop.batch.replace(pbm=pbm.replace(breakage=brk, solver=solver)))
        frame = speed_study(case, model_path, speeds, grid_speeds)
        v = critical_speed(pbm.aggregation.success.stokes.granule_density, brk.yield_strength, brk.critical_stokes)
        frames.append(
            frame.assign(
                variant=name,
                breakage=brk.enabled,
                yield_strength=brk.yield_strength,
                critical_stokes=brk.critical_stokes,
                strength_spread=brk.strength_spread,
                strength_porosity_exponent=brk.strength_porosity_exponent,
                critical_speed=v if brk.enabled else float("nan"),
            )
        )
    out = pd.concat(frames, ignore_index=True)
    first = ["variant", "breakage", "yield_strength", "critical_stokes", "strength_spread"]
    first += ["strength_porosity_exponent", "critical_speed"]
    return out[first + [c for c in out.columns if c not in first]]
