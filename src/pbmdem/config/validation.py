"""Settings of the validation study (the `validation:` section)."""

from __future__ import annotations

from dataclasses import dataclass

from .typed import Settings


@dataclass(frozen=True)
class Sweep(Settings):
    """PBM-ANN impeller-speed sweep: num speeds evenly from start to stop (rpm)."""

    start: float
    stop: float
    num: int

    def speeds(self) -> list[float]:
        import numpy as np

        return [float(r) for r in np.linspace(self.start, self.stop, self.num)]


@dataclass(frozen=True)
class SampleRule(Settings):
    """How a PBM size distribution becomes a representative DEM bed (docs/validation.md):
    neighbouring bins merged until a class holds `min_particles_per_class`, at most
    `max_classes` classes, at most `max_particles` particles (larger beds are scaled down)."""

    max_classes: int
    min_particles_per_class: int
    max_particles: int


@dataclass(frozen=True)
class Proposals(Settings):
    """Active learning: how many operating points (new size distributions or speeds) to propose at most."""

    max_points: int


@dataclass(frozen=True)
class FeedCheck(Settings):
    """The PBM-DEM check of one case of the feed study (`feed`, None: no check) at `rpm`, with
    `replicates` PBM-DEM loops (docs/validation.md, "The feed check")."""

    feed: str | None
    rpm: float
    replicates: int


@dataclass(frozen=True)
class Validation(Settings):
    """Speeds, feed, coupling intervals and DEM sampling window of the validation loops."""

    rpm: tuple[float, ...]
    distribution: str
    coupling_intervals: int
    dem_replicates: int
    dem_sampling_time: float
    max_classes: int
    min_particles_per_class: int
    sweep: Sweep
    proposals: Proposals
    feed_check: FeedCheck
