"""How long DEM runs will take: a run's particle-steps divided by the engine's measured throughput.

The throughput (particle-steps per second of LIGGGHTS on one MPI rank) is read from the finished
runs of a study (`results/dem/runs.csv`, columns `n_particles` and `particle_steps_per_s`) and
interpolated in the particle number, which sets it (small runs spend more of each step outside the
contact loop). Without finished runs the reference measurement below stands in for it; the
estimate says which of the two it used.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem import layout

from .plan import plan_point

# Reference throughput (particles, particle-steps/s on one rank, two runs at once on 2 cores),
# measured on the project's 2-core reference machine with the default grid (runs.csv of a default
# run; benchmarks/bench_dem.py measures one point). A machine's own runs.csv replaces it.
REFERENCE_THROUGHPUT = ((273, 1.4e6), (2342, 3.0e6))
REFERENCE_SOURCE = "the reference machine's throughput (1.4-3.0 M particle-steps/s, no runs.csv yet)"


@dataclass(frozen=True)
class Throughput:
    """Particle-steps per second against particle number (log-linear between measured points)."""

    points: tuple[tuple[float, float], ...]
    source: str

    def rate(self, n_particles: float) -> float:
        n, rate = zip(*sorted(self.points))
        return float(np.interp(np.log(n_particles), np.log(n), rate))

    def seconds(self, particle_steps: float, n_particles: float, ranks: int = 1) -> float:
        """Wall time of a run of `particle_steps` (no speed-up assumed beyond the ranks)."""
        return particle_steps / self.rate(n_particles) / max(1, ranks)


def measured_throughput(runs_csv: str | Path | None = None) -> Throughput:
    """The throughput of the finished runs in `runs_csv` (median per particle number), or the
    reference if the file is missing or holds no usable rows."""
    try:
        runs = pd.read_csv(runs_csv, usecols=["n_particles", "particle_steps_per_s"]).dropna()
    except (OSError, ValueError):  # no such file (or None), or not a run table
        return Throughput(REFERENCE_THROUGHPUT, REFERENCE_SOURCE)
    runs = runs[runs["particle_steps_per_s"] > 0]
    med = runs.groupby("n_particles")["particle_steps_per_s"].median()
    if not len(med):
        return Throughput(REFERENCE_THROUGHPUT, REFERENCE_SOURCE)
    source = f"the throughput of the {len(runs)} finished runs in {runs_csv}"
    return Throughput(tuple((float(n), float(r)) for n, r in med.items()), source)


def duration_text(seconds: float) -> str:
    """A wall time in words: '45 s', '12 min', '3.4 h'."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 90 * 60:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


@dataclass(frozen=True)
class StudyEstimate:
    """The DEM work a study has left: grid runs and coupled-loop intervals, and their wall time."""

    grid_runs: int
    grid_seconds: float
    loop_intervals: int
    loop_seconds: float
    ranks: int
    source: str
    #: coupling intervals that borrow the grid's run of their feed instead of running LIGGGHTS
    borrowed_intervals: int = 0

    def text(self, cores: int = 2) -> str:
        total = self.grid_seconds + self.loop_seconds
        if not self.grid_runs and not self.loop_intervals:
            return "pbmdem runtime estimate: no DEM run left to do."
        parallel = max(1, cores // max(1, self.ranks))
        return (
            f"pbmdem runtime estimate: {self.grid_runs} DEM grid run(s), {duration_text(self.grid_seconds)}, and "
            f"{self.loop_intervals} PBM-DEM coupling interval(s), {duration_text(self.loop_seconds)} (an upper "
            f"bound: granules grow, so later intervals hold fewer particles; {self.borrowed_intervals} borrow the "
            f"grid's run of their feed); {duration_text(total)} of LIGGGHTS "
            f"on {self.ranks} rank(s) per run, about {duration_text(total / parallel)} with {parallel} run(s) at "
            f"once on {cores} cores; from {self.source}. The PBM, surrogate and report add minutes."
        )


def study_estimate(cfg, grid_runs, loops, results: str | Path = layout.RESULTS) -> StudyEstimate:
    """The wall time of the DEM runs of a workflow run on `cfg`: `grid_runs`, (rpm, distribution,
    replicate) of the grid's jobs (from settled beds), and `loops`, (rpm, replicate[, CoupledLoop:
    another loop than the validation's]) of the coupled loops, one run per coupling interval but
    the first, which borrows the grid's run or bed of the feed (docs/validation.md, "Borrowed grid
    runs"); the throughput from the finished runs in `results`."""
    throughput = measured_throughput(layout.dem("runs.csv", str(results)))
    ranks = cfg.dem_execution.mpi_ranks
    grid_seconds = 0.0
    beds = set()
    for rpm, dist, rep in grid_runs:
        plan = plan_point(cfg.dem_point(dist), float(rpm), replicate=int(rep))
        # a grid run starts from its settled bed, which is settled once for all speeds
        grid_seconds += throughput.seconds(float(plan.n_particles) * plan.run_steps, plan.n_particles, ranks)
        if (dist, int(rep)) not in beds:
            beds.add((dist, int(rep)))
            grid_seconds += throughput.seconds(float(plan.n_particles) * plan.settle_steps, plan.n_particles, ranks)
    validation_loop = cfg.coupled_loop()
    feed, points = validation_loop.batch.distribution, cfg.grid.points()
    loop_seconds, intervals, borrowed = 0.0, 0, 0
    for rpm, rep, *other in loops:
        loop = other[0] if other else validation_loop
        plan = plan_point(loop.dem_point(), float(rpm), replicate=int(rep))
        one = throughput.seconds(plan.particle_steps, plan.n_particles, ranks)
        loop_seconds += loop.coupling_intervals * one
        intervals += loop.coupling_intervals
        if other or int(rep) >= cfg.point_replicates(feed) or all(d != feed for _, d in points):
            continue
        if (float(rpm), feed) in points:  # the first interval borrows the grid's run
            loop_seconds -= one
            borrowed += 1
        else:  # the first interval starts from the grid's settled bed
            loop_seconds -= throughput.seconds(float(plan.n_particles) * plan.settle_steps, plan.n_particles, ranks)
    return StudyEstimate(len(grid_runs), grid_seconds, intervals, loop_seconds, ranks, throughput.source, borrowed)
