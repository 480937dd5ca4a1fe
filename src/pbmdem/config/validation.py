"""Settings of the validation study (the `validation:` section)."""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import StringConstraints

from .typed import Name, Rpm, Settings, Unique, setting


class Sweep(Settings):
    """PBM-ANN impeller-speed sweep: num speeds evenly from start to stop (rpm)."""

    start: Rpm | None = setting(None, "lowest speed of the PBM-ANN sweep; null: the grid's lowest", "rpm")
    stop: Rpm | None = setting(None, "highest speed of the sweep; null: the grid's highest", "rpm")
    num: int = setting(8, "speeds of the sweep", ge=2, le=1000)

    def speeds(self) -> list[float]:
        return [float(r) for r in np.linspace(self.start, self.stop, self.num)]


class SampleRule(Settings):
    """How a PBM size distribution becomes a representative DEM bed (docs/validation.md):
    neighbouring bins merged until a class holds `min_particles_per_class`, at most
    `max_classes` classes, at most `max_particles` particles (larger beds are scaled down)."""

    max_classes: int
    min_particles_per_class: int
    max_particles: int


class Proposals(Settings):
    """Active learning: how many operating points (new size distributions or speeds) to propose at most."""

    max_points: int = setting(
        2,
        "operating points proposed at most: samples outside the training domain first, then by ensemble spread",
        ge=0,
        le=100,
    )


class FeedCheck(Settings):
    """The PBM-DEM check of one case of the feed study (`feed`, None: no check) at `rpm`, with
    `replicates` PBM-DEM loops (docs/validation.md, "The feed check")."""

    feed: Annotated[str, StringConstraints(pattern=r"^[A-Za-z][A-Za-z0-9_+-]{0,129}$")] | None = setting(
        None,
        "a case of the feed study with a grid feed on either side (a blend a+b of neighbouring feeds, "
        "or a feed between two others); null: no feed check",
    )
    rpm: Rpm | None = setting(None, "speed of the check; null: the feed study's (the grid's middle speed)", "rpm")
    replicates: int = setting(
        3, "PBM-DEM loops of the check, differing only by their DEM insertion seeds", ge=1, le=100
    )


class Validation(Settings):
    """Speeds, feed, coupling intervals and DEM sampling window of the validation loops."""

    rpm: Unique[Rpm] = setting(
        ..., "impeller speeds of the comparison; include one that is not in grid.impeller_rpm", "rpm", min_length=1
    )
    distribution: Name = setting(..., "initial size distribution (a name from size_distributions)")
    coupling_intervals: int = setting(
        4, "equal intervals of the batch; the collision frequencies are refreshed at the start of each", ge=1, le=1000
    )
    dem_replicates: int = setting(
        3, "PBM-DEM loops per speed, differing only by their DEM insertion seeds (the reference band)", ge=1, le=100
    )
    dem_sampling_time: float = setting(0.1, "sampling window of each DEM call of the PBM-DEM loop", "s", gt=0, le=100)
    max_classes: int = setting(5, "size classes of the representative DEM sample of the PBM distribution", ge=1, le=20)
    min_particles_per_class: int = setting(
        50, "neighbouring PBM bins are merged until a class holds this many particles", ge=1, le=100000
    )
    sweep: Sweep = setting(Sweep, "the PBM-ANN impeller-speed sweep")
    proposals: Proposals = setting(Proposals, "active learning: the next operating points")
    feed_check: FeedCheck = setting(FeedCheck, "the PBM-DEM check of one case of the feed study")
