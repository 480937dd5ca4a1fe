"""A space-filling design of operating points for the DEM grid.

The surrogate learns the encounter frequency of a class pair from the pair's diameters, the number
fractions of its two classes, the bed's particle count and the tip speed
(`pbmdem.surrogate.features.FEATURE_NAMES`). The named feeds at the grid's speeds place a few beds
in that space; the PBM's states lie between them. `design_points` fills the space between with
three-class distributions, each at one impeller speed, from a scrambled Sobol sequence
(scipy.stats.qmc, seeded) over six coordinates:

* the smallest diameter, log-uniform in `d_min_range`;
* the largest over the smallest, log-uniform from `min_span` to what keeps the largest within
  `d_max_limit`;
* the middle class's place between them on a log scale, uniform in `middle_range`;
* the number fractions, uniform on the simplex above a floor `min_fraction` for each class;
* the impeller speed, log-uniform in `rpm_range` (the speeds of the named grid double from one to
  the next, and the encounter rate changes most at the low end).

The particle count follows from the bed's solid volume (`pbmdem.dem.plan.bed_particle_count`).
Placing each distribution at one speed, instead of at every grid speed, spreads the design over
the tip-speed feature too, between the grid's speeds, at a quarter of the cost of running it at
four speeds. Diameters are rounded to 0.1 mm, fractions to 0.01 and speeds to 10 rpm, so that the
config holds the design as plain numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class DesignSpace:
    """The ranges of the design (m for diameters). The defaults span the feeds and the active
    learning's points of the default grid and reach past them where the PBM goes: smallest classes
    2-3.2 mm, largest up to 9.5 mm (the largest class of PBM-ANN's samples at 900-1200 rpm reached
    8.1 mm, the largest class of the feeds and the active learning's points), size ratios largest /
    smallest from 1.5 (narrower than any feed) to 4, every class at least 10 % of the particles (a
    smaller class has too few pairs for a frequency: docs/validation.md), speeds over the grid's."""

    d_min_range: tuple[float, float] = (0.0020, 0.0032)
    min_span: float = 1.5
    d_max_limit: float = 0.0095
    middle_range: tuple[float, float] = (0.3, 0.7)
    min_fraction: float = 0.10
    max_span: float = 4.0
    rpm_range: tuple[float, float] = (150.0, 1200.0)


def _fractions(u: float, v: float, floor: float) -> list[float]:
    """A point of the simplex (three fractions >= floor) from two uniform numbers (uniform on it)."""
    r = math.sqrt(u)
    simplex = (1.0 - r, r * (1.0 - v), r * v)
    raw = [floor + (1.0 - 3.0 * floor) * s for s in simplex]
    rounded = [round(f, 2) for f in raw[:2]]
    return [*rounded, round(1.0 - sum(rounded), 2)]


def design_points(n: int, seed: int, space: DesignSpace = DesignSpace()) -> list[dict]:
    """`n` design points `{"rpm": ..., "diameters": [...], "number_fractions": [...]}` (three
    classes, m, ascending; fractions sum to 1) from the first `n` points of a scrambled Sobol
    sequence seeded with `seed`."""
    from scipy.stats import qmc

    if n < 1:
        raise ValueError(f"n = {n!r}: at least one design point is needed")
    points = qmc.Sobol(d=6, scramble=True, seed=seed).random(n)
    out = []
    lo, hi = space.d_min_range
    rpm_lo, rpm_hi = space.rpm_range
    for a, b, c, u, v, w in points:
        d_min = lo * (hi / lo) ** a
        top = min(space.max_span, space.d_max_limit / d_min)
        span = space.min_span * (top / space.min_span) ** b
        t = space.middle_range[0] + (space.middle_range[1] - space.middle_range[0]) * c
        diameters = [d_min, d_min * span**t, d_min * span]
        out.append(
            {
                "rpm": float(round(rpm_lo * (rpm_hi / rpm_lo) ** w, -1)),
                "diameters": [round(float(d), 4) for d in diameters],
                "number_fractions": _fractions(float(u), float(v), space.min_fraction),
            }
        )
    return out


def design_names(n: int, prefix: str = "sf") -> list[str]:
    """The config names of the design's distributions: sf01, sf02, ..."""
    width = max(2, len(str(n)))
    return [f"{prefix}{k + 1:0{width}d}" for k in range(n)]


def design_yaml(n: int, seed: int) -> str:
    """The design as config/config.yaml entries: `size_distributions` and `grid.design_points`."""
    names, points = design_names(n), design_points(n, seed)
    lines = ["size_distributions:"]
    for name, point in zip(names, points):
        d = ", ".join(f"{x:g}" for x in point["diameters"])
        f = ", ".join(f"{x:.2f}" for x in point["number_fractions"])
        lines += [f"  {name}:", f"    diameters: [{d}]", f"    number_fractions: [{f}]"]
    lines += ["grid:", "  design_points:"]
    lines += [f"    - {{rpm: {point['rpm']:g}, distribution: {name}}}" for name, point in zip(names, points)]
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover - prints the config entries
    import sys

    print(design_yaml(int(sys.argv[1]), int(sys.argv[2])))
