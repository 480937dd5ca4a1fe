"""Collision frequencies of a coupling interval's representative sample: from LIGGGHTS (PBM-DEM)
or from the trained surrogate (PBM-ANN). A provider is called as `provider(sample, interval_dir,
index) -> (rates, info)` (rates: a matrix, `EncounterRates` or `ImpactRates`; info: the
interval's recorded figures); `fingerprint()` names what its rates depend on, so that finished
intervals of a changed provider are not reused.

The DEM stage and the surrogate are imported with the module (imports at the top): a PBM-DEM job
loads scikit-learn too (about 1.4 s of its start, measured 2026-12-05), a PBM-ANN job the DEM stage.
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from pathlib import Path

import numpy as np

from pbmdem.config import ConfigError, CoupledLoop, DemExecution
from pbmdem.dem import plan_point, run_point
from pbmdem.dem.deck import DeckValueError, known_name
from pbmdem.dem.plan import class_counts
from pbmdem.dem.run import BED_RECORD, check_bed, is_finished
from pbmdem.frequency import matrix_from_table, velocity_fractions_from_table, wall_rates_from_tables
from pbmdem.impact import EncounterRates, ImpactRates
from pbmdem.readers import InputFileError, read_json
from pbmdem.surrogate import load_surrogate
from pbmdem.surrogate.domain import out_of_domain_recorded
from pbmdem.tables import RUN_PAIRS, RUN_VELOCITIES, RUN_WALL_VELOCITIES, RUN_WALLS

from .sample import DIAMETER_RESOLUTION, DemSample

log = logging.getLogger(__name__)

#: plan keys that name a run rather than define it (an interval's DEM bed is named after it)
_NAME_KEYS = ("distribution", "point_id")


def dem_rates(run_dir: Path, k: int) -> ImpactRates:
    """The impacts of the K classes of one DEM run of a coupling interval, from the run's tables in
    `run_dir` (collisions.csv, impact_velocity.csv, wall_collisions.csv, wall_impact_velocity.csv):
    what PBM-DEM hands to the PBM (benchmarks/bench_replay.py reads the stored intervals with it)."""
    table = RUN_PAIRS.read(run_dir / "collisions.csv", "collision table of a coupling interval")
    velocities = RUN_VELOCITIES.read(run_dir / "impact_velocity.csv", "impact-velocity table of a coupling interval")
    walls = RUN_WALLS.read(run_dir / "wall_collisions.csv", "wall-collision table of a coupling interval")
    wall_velocities = RUN_WALL_VELOCITIES.read(
        run_dir / "wall_impact_velocity.csv", "wall impact-velocity table of a coupling interval"
    )
    return ImpactRates(
        EncounterRates(matrix_from_table(table, k), velocity_fractions_from_table(velocities, k)),
        wall_rates_from_tables(walls, wall_velocities, k),
    )


class DemProvider:
    """Class encounter frequencies from a LIGGGHTS run of the representative sample.

    An interval whose sample is an earlier interval's is not run again (`dem_reused_from_interval`);
    an interval of the loop's feed is planned as the DEM grid's run of the feed, borrows `grid_run`
    when it covers the interval's plan (`covers`; `dem_borrowed_run`) and starts from the grid's
    settled bed `bed_dir` when it is its plan's (`dem_settled_bed`): docs/validation.md,
    "Representative sample" and "Borrowed grid runs"."""

    name = "pbm_dem"

    def __init__(
        self,
        loop: CoupledLoop,
        rpm: float,
        execution: DemExecution,
        replicate: int,
        grid_run: str | Path | None = None,
        bed_dir: str | Path | None = None,
    ):
        self.point = loop.dem_point()
        self.rpm = float(rpm)
        self.execution = execution
        self.replicate = int(replicate)
        self.grid_run = None if grid_run is None else Path(grid_run)
        self.bed_dir = None if bed_dir is None else Path(bed_dir)

    def fingerprint(self) -> dict:
        return {
            "name": self.name,
            "dem": self.point.dem.to_dict(),
            "rpm": self.rpm,
            "replicate": self.replicate,
            # the feed's sample planned with the feed's fractions (2026-12-05): earlier intervals are stale
            "feed_plan": "feed fractions",
            "grid_run": _digest(self.grid_run, ("plan.json", "summary.json", "collisions.csv")),
            "settled_bed": _digest(self.bed_dir, (BED_RECORD,)),
        }

    def _point_of(self, sample: DemSample, index: int):
        """The DEM point of `sample`: the loop's feed itself if the sample is the feed and the feed
        has a deck name (a grid feed; a blend's "fine+medium" is none), else the sample named
        after its interval."""
        feed = self.point.sizes
        rounded = [round(d / DIAMETER_RESOLUTION) * DIAMETER_RESOLUTION for d in feed.diameters]
        if list(sample.diameters) == rounded and class_counts(sample.n_particles, feed.number_fractions) == list(
            sample.counts
        ):
            try:
                known_name("distribution", self.point.distribution)
                return self.point
            except DeckValueError:
                pass
        return self.point.replace(distribution=f"interval{index:02d}", sizes=sample.sizes())

    def __call__(self, sample: DemSample, interval_dir: Path, index: int):
        plan = plan_point(self._point_of(sample, index), self.rpm, replicate=self.replicate, counts=sample.counts)
        earlier = self._identical_earlier_run(plan, interval_dir, index)
        if earlier is not None:
            reused_from, run_dir = earlier
            summary = read_json(run_dir / "summary.json", "DEM run summary of a coupling interval")
            info = {"dem_wall_time_s": 0.0, "dem_cpu_time_s": 0.0, "dem_reused_from_interval": reused_from}
        elif self._borrowable(plan, index):
            run_dir = self.grid_run
            summary = read_json(run_dir / "summary.json", "DEM run summary of a grid run")
            wall = _run_wall(summary)
            info = {
                "dem_wall_time_s": wall,
                "dem_cpu_time_s": _run_cpu(summary),
                "dem_borrowed_run": str(run_dir),
                "dem_borrowed_wall_time_s": wall,
            }
        else:
            run_dir = interval_dir / "dem"
            bed = self._bed_for(plan, index)
            # an interval without interval.json is unfinished, whatever its DEM folder holds
            summary = run_point(plan, run_dir, self.execution, force=True, bed_dir=bed)
            info = {
                "dem_wall_time_s": _run_wall(summary),
                "dem_cpu_time_s": _run_cpu(summary),
            }
            if bed is not None:
                info |= {"dem_settled_bed": str(bed), "dem_borrowed_wall_time_s": summary["bed_liggghts_wall_time_s"]}
        rates = dem_rates(run_dir, len(sample.diameters))
        return rates, {
            **info,
            "dem_particles": summary["n_particles"],
            "dem_collisions": summary["total_collisions"],
            "dem_encounters": summary["total_encounters"],
        }

    def _borrowable(self, plan, index: int) -> bool:
        """Whether the grid run (if any) covers `plan` (the reason it does not is logged)."""
        if self.grid_run is None or plan.distribution != self.point.distribution:
            return False
        why = covers(self.grid_run, plan)
        if why:
            log.info("PBM-DEM at rpm %g, interval %d: runs its own DEM run: %s", self.rpm, index, why)
        return not why

    def _bed_for(self, plan, index: int) -> Path | None:
        """The grid's settled bed if it is the bed `plan` would settle, else None (the reason logged)."""
        if self.bed_dir is None or plan.distribution != self.point.distribution:
            return None
        try:
            check_bed(plan, self.bed_dir)
        except (ConfigError, InputFileError) as exc:
            log.info("PBM-DEM at rpm %g, interval %d: settles its own bed: %s", self.rpm, index, exc)
            return None
        return self.bed_dir

    def _identical_earlier_run(self, plan, interval_dir: Path, index: int) -> tuple[int, Path] | None:
        """(interval, run folder) of an earlier interval of this loop whose finished DEM run had
        this very plan on as many ranks, or that borrowed a grid run covering it, else None."""
        wanted = {k: v for k, v in plan.to_dict().items() if k not in _NAME_KEYS}
        wanted = json.loads(json.dumps(wanted | {"mpi_ranks": self.execution.mpi_ranks}))  # as stored
        for j in range(index):
            folder = interval_dir.parent / f"interval_{j:02d}"
            if (folder / "interval.json").exists():
                borrowed = read_json(folder / "interval.json", "coupling interval record").get("dem_borrowed_run")
                if borrowed and not covers(Path(borrowed), plan):
                    return j, Path(borrowed)
            run_dir = folder / "dem"
            if not (is_finished(run_dir) and (run_dir / "summary.json").exists() and (run_dir / "plan.json").exists()):
                continue
            done = read_json(run_dir / "plan.json", "DEM plan of a coupling interval")
            if {k: v for k, v in done.items() if k not in (*_NAME_KEYS, "settled_bed")} == wanted:
                return j, run_dir
        return None


def interval_run_dir(rep_dir: str | Path, info: dict) -> Path:
    """The DEM run whose tables interval `info` (its interval.json) of the stored loop in `rep_dir`
    used: its own (`interval_NN/dem`), the grid run it borrowed (`dem_borrowed_run`, a path relative
    to the workflow's folder: found from the working directory or a folder above the loop), or
    that of the earlier interval it reused."""
    rep_dir = Path(rep_dir)
    reused = info.get("dem_reused_from_interval")
    if reused is not None and reused == reused:  # not NaN
        earlier = rep_dir / f"interval_{int(reused):02d}"
        return interval_run_dir(rep_dir, read_json(earlier / "interval.json", "coupling interval record"))
    borrowed = info.get("dem_borrowed_run")
    if borrowed:
        for base in (Path.cwd(), *rep_dir.resolve().parents):
            if (base / borrowed / "summary.json").exists():
                return base / borrowed
        raise InputFileError(f"{rep_dir}: interval {info.get('interval')} borrowed {borrowed}, which is not found")
    return rep_dir / f"interval_{int(info['interval']):02d}" / "dem"


def _run_wall(summary: dict) -> float:
    """A DEM run's wall time as an interval counts it: LIGGGHTS, the settled bed's (if it started
    from one) and the parsing of its contacts."""
    return summary["liggghts_wall_time_s"] + summary.get("bed_liggghts_wall_time_s", 0.0) + summary["parse_time_s"]


def _run_cpu(summary: dict) -> float:
    """A DEM run's CPU time as an interval counts it: the LIGGGHTS processes' CPU seconds of the run
    and, if it settled its own bed, the bed's."""
    return summary["liggghts_cpu_time_s"] + summary.get("bed_liggghts_cpu_time_s", 0.0)


def _digest(folder: Path | None, names) -> str | None:
    """SHA-256 of the files `names` in `folder` (None: no folder, or a file missing)."""
    if folder is None or not all((folder / n).exists() for n in names):
        return None
    h = hashlib.sha256()
    for n in names:
        h.update((folder / n).read_bytes())
    return h.hexdigest()


def covers(run_dir: Path, plan) -> str:
    """Why the finished DEM run in `run_dir` does not cover `plan` (empty: it does). It covers it
    when its plan (plan.json) is `plan` in every recorded value (particles, time step, settling,
    seeds, spin-up, contact and position intervals, speed) but the names, the settled bed it
    started from and the MPI ranks, and its sampling window opens at the same step and is at least
    as long: its tables are then the same rates as `plan`'s, over a longer window."""
    run_dir = Path(run_dir)
    if not (is_finished(run_dir) and (run_dir / "plan.json").exists() and (run_dir / "summary.json").exists()):
        return f"{run_dir} holds no finished run"
    done = read_json(run_dir / "plan.json", "DEM plan of a grid run")
    wanted = json.loads(json.dumps(plan.to_dict()))  # as stored
    window = ("sampling_steps", "sampling_time")
    for key, value in wanted.items():
        if key in (*_NAME_KEYS, *window):
            continue
        if done.get(key) != value:
            return f"{run_dir}/plan.json: {key} = {done.get(key)!r}, the interval's plan has {value!r}"
    if done.get("sampling_steps", -1) < wanted["sampling_steps"]:
        return (
            f"{run_dir}/plan.json: sampling_steps = {done.get('sampling_steps')!r}, shorter than the "
            f"interval's {wanted['sampling_steps']}"
        )
    return ""


def surrogate_needs(pbm) -> tuple[bool, bool]:
    """(impact velocities, wall impacts): what the PBM of the ``pbm`` settings reads from a
    frequency source besides the pair encounter frequencies. Velocities: a velocity-dependent
    success (the Stokes criterion) or breakage by granule-granule impacts; walls: breakage by
    wall impacts."""
    breakage = pbm.breakage
    walls = bool(breakage.enabled and breakage.walls)
    velocities = pbm.aggregation.success.velocity_model != "none" or bool(breakage.enabled and breakage.pairs)
    return velocities, walls


class SurrogateProvider:
    """Class encounter frequencies from the trained surrogate (one vectorised call per interval):
    its ensemble mean, or ensemble member `member` alone.

    `model` is the path of a saved surrogate or a loaded one (the many in-memory batches of the
    design space and the calibration load it once). `log_each=False` leaves the logging of each
    out-of-domain warning to the caller, which records and reports their count (never drops it).
    `needs` = (impact velocities, wall impacts), :func:`surrogate_needs` of the PBM's settings:
    only what the PBM reads is predicted (None: everything the surrogate can predict). A sample
    equal to the one of an earlier interval (typically the feed, until the binder lets granules
    grow) is not predicted again: its rates and out-of-domain warnings are those of that interval.
    """

    name = "pbm_ann"

    def __init__(self, model, rpm: float, member: int | None = None, log_each: bool = True, needs=None):
        if isinstance(model, (str, Path)):
            self.model_path = Path(model)
            model = load_surrogate(model)
        else:
            self.model_path = None
        self.model = model if member is None else model.member(member)
        self.member = member
        self.rpm = float(rpm)
        self.log_each = log_each
        velocities, walls = (True, True) if needs is None else needs
        # with a velocity model the provider also hands over impact-velocity fractions (one call),
        # with wall models also the wall impacts (breakage): when the PBM reads them
        has_velocity = bool(self.model.has_velocity_model())
        self.walls = has_velocity and walls and bool(getattr(self.model, "wall_models_", None))
        self.velocity_resolved = has_velocity and (velocities or self.walls)
        self._last: tuple[bytes, object, list[str]] | None = None

    def fingerprint(self) -> dict:
        if self.model_path is None:
            raise ValueError("a surrogate provider of a loaded model has no fingerprint: give the model's path")
        return {
            "name": self.name,
            "rpm": self.rpm,
            "member": self.member,
            "model_sha256": hashlib.sha256(self.model_path.read_bytes()).hexdigest(),
        }

    def __call__(self, sample: DemSample, interval_dir: Path | None, index: int):
        t0 = time.perf_counter()
        d, n = np.asarray(sample.diameters, float), np.asarray(sample.counts, float)
        key = d.tobytes() + n.tobytes()
        if self._last is not None and self._last[0] == key:
            _, rates, found = self._last  # the sample of the interval before: the same prediction
        else:
            where = f"{self.name} at rpm {self.rpm:g}, interval {index}"
            with out_of_domain_recorded(where, log_each=self.log_each) as found:
                if self.walls:
                    rates = self.model.impacts(d, n, self.rpm)
                elif self.velocity_resolved:
                    rates = self.model.encounters(d, n, self.rpm)
                else:
                    rates = np.asarray(self.model.frequency_matrix(d, n, self.rpm), float)
            self._last = (key, rates, list(found))
        return rates, {
            "ann_wall_time_s": time.perf_counter() - t0,
            "out_of_domain": "; ".join(sorted(set(found))),
            "out_of_domain_count": len(found),
        }
