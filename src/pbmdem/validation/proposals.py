"""Active learning: the next operating points worth a DEM run, from the PBM-ANN loops' samples
outside the surrogate's training domain or where its members disagree, written as a config
fragment to add to the grid (docs/validation.md, "Active learning").
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import yaml

from pbmdem.atomic import write_text
from pbmdem.config import Granulator, OperatingGrid, rpm_text
from pbmdem.frequency import pair_counts, pair_weighted_mean
from pbmdem.surrogate.features import make_features, pair_table

#: rounding of proposed class diameters (m) and number fractions
DIAMETER_STEP = 1e-4
FRACTION_STEP = 1e-3
#: two samples whose (rounded) class diameters differ by at most one step and whose number fractions
#: differ by less than this in every class teach the surrogate the same thing: only the first is
#: proposed, and a sample like a defined distribution proposes that distribution
SIMILAR_FRACTIONS = 0.02


@dataclass
class Assessment:
    """What the surrogate says about one interval's sample."""

    rpm: float
    interval: int
    diameters: list[float]
    counts: list[int]
    out_of_domain: dict[str, float] = field(default_factory=dict)  # feature -> relative excess
    spread: float = 0.0  # pair-weighted mean ensemble std of log10 c (decades)

    @property
    def is_out_of_domain(self) -> bool:
        return bool(self.out_of_domain)


def assess(surrogate, rpm: float, intervals: pd.DataFrame) -> list[Assessment]:
    """One Assessment per interval of a PBM-ANN run's intervals.csv."""
    ranges = surrogate.feature_ranges()
    out = []
    for row in intervals.itertuples():
        d, n = row.class_diameters, row.class_counts
        frame, _, _ = pair_table(d, n, rpm)
        features = make_features(frame, surrogate.impeller_radius)
        mask = surrogate.out_of_domain(frame)
        excess = {}
        for name in mask.columns[mask.any().to_numpy()]:
            lo, hi = ranges[name]
            v = features[name].to_numpy(float)
            span = hi - lo if hi > lo else max(abs(hi), 1e-300)
            excess[name] = float(np.max(np.maximum(lo - v, v - hi)) / span)
        _, std = surrogate.frequency_matrix(d, n, rpm, return_std=True, check_domain=False)
        spread = pair_weighted_mean(std, n) if pair_counts(n).sum() > 0 else float("nan")
        out.append(Assessment(float(rpm), int(row.interval), d.tolist(), n.astype(int).tolist(), excess, spread))
    return out


def largest_feasible_diameter(granulator: Granulator) -> float:
    """The largest proposed diameter (m): the largest rounding step below the granulator's
    `particle_diameter_limit`, which the config checks enforce."""
    return math.floor(granulator.particle_diameter_limit * (1 - 1e-9) / DIAMETER_STEP) * DIAMETER_STEP


def as_distribution(a: Assessment, d_max: float) -> tuple[list[float], list[float], bool]:
    """(diameters, number fractions, capped) of a sample: rounded (the ends outwards, so that the
    proposal spans the sample), ascending, classes merged where rounding makes them equal, capped at `d_max`."""
    steps = np.asarray(a.diameters, float) / DIAMETER_STEP
    order = np.argsort(steps)
    rounded = np.round(steps)
    rounded[order[0]] = math.floor(steps[order[0]] + 1e-6)
    rounded[order[-1]] = math.ceil(steps[order[-1]] - 1e-6)
    d = np.minimum(rounded * DIAMETER_STEP, d_max)
    capped = bool(np.any(np.asarray(a.diameters) > d_max))
    n = np.asarray(a.counts, float)
    classes: dict[float, float] = {}
    for di, ni in zip(d, n):
        key = round(float(di), 6)
        classes[key] = classes.get(key, 0.0) + ni
    diameters = sorted(classes)
    f = np.array([classes[k] for k in diameters])
    f = np.round(f / f.sum() / FRACTION_STEP) * FRACTION_STEP
    f[np.argmax(f)] += 1.0 - f.sum()  # exact sum 1 after rounding
    return [float(x) for x in diameters], [round(float(x), 6) for x in f], capped


def placement(rpm: float, grid_speeds) -> list[float]:
    """The speeds at which a sample from PBM-ANN at `rpm` is run: `rpm` itself when it is a grid speed
    or outside the grid's speeds, else the grid speeds on either side."""
    speeds = sorted(float(r) for r in grid_speeds)
    rpm = float(rpm)
    if rpm in speeds or rpm < speeds[0] or rpm > speeds[-1]:
        return [rpm]
    return [max(r for r in speeds if r < rpm), min(r for r in speeds if r > rpm)]


