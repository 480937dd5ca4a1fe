"""Operating points: the grid of impeller speeds x size distributions, and their ids; the feed
study's cases (the grid's feeds and the 50:50 blends between neighbours) by name."""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from pydantic import Field

from .typed import Name, Rpm, Settings, Unique, setting


def rpm_text(rpm: float) -> str:
    """The impeller speed as it appears in ids and paths: the shortest decimal that reads back as
    the same float, never in exponent form (so the rules' rpm wildcard `[0-9]+(\\.[0-9]+)?`
    accepts every speed the schema allows, and two different speeds never share an id)."""
    return np.format_float_positional(float(rpm), trim="-")


def point_id(rpm: float, distribution: str) -> str:
    """Id of an operating point, e.g. rpm300_fine."""
    return f"rpm{rpm_text(rpm)}_{distribution}"


class SizeDistribution(Settings):
    """A discrete size distribution: class diameters (m, ascending) and number fractions (sum 1)."""

    diameters: tuple[Annotated[float, Field(ge=1.0e-5, le=0.1)], ...] = setting(
        ..., "class diameters, ascending", "m", min_length=1, max_length=20
    )
    number_fractions: tuple[Annotated[float, Field(ge=0, le=1)], ...] = setting(
        ..., "number fraction of each class (sum 1)", min_length=1, max_length=20
    )

    @property
    def mean_particle_volume(self) -> float:
        """Number-weighted mean particle volume sum_k f_k pi d_k^3 / 6 (m3)."""
        return math.fsum(f * math.pi / 6.0 * d**3 for d, f in zip(self.diameters, self.number_fractions))

    @property
    def mass_median(self) -> float:
        """The mass-median diameter (m): the class where the cumulative mass passes 50 %,
        interpolated in ln d between class diameters."""
        d = np.asarray(self.diameters, float)
        mass = np.asarray(self.number_fractions, float) * d**3
        cum = np.cumsum(mass) / mass.sum()
        k = int(np.searchsorted(cum, 0.5))
        if k == 0:
            return float(d[0])
        lo, hi = cum[k - 1], cum[k]
        w = (0.5 - lo) / (hi - lo) if hi > lo else 0.0
        return float(math.exp(math.log(d[k - 1]) + w * (math.log(d[k]) - math.log(d[k - 1]))))


#: the name of the 50:50 blend of two neighbouring feeds of the feed study: "<finer>+<coarser>"
#: (a distribution's name cannot hold "+", so a blend's name is never a feed's)
BLEND_JOIN = "+"


def feed_case_names(distributions: dict[str, SizeDistribution]) -> list[tuple[str, bool]]:
    """The feed study's cases, (name, a feed of the DEM grid): the feeds ordered by mass-median
    diameter, with the 50:50 blend of each pair of neighbours between them ("fine+medium")."""
    named = sorted(distributions, key=lambda name: distributions[name].mass_median)
    cases: list[tuple[str, bool]] = []
    for k, name in enumerate(named):
        if k:
            cases.append((f"{named[k - 1]}{BLEND_JOIN}{name}", False))
        cases.append((name, True))
    return cases


def feed_case_parents(cases) -> dict[str, tuple[str, str]]:
    """The parents of the feed study's cases (`cases`: (name, a feed of the DEM grid) in the
    feed study's order, :func:`feed_case_names`): the nearest grid feeds before and after a case,
    i.e. the two feeds of a blend, and a feed's finer and coarser neighbours. The cases at either
    end have one neighbour only and are left out."""
    cases = list(cases)
    grid = [k for k, (_, in_grid) in enumerate(cases) if in_grid]
    out = {}
    for k, (name, _) in enumerate(cases):
        before = [j for j in grid if j < k]
        after = [j for j in grid if j > k]
        if before and after:
            out[name] = (cases[before[-1]][0], cases[after[0]][0])
    return out


class ExtraPoint(Settings):
    """One operating point beyond the full grid: a size distribution at one impeller speed."""

    rpm: Rpm = setting(..., "impeller speed", "rpm")
    distribution: Name = setting(..., "a name from size_distributions")


class OperatingGrid(Settings):
    """The DEM grid: every impeller speed (rpm) with every named size distribution, single extra
    points (the active learning's proposals) and the points of a space-filling design (each a
    distribution at one speed, tests/design_points.py)."""

    impeller_rpm: Unique[Rpm] = setting(..., "impeller speeds of the full grid", "rpm", min_length=1)
    size_distributions: Unique[Name] = setting(..., "size distributions of the full grid", min_length=1)
    extra_points: Unique[ExtraPoint] = setting(
        (), "single operating points beyond the full grid (the active learning's proposals, docs/validation.md)"
    )
    max_points: int = setting(
        1000,
        "most operating points the grid may hold; a larger grid is refused before Snakemake builds its DAG "
        "(~80x the default grid's 12 points; 1000 points x 3 replicates of a minute each is two days of DEM)",
        ge=1,
    )
    design_points: Unique[ExtraPoint] = setting(
        (), "points of a space-filling design over the surrogate's features (tests/design_points.py, docs/dem.md)"
    )
    design_replicates: int | None = setting(None, "DEM runs per design point (null: dem.replicates)", ge=1, le=1000)

    def count(self) -> int:
        """Number of operating points of the full grid plus the extra and design points (an upper
        bound of len(points()), computed without listing them)."""
        return len(self.impeller_rpm) * len(self.size_distributions) + len(self.extra_points) + len(self.design_points)

    def points(self) -> list[tuple[float, str]]:
        """Every operating point (rpm, distribution): the full grid, then the extra points and the
        design points not in it."""
        full = [(rpm, dist) for rpm in self.impeller_rpm for dist in self.size_distributions]
        single = [(p.rpm, p.distribution) for p in (*self.extra_points, *self.design_points)]
        return full + [p for k, p in enumerate(single) if p not in full and p not in single[:k]]

    def speeds(self) -> list[float]:
        """Every impeller speed that some operating point runs at, ascending."""
        return sorted({rpm for rpm, _ in self.points()})

    def middle_speed(self) -> float:
        """The middle impeller speed of the grid's speeds (`impeller_rpm`; of two middle ones the
        lower): the feed study's speed, one the surrogate was trained at."""
        speeds = sorted(self.impeller_rpm)
        return float(speeds[(len(speeds) - 1) // 2])

    def replicates(self, distribution: str, default: int) -> int:
        """DEM runs per operating point of `distribution`: `design_replicates` for a design point's
        distribution (unless it is also named or an extra point's), else `default` (dem.replicates)."""
        own = set(self.size_distributions) | {p.distribution for p in self.extra_points}
        design = {p.distribution for p in self.design_points}
        if distribution in design and distribution not in own and self.design_replicates:
            return int(self.design_replicates)
        return int(default)

    def distributions(self) -> list[str]:
        """The size distributions of the grid, of the extra points and of the design points, each once."""
        names = list(self.size_distributions)
        single = {p.distribution for p in (*self.extra_points, *self.design_points)}
        return names + sorted(single - set(names))
