"""Operating points: the grid of impeller speeds x size distributions, and their ids."""

from __future__ import annotations

import math
from dataclasses import dataclass

from .typed import Settings


def rpm_text(rpm: float) -> str:
    """The impeller speed as it appears in ids and paths: the shortest decimal that reads back as
    the same float, never in exponent form (so the rules' rpm wildcard `[0-9]+(\\.[0-9]+)?`
    accepts every speed the schema allows, and two different speeds never share an id)."""
    import numpy as np

    return np.format_float_positional(float(rpm), trim="-")


def point_id(rpm: float, distribution: str) -> str:
    """Id of an operating point, e.g. rpm300_fine."""
    return f"rpm{rpm_text(rpm)}_{distribution}"


@dataclass(frozen=True)
class SizeDistribution(Settings):
    """A discrete size distribution: class diameters (m, ascending) and number fractions (sum 1)."""

    diameters: tuple[float, ...]
    number_fractions: tuple[float, ...]

    @property
    def mean_particle_volume(self) -> float:
        """Number-weighted mean particle volume sum_k f_k pi d_k^3 / 6 (m3)."""
        return math.fsum(f * math.pi / 6.0 * d**3 for d, f in zip(self.diameters, self.number_fractions))


@dataclass(frozen=True)
class ExtraPoint(Settings):
    """One operating point beyond the full grid: a size distribution at one impeller speed."""

    rpm: float
    distribution: str


@dataclass(frozen=True)
class OperatingGrid(Settings):
    """The DEM grid: every impeller speed (rpm) with every named size distribution, single extra
    points (the active learning's proposals) and the points of a space-filling design (each a
    distribution at one speed, `pbmdem.dem.design`)."""

    impeller_rpm: tuple[float, ...]
    size_distributions: tuple[str, ...]
    extra_points: tuple[ExtraPoint, ...]
    max_points: int
    design_points: tuple[ExtraPoint, ...]
    design_replicates: int | None

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