def propose(
    grid: OperatingGrid, granulator: Granulator, distributions: dict, assessments: list[Assessment], max_points: int
) -> pd.DataFrame:
    """The proposals (`PROPOSAL_COLUMNS`), one row per chosen sample, out-of-domain first (by excess),
    then by ensemble spread; a sample like one of the defined `distributions` proposes that one."""
    ranked = sorted(
        assessments, key=lambda a: (not a.is_out_of_domain, -max(a.out_of_domain.values(), default=0.0), -a.spread)
    )
    d_max = largest_feasible_diameter(granulator)
    known = {}
    for name, dist in distributions.items():
        rounded = as_distribution(Assessment(0.0, -1, list(dist.diameters), list(dist.number_fractions)), np.inf)
        known.setdefault((tuple(rounded[0]), tuple(rounded[1])), name)
    existing = set(grid.points())
    rows, seen = [], []
    for a in ranked:
        if len(rows) >= max_points:
            break
        diameters, fractions, capped = as_distribution(a, d_max)
        key = (tuple(diameters), tuple(fractions))
        speeds = placement(a.rpm, grid.impeller_rpm)
        reason = (
            "outside the training domain in "
            + ", ".join(f"{k} (by {v:.2g} of its range)" for k, v in sorted(a.out_of_domain.items()))
            if a.is_out_of_domain
            else f"largest surrogate uncertainty (calibrated std) ({a.spread:.3g} decades)"
        )
        match = known.get(key) or next((n for k, n in known.items() if similar(key, k)), None)
        if match is not None:
            name, kind = match, "point"
            speeds = [r for r in speeds if (r, name) not in existing]
            if not speeds:
                continue  # those very points are run already
            existing |= {(r, name) for r in speeds}
        else:
            if any(similar(key, other) for other in seen):
                continue
            seen.append(key)
            taken = set(distributions) | {r["name"] for r in rows}
            name, kind = unique_name(f"al_rpm{rpm_text(a.rpm).replace('.', 'p')}_i{a.interval}", taken), "distribution"
        rows.append(
            {
                "name": name,
                "kind": kind,
                "rpm": a.rpm,
                "interval": a.interval,
                "reason": reason,
                "out_of_domain_features": ";".join(sorted(a.out_of_domain)),
                "ensemble_spread_log10": a.spread,
                "diameters": json.dumps(diameters),
                "number_fractions": json.dumps(fractions),
                "points_rpm": json.dumps(speeds),
                "capped_at_granulator_limit": capped,
            }
        )
    return pd.DataFrame(rows, columns=PROPOSAL_COLUMNS)


#: the columns of `propose` (results/validation/proposals.csv)
PROPOSAL_COLUMNS = [
    "name",
    "kind",
    "rpm",
    "interval",
    "reason",
    "out_of_domain_features",
    "ensemble_spread_log10",
    "diameters",
    "number_fractions",
    "points_rpm",
    "capped_at_granulator_limit",
]


def unique_name(base: str, taken: set[str]) -> str:
    """`base`, or `base_2`, `base_3`, ... if taken (a proposal never redefines a distribution)."""
    name, k = base, 1
    while name in taken:
        k += 1
        name = f"{base}_{k}"
    return name


def similar(a: tuple, b: tuple) -> bool:
    """Whether two rounded distributions (diameters, fractions) teach the surrogate the same thing."""
    if len(a[0]) != len(b[0]):
        return False
    close_d = np.all(np.abs(np.subtract(a[0], b[0])) <= 1.5 * DIAMETER_STEP)
    return bool(close_d and np.all(np.abs(np.subtract(a[1], b[1])) < SIMILAR_FRACTIONS))


def fragment(grid: OperatingGrid, proposals: pd.DataFrame) -> dict:
    """The config fragment of the proposals: the new size distributions and the grid's complete
    list of extra points with the proposed ones added."""
    if proposals.empty:
        return {}
    dists = {
        r.name: {"diameters": json.loads(r.diameters), "number_fractions": json.loads(r.number_fractions)}
        for r in proposals.itertuples()
        if r.kind == "distribution"
    }
    points = [p.to_dict() for p in grid.extra_points]
    for r in proposals.itertuples():
        points += [{"rpm": float(rpm), "distribution": r.name} for rpm in json.loads(r.points_rpm)]
    out = {"size_distributions": dists} if dists else {}
    out["grid"] = {"extra_points": points}
    return out


def write_fragment(grid: OperatingGrid, proposals: pd.DataFrame, path, source: str) -> None:
    """`proposals` as a YAML config fragment with a header saying where it comes from and how to use it."""
    lines = [
        f"# Operating points proposed by pbmdem's active learning from {source}.",
        "# Add them to the grid with (only the new DEM points run, then the surrogate and what follows):",
        "#   snakemake --cores 2 --configfile config/config.yaml <this file>",
    ]
    for r in proposals.itertuples():
        at = " and ".join(f"{rpm:g}" for rpm in json.loads(r.points_rpm))
        what = f"new distribution {r.name} at {at} rpm" if r.kind == "distribution" else f"{r.name} at {at} rpm"
        lines.append(
            f"# {what} (PBM-ANN at {r.rpm:g} rpm, interval {r.interval}): {r.reason}"
            + ("; largest class capped at the granulator's limit" if r.capped_at_granulator_limit else "")
        )
    body = fragment(grid, proposals)
    if not body:
        lines.append(
            "# Nothing to propose: every sample the loops asked about is a point of the grid already "
            "(or validation.proposals.max_points is 0)."
        )
    write_text(path, "\n".join(lines) + "\n" + (yaml.safe_dump(body, sort_keys=False) if body else "{}\n"))
