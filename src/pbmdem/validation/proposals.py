"""Active learning: the next operating points worth a DEM run.

The PBM-ANN loop asks the surrogate, at the start of every coupling interval, for the encounter
frequencies of one representative DEM sample of the PBM's size distribution. This module looks at
those samples (the `intervals.csv` of each validation speed's PBM-ANN run) and ranks them:

1. samples outside the surrogate's training domain (any feature outside its training range);
   their extrapolated frequencies are the least trustworthy;
2. then the samples where the surrogate's ensemble members disagree most (the pair-weighted mean
   standard deviation of their log10 c_ij, in decades).

Each chosen sample becomes a proposed operating point: its classes (diameters rounded to 0.1 mm,
outwards at both ends, number fractions to 0.001) as a new named size distribution for the grid, and its speed when the
impeller tip speed is what lies outside the domain; a sample that is a grid distribution already
proposes its speed instead (the grid runs every distribution at every speed). A class too large for the DEM granulator
(three diameters above the blade top, half the bowl radius) is capped at that limit, and the
proposal says so. `write_fragment` writes them as a config fragment to add to the grid:

    snakemake --cores 2 --configfile config/config.yaml results/validation/proposals.yaml

(Snakemake merges the fragment's new distributions and its complete grid lists over the config;
only the new DEM points run, then the surrogate and everything after it.)
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from pbmdem.config import Granulator, OperatingGrid, rpm_text
from pbmdem.frequency import pair_counts, pairs_of

#: rounding of proposed class diameters (m) and number fractions
DIAMETER_STEP = 1e-4
FRACTION_STEP = 1e-3
#: two samples with the same (rounded) class diameters whose number fractions differ by less than
#: this in every class teach the surrogate the same thing: only the first is proposed
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
    from pbmdem.surrogate.features import make_features, pair_table

    ranges = surrogate.feature_ranges()
    out = []
    for row in intervals.itertuples():
        d = np.asarray(json.loads(row.class_diameters), float)
        n = np.asarray(json.loads(row.class_counts), float)
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
        pairs = pairs_of(pair_counts(n))
        spread = float((pairs_of(std) * pairs).sum() / pairs.sum()) if pairs.sum() > 0 else float("nan")
        out.append(Assessment(float(rpm), int(row.interval), d.tolist(), n.astype(int).tolist(), excess, spread))
    return out


def largest_feasible_diameter(granulator: Granulator) -> float:
    """The largest DEM particle the granulator takes (the config checks' limits), m."""
    bowl, top = granulator.bowl, granulator.impeller.top
    limit = min((bowl.height - top) / 3.0, bowl.radius / 2.0)
    return math.floor(limit * (1 - 1e-9) / DIAMETER_STEP) * DIAMETER_STEP


def as_distribution(a: Assessment, d_max: float) -> tuple[list[float], list[float], bool]:
    """(diameters, number fractions, capped) of a sample: rounded, ascending, classes merged where
    rounding makes them equal, too large classes capped at `d_max`. The smallest class is rounded
    down and the largest up (the others to the nearest step), so that the proposal spans the sample:
    a sample just beyond the training sizes (8.004 mm against 8 mm) proposes 8.1 mm, not 8 mm again."""
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


def propose(
    grid: OperatingGrid, granulator: Granulator, distributions: dict, assessments: list[Assessment], max_points: int
) -> pd.DataFrame:
    """The proposals: one row per chosen sample (out-of-domain first, by excess; then by ensemble
    spread). A sample that is one of the grid's distributions (`distributions`: name ->
    SizeDistribution, as rounded here) proposes its speed for the grid, if the speed is new, and
    is skipped otherwise; any other sample proposes a new distribution (and its speed too when the
    tip speed is what lies outside the domain). Columns: name, kind ('distribution' or 'speed'),
    rpm, interval, reason, diameters (m) and fractions (JSON), propose_speed, capped."""
    ranked = sorted(
        assessments, key=lambda a: (not a.is_out_of_domain, -max(a.out_of_domain.values(), default=0.0), -a.spread)
    )
    d_max = largest_feasible_diameter(granulator)
    known = {}
    for name in grid.size_distributions:
        dist = distributions[name]
        rounded = as_distribution(Assessment(0.0, -1, list(dist.diameters), list(dist.number_fractions)), np.inf)
        known[(tuple(rounded[0]), tuple(rounded[1]))] = name
    rows, seen = [], set()
    for a in ranked:
        if len(rows) >= max_points:
            break
        diameters, fractions, capped = as_distribution(a, d_max)
        key = (tuple(diameters), tuple(fractions))
        reason = (
            "outside the training domain in "
            + ", ".join(f"{k} (by {v:.2g} of its range)" for k, v in sorted(a.out_of_domain.items()))
            if a.is_out_of_domain
            else f"largest ensemble spread ({a.spread:.3g} decades)"
        )
        if key in known:
            name, kind = known[key], "speed"
            if a.rpm in grid.impeller_rpm or ("speed", a.rpm) in seen:
                continue  # that very point is in the grid already
            seen.add(("speed", a.rpm))
        else:
            if any(similar(key, other) for other in seen if isinstance(other[0], tuple)):
                continue
            seen.add(key)
            name, kind = (
                unique_name(
                    f"al_rpm{rpm_text(a.rpm).replace('.', 'p')}_i{a.interval}",
                    set(distributions) | {r["name"] for r in rows},
                ),
                "distribution",
            )
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
                "propose_speed": kind == "speed" or ("tip_speed" in a.out_of_domain and a.rpm not in grid.impeller_rpm),
                "capped_at_granulator_limit": capped,
            }
        )
    return pd.DataFrame(
        rows,
        columns=[
            "name",
            "kind",
            "rpm",
            "interval",
            "reason",
            "out_of_domain_features",
            "ensemble_spread_log10",
            "diameters",
            "number_fractions",
            "propose_speed",
            "capped_at_granulator_limit",
        ],
    )


