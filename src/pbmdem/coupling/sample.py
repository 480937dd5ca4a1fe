"""The representative DEM sample of a PBM size distribution: the aggregates at the pivots and the
feed granules at their own sizes, merged into at most `max_classes` classes of at least
`min_particles_per_class` particles (number and solid volume conserved), diameters rounded to
whole nanometres (`DIAMETER_RESOLUTION`: a round-off change of a diameter would change the chaotic
DEM's counts), scaled down above `dem.max_particles` (docs/validation.md, "Representative sample")."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from pbmdem.config import SampleRule, SizeDistribution

#: class diameters handed to LIGGGHTS are rounded to this (m); see the module docstring, rule 2
DIAMETER_RESOLUTION = 1e-9


@dataclass
class DemSample:
    diameters: list[float]
    counts: list[int]
    bins: list[list[int]]  # the PBM's particle classes merged into each DEM class
    scaled_down: float = 1.0  # < 1 when the sample was capped at max_particles

    @property
    def n_particles(self) -> int:
        return int(sum(self.counts))

    @property
    def number_fractions(self) -> list[float]:
        n = np.asarray(self.counts, float)
        return (n / n.sum()).tolist()

    def sizes(self) -> SizeDistribution:
        return SizeDistribution(diameters=tuple(self.diameters), number_fractions=tuple(self.number_fractions))


def representative_sample(volumes, numbers, rule: SampleRule) -> DemSample:
    """DEM classes for a PBM distribution: its particle classes' solid `volumes` (ascending; the
    pivots' aggregates and the feed granules, `GranulationPBM.particle_classes`) and `numbers`."""
    x = np.asarray(volumes, float)
    n = np.asarray(numbers, float)
    if x.shape != n.shape or x.ndim != 1:
        raise ValueError(f"volumes {x.shape} and numbers {n.shape} must be 1-D of the same length")
    max_classes, min_per_class = rule.max_classes, rule.min_particles_per_class
    if max_classes < 1 or min_per_class < 1:
        raise ValueError(
            f"max_classes = {max_classes}, min_particles_per_class = {min_per_class}: both must be at least 1"
        )
    total = n.sum()
    if not total >= min_per_class:
        raise ValueError(
            f"the PBM holds {total:.3g} particles, fewer than min_particles_per_class = "
            f"{min_per_class}: no representative DEM bed can be formed"
        )
    groups: list[list[int]] = []
    current: list[int] = []
    acc = 0.0
    values = n.tolist()  # Python floats: the same sums, without a numpy scalar per class
    for k in np.flatnonzero(n > 0).tolist():
        current.append(k)
        acc += values[k]
        if acc >= min_per_class:
            groups.append(current)
            current, acc = [], 0.0
    if current:
        if groups:
            groups[-1].extend(current)
        else:
            groups.append(current)

    def count(g) -> float:
        return float(n[g].sum())

    sums = [count(g) for g in groups]  # each group's number, summed again only when it grows
    while len(groups) > max_classes:
        neighbours = [a + b for a, b in zip(sums, sums[1:])]
        j = int(np.argmin(neighbours))
        groups[j : j + 2] = [groups[j] + groups[j + 1]]
        sums[j : j + 2] = [count(groups[j])]
    diam = [
        round(float((6.0 / math.pi * float((ng * xg).sum() / ng.sum())) ** (1.0 / 3.0)) / DIAMETER_RESOLUTION)
        * DIAMETER_RESOLUTION
        for ng, xg in ((n[g], x[g]) for g in map(np.asarray, groups))
    ]
    counts = np.array(sums)
    scale = 1.0
    if counts.sum() > rule.max_particles:
        scale = rule.max_particles / counts.sum()
        warnings.warn(
            f"representative DEM sample of {counts.sum():.0f} particles capped at dem.max_particles = "
            f"{rule.max_particles}: the DEM bed is scaled down by {scale:.3f}",
            stacklevel=2,
        )
    rounded = np.maximum(1, np.round(counts * scale)).astype(int)
    return DemSample(diameters=diam, counts=rounded.tolist(), bins=groups, scaled_down=scale)
