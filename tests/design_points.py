"""A space-filling design of operating points for the DEM grid (the generator of the config's
`grid.design_points`: `python tests/design_points.py N SEED [CONFIG]` prints the entries;
tests/test_dem_design.py holds config/config.yaml equal to it).

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
* the number fraction of the largest class, log-uniform from `min_fraction` to 1/3, and how the
  rest splits between the two smaller classes (each at least the largest's): the PBM's samples are
  mostly beds of small granules with a few large aggregates, whose rare classes (2.5-8 % of a
  sample) a design with every class at 10 % or more left outside the training domain;
* the impeller speed, log-uniform in `rpm_range` (the speeds of the named grid double from one to
  the next, and the encounter rate changes most at the low end).

The particle count follows from the bed's solid volume (`pbmdem.dem.plan.bed_particle_count`). A
class needs particles to give a frequency: a point whose largest class would hold fewer than
`min_class_particles` (the 50 granules below which the PBM's samples merge classes,
`validation.min_particles_per_class`) is skipped and the sequence goes on, so the rarest classes
come in beds of many small granules, as in the PBM.
Placing each distribution at one speed, instead of at every grid speed, spreads the design over
the tip-speed feature too, between the grid's speeds, at a quarter of the cost of running it at
four speeds.

A handful of Sobol points need not come near a corner of the space, and one corner matters most:
the largest granules at the fastest speeds, where the batch grows most. `corner_point` pins a
distribution there: its largest class at `d_max_limit`, its smallest at the widest span, both
larger classes as rare as `min_class_particles` allows, at the top of `rpm_range`. (Ten Sobol
points of seed 20141 reached 8.3 mm, and PBM-ANN's samples at 900 rpm left the training domain
with classes of 8.5-8.8 mm.) Diameters are rounded to 0.1 mm, fractions to 0.001 and speeds to
10 rpm, so that the config holds the design as plain numbers.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

from scipy.stats import qmc

from pbmdem.config import SizeDistribution, load_config
from pbmdem.dem.plan import bed_particle_count, class_counts


@dataclass(frozen=True)
class DesignSpace:
    """The ranges of the design (m for diameters). The defaults span the feeds and the active
    learning's points of the default grid and reach past them where the PBM goes: smallest classes
    2-3.2 mm, largest up to 9.5 mm (the largest class of PBM-ANN's samples at 900-1200 rpm reached
    8.1 mm, the largest class of the feeds and the active learning's points), size ratios largest /
    smallest from 1.5 (narrower than any feed) to 4, the largest class from 2 % of the particles
    with at least 50 particles in every class (docs/validation.md), speeds over the grid's."""

    d_min_range: tuple[float, float] = (0.0020, 0.0032)
    min_span: float = 1.5
    d_max_limit: float = 0.0095
    middle_range: tuple[float, float] = (0.3, 0.7)
    min_fraction: float = 0.02
    max_span: float = 4.0
    rpm_range: tuple[float, float] = (150.0, 1200.0)
    min_class_particles: int = 50


def _fractions(u: float, v: float, floor: float) -> list[float]:
    """Three number fractions (sum 1, smallest diameter first) from two uniform numbers: the largest
    class's log-uniform from `floor` to 1/3 (u), the rest split between the two smaller classes,
    each at least the largest's (v)."""
    rare = floor * (1.0 / (3.0 * floor)) ** u
    first = round(rare + (1.0 - 3.0 * rare) * v, 3)
    rare = round(rare, 3)
    return [first, round(1.0 - first - rare, 3), rare]


def _particles(bed_solid_volume: float, diameters, fractions) -> list[int]:
    """Particles per class of a bed of `bed_solid_volume` (m3): the counts a DEM run would plan."""
    sizes = SizeDistribution(diameters=tuple(diameters), number_fractions=tuple(fractions))
    return class_counts(bed_particle_count(bed_solid_volume, sizes), fractions)


def design_points(n: int, seed: int, bed_solid_volume: float, space: DesignSpace = DesignSpace()) -> list[dict]:
    """`n` design points `{"rpm": ..., "diameters": [...], "number_fractions": [...]}` (three
    classes, m, ascending; fractions sum to 1): the first `n` points of a scrambled Sobol sequence
    seeded with `seed` whose every class holds at least `space.min_class_particles` particles in a
    bed of `bed_solid_volume` (m3, `granulator.bed_solid_volume`)."""
    if n < 1:
        raise ValueError(f"n = {n!r}: at least one design point is needed")
    candidates = qmc.Sobol(d=6, scramble=True, seed=seed).random(2 ** math.ceil(math.log2(64 * n)))
    out = []
    lo, hi = space.d_min_range
    rpm_lo, rpm_hi = space.rpm_range
    for a, b, c, u, v, w in candidates:
        d_min = lo * (hi / lo) ** a
        top = min(space.max_span, space.d_max_limit / d_min)
        span = space.min_span * (top / space.min_span) ** b
        t = space.middle_range[0] + (space.middle_range[1] - space.middle_range[0]) * c
        diameters = [round(float(d), 4) for d in (d_min, d_min * span**t, d_min * span)]
        fractions = _fractions(float(u), float(v), space.min_fraction)
        if min(_particles(bed_solid_volume, diameters, fractions)) < space.min_class_particles:
            continue
        rpm = float(round(rpm_lo * (rpm_hi / rpm_lo) ** w, -1))
        out.append({"rpm": rpm, "diameters": diameters, "number_fractions": fractions})
        if len(out) == n:
            return out
    raise ValueError(
        f"only {len(out)} of the {n} design points hold {space.min_class_particles} particles in every class"
    )


def corner_point(bed_solid_volume: float, space: DesignSpace = DesignSpace()) -> dict:
    """The design's corner of large granules at high speed, `{"rpm", "diameters", "number_fractions"}`:
    the largest class at `space.d_max_limit`, the smallest at `d_max_limit / max_span` (rounded up
    to 0.1 mm, within `d_min_range`), the middle class halfway between on a log scale, at the top
    of `rpm_range`. The two larger classes share the smallest number fraction (0.001 steps from
    `min_fraction`) at which every class of a bed of `bed_solid_volume` (m3) holds
    `min_class_particles`: the rare large aggregates of a bed that has grown."""
    lo, hi = space.d_min_range
    d_max = space.d_max_limit
    d_min = min(hi, max(lo, math.ceil(round(d_max / space.max_span * 1e4, 6)) / 1e4))
    diameters = [d_min, round(math.sqrt(d_min * d_max), 4), d_max]
    for k in range(round(space.min_fraction * 1000), 334):
        rare = k / 1000.0
        fractions = [round(1.0 - 2.0 * rare, 3), rare, rare]
        if min(_particles(bed_solid_volume, diameters, fractions)) >= space.min_class_particles:
            return {"rpm": space.rpm_range[1], "diameters": diameters, "number_fractions": fractions}
    raise ValueError(
        f"a bed of {bed_solid_volume:g} m3 cannot hold {space.min_class_particles} particles in every class "
        f"of {[f'{d * 1e3:g} mm' for d in diameters]}"
    )


#: the config name of `corner_point`'s distribution
CORNER_NAME = "corner"


def design_names(n: int, prefix: str = "sf") -> list[str]:
    """The config names of the design's distributions: sf01, sf02, ..."""
    width = max(2, len(str(n)))
    return [f"{prefix}{k + 1:0{width}d}" for k in range(n)]


def design_yaml(n: int, seed: int, bed_solid_volume: float) -> str:
    """The design as config/config.yaml entries: `size_distributions` and `grid.design_points`, the
    `n` Sobol points and the corner last."""
    names = [*design_names(n), CORNER_NAME]
    points = [*design_points(n, seed, bed_solid_volume), corner_point(bed_solid_volume)]
    lines = ["size_distributions:"]
    for name, point in zip(names, points):
        d = ", ".join(f"{x:g}" for x in point["diameters"])
        f = ", ".join(f"{x:g}" for x in point["number_fractions"])
        lines += [f"  {name}:", f"    diameters: [{d}]", f"    number_fractions: [{f}]"]
    lines += ["grid:", "  design_points:"]
    lines += [f"    - {{rpm: {point['rpm']:g}, distribution: {name}}}" for name, point in zip(names, points)]
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover - prints the config entries
    config = load_config(sys.argv[3] if len(sys.argv) > 3 else "config/config.yaml")
    print(design_yaml(int(sys.argv[1]), int(sys.argv[2]), config.granulator.bed_solid_volume))