def unique_name(base: str, taken: set[str]) -> str:
    """`base`, or `base_2`, `base_3`, ... if taken (a proposal never redefines a distribution)."""
    name, k = base, 1
    while name in taken:
        k += 1
        name = f"{base}_{k}"
    return name


def similar(a: tuple, b: tuple) -> bool:
    """Two rounded distributions (diameters, fractions) with the same diameters and fractions
    within SIMILAR_FRACTIONS of each other."""
    return a[0] == b[0] and bool(np.all(np.abs(np.subtract(a[1], b[1])) < SIMILAR_FRACTIONS))


def fragment(grid: OperatingGrid, proposals: pd.DataFrame) -> dict:
    """The config fragment of the proposals: the new size distributions and the grid's complete
    lists with them (and any proposed speed) added."""
    if proposals.empty:
        return {}
    dists = {
        r.name: {"diameters": json.loads(r.diameters), "number_fractions": json.loads(r.number_fractions)}
        for r in proposals.itertuples()
        if r.kind == "distribution"
    }
    speeds = list(grid.impeller_rpm)
    for r in proposals.itertuples():
        if r.propose_speed and r.rpm not in speeds:
            speeds.append(float(r.rpm))
    out = {"size_distributions": dists} if dists else {}
    out["grid"] = {"impeller_rpm": sorted(speeds), "size_distributions": list(grid.size_distributions) + list(dists)}
    return out


def write_fragment(grid: OperatingGrid, proposals: pd.DataFrame, path, source: str) -> None:
    """`proposals` as a YAML config fragment with a header saying where it comes from and how to use it."""
    import yaml

    from pbmdem.atomic import write_text

    lines = [
        f"# Operating points proposed by pbmdem's active learning from {source}.",
        "# Add them to the grid with (only the new DEM points run, then the surrogate and what follows):",
        "#   snakemake --cores 2 --configfile config/config.yaml <this file>",
    ]
    for r in proposals.itertuples():
        what = f"new distribution {r.name}" if r.kind == "distribution" else f"speed {r.rpm:g} rpm for {r.name}"
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
