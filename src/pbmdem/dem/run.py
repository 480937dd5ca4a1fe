"""Run one DEM plan, or settle one bed, in a staging folder moved into place only when it
succeeded; this module decides nothing, the plan holds every decision (docs/dem.md, "A run" and
"One settled bed for every speed").
"""

from __future__ import annotations

import functools
import hashlib
import os
import shutil
import time
from pathlib import Path

from pbmdem.atomic import write_json, write_text
from pbmdem.config import ConfigError, DemExecution
from pbmdem.readers import InputFileError, read_json

from . import collisions, engine, geometry, viewer
from .deck import render_bed, render_granulator
from .plan import BedPlan, DemPlan
from .progress import ThermoProgress

#: the settled bed in a bed folder and in a run folder that starts from it
BED_FILE = "bed.restart"
#: what names a bed: the deck that settled it (1 rank) and its plan
BED_RECORD = "bed.json"


def bed_key(bed: BedPlan) -> dict:
    """What makes two beds the same: the plan and the deck that settles it (on one rank; the rank
    count changes the floating-point order, not what the bed is)."""
    deck = render_bed(bed, 1)
    return {"bed": bed.to_dict(), "deck_sha256": hashlib.sha256(deck.encode()).hexdigest()}


def check_bed(plan: DemPlan, bed_dir: str | Path) -> Path:
    """The restart file of the settled bed in `bed_dir`, after checking that `bed.json` names the
    bed `plan` would settle (ConfigError naming the file and the first value that differs)."""
    bed_dir = Path(bed_dir)
    record = bed_dir / BED_RECORD
    restart = bed_dir / BED_FILE
    if not restart.exists():
        raise InputFileError(f"settled bed {restart} does not exist (run the bed first: pbmdem.dem.run.settle_bed)")
    found, want = read_json(record, "settled-bed record"), bed_key(plan.bed)
    pairs = [(f"bed.{k}", found.get("bed", {}).get(k), need) for k, need in want["bed"].items()]
    for key, have, need in [*pairs, ("deck_sha256", found.get("deck_sha256"), want["deck_sha256"])]:
        if have != need:
            raise ConfigError(
                f"{record}: {key} = {have!r}, but the run {plan.point_id} (replicate {plan.replicate}) needs the "
                f"bed with {key} = {need!r}; settle its bed again"
            )
    return restart


def prepare_run(
    plan: DemPlan,
    run_dir: str | Path,
    ranks: int,
    bed: Path | None = None,
    deck: str | None = None,
) -> Path:
    """Write geometry, deck and plan into the fresh folder `run_dir`; with `bed` (a settled bed's
    restart file, as returned by `check_bed`), a copy of it for the deck to read; `deck`: the
    rendered deck, if the caller has it already."""
    run_dir = Path(run_dir)
    (run_dir / "post").mkdir(parents=True, exist_ok=True)
    geometry.write_granulator(plan.granulator, run_dir)
    if bed is not None:
        shutil.copyfile(bed, run_dir / BED_FILE)
    if deck is None:
        deck = render_granulator(plan, ranks, from_bed=bed is not None)
    write_text(run_dir / "in.granulator", deck)
    # a run from a settled bed names it; a fresh run's plan.json is its plan (coupled loops compare them)
    named = {"settled_bed": str(bed)} if bed is not None else {}
    write_json(run_dir / "plan.json", plan.to_dict() | {"mpi_ranks": ranks} | named)
    return run_dir / "in.granulator"


def settle_bed(bed: BedPlan, bed_dir: str | Path, execution: DemExecution) -> dict:
    """Insert and settle the bed `bed` in `bed_dir` and write it to `bed.restart`, then
    `bed.json` (the bed's plan, the deck's hash, the wall time), last, as the finished marker."""
    bed_dir = Path(bed_dir)
    key = bed_key(bed)  # raises on any bad value, before any I/O

    def settle(stage: Path) -> dict:
        geometry.write_granulator(bed.granulator, stage)
        write_text(stage / "in.bed", render_bed(bed, execution.mpi_ranks))
        result = engine.run("in.bed", stage, ranks=execution.mpi_ranks, timeout=execution.timeout)
        engine.check_finished(stage, bed.settle_steps, {})
        if not (stage / BED_FILE).exists():
            engine.record_crash(stage, [f"LIGGGHTS finished but wrote no {BED_FILE}"])
        record = key | {
            "liggghts_wall_time_s": result.wall_time,
            "liggghts_cpu_time_s": result.cpu_time,
            "particle_steps": float(bed.n_particles) * bed.settle_steps,
            "liggghts_version": engine.version_of_log(result.log),
        }
        write_json(stage / BED_RECORD, record)
        return record

    return _staged(bed_dir, (bed_dir / BED_RECORD).exists(), (BED_RECORD,), ("crash.json",), settle)


class FinishedRunError(ValueError):
    """The run folder holds a finished run; it is only replaced when asked to (force)."""


FINISHED_MARKERS = ("collisions.csv", "summary.json")


def is_finished(run_dir: str | Path) -> bool:
    """A run folder holds a finished run once its collision table or summary exists."""
    return any((Path(run_dir) / name).exists() for name in FINISHED_MARKERS)


#: moved into a run folder last, in this order: the tables, then the finished markers
LAST_PRODUCTS = tuple(dict.fromkeys((*collisions.TABLE_FILES, *FINISHED_MARKERS)))
# what a run writes into its folder (besides whatever LIGGGHTS itself adds)
RUN_PRODUCTS = (
    "bowl.stl",
    "impeller.stl",
    "in.granulator",
    "plan.json",
    "log.liggghts",
    "screen.liggghts",
    "crash.json",
    BED_FILE,
    "post",
    *LAST_PRODUCTS,
)


def _staged(folder: Path, finished: bool, last: tuple[str, ...], products: tuple[str, ...], work):
    """`work(stage)` in the staging folder `.<name>.staging` beside `folder`, then its output moved
    into `folder`: `last` (the finished markers) removed first and moved in last, `products` the
    new attempt lacks removed, anything else in `folder` left alone. A failed attempt is moved in
    too (crash.json and logs) unless `folder` holds a `finished` one, which stays untouched."""
    where = folder.resolve()
    stage = where.parent / f".{where.name}.staging"
    if stage.exists():
        shutil.rmtree(stage)
    (stage / "post").mkdir(parents=True)
    try:
        out = work(stage)
    except BaseException as exc:
        message = len(exc.args) == 1 and isinstance(exc.args[0], str)
        if not finished:  # nothing to protect: keep the crash and the logs in the folder
            _move_in(stage, folder, last, products)
            if message:
                exc.args = (exc.args[0].replace(str(stage), str(folder)),)
        elif message:
            exc.args = (f"{exc.args[0]}\n(the finished run in {folder} is untouched; this attempt is in {stage})",)
        raise
    _move_in(stage, folder, last, products)
    return out


def _move_in(stage: Path, folder: Path, last: tuple[str, ...], products: tuple[str, ...]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name in last:
        (folder / name).unlink(missing_ok=True)
    for name in products:
        if not (stage / name).exists() and (folder / name).exists():
            _remove(folder / name)
    moved_last = [stage / n for n in last if (stage / n).exists()]
    for item in [p for p in sorted(stage.iterdir()) if p not in moved_last] + moved_last:
        _remove(folder / item.name)
        os.replace(item, folder / item.name)
    stage.rmdir()


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)


def check_finished(plan: DemPlan, run_dir: str | Path) -> None:
    """Judge the run in `run_dir` against `plan`, not its exit code (`engine.check_finished`)."""
    engine.check_finished(run_dir, plan.total_steps, plan.dumps, plan.counts)


def run_point(
    plan: DemPlan,
    run_dir: str | Path,
    execution: DemExecution,
    *,
    force: bool = False,
    progress_bar: bool = False,
    bed_dir: str | Path | None = None,
) -> dict:
    """Run LIGGGHTS for `plan` in `run_dir` (from the bed `settle_bed` wrote in `bed_dir`, if
    given), tabulate its collisions and index its VTK files; the summary (also summary.json).
    A finished run is refused unless `force`, and never removed by a failure (LiggghtsError;
    docs/dem.md, "A run"). `execution`: MPI ranks and wall-time limit (s)."""
    run_dir = Path(run_dir)
    deck = render_granulator(plan, execution.mpi_ranks, from_bed=bed_dir is not None)
    bed = check_bed(plan, bed_dir) if bed_dir is not None else None
    finished = is_finished(run_dir)
    if finished and not force:
        markers = ", ".join(n for n in FINISHED_MARKERS if (run_dir / n).exists())
        raise FinishedRunError(
            f"{run_dir} already holds a finished run ({markers}); "
            "refusing to overwrite it (rerunning would give it new time stamps, so Snakemake would redo "
            "everything downstream). Use --force to replace it, or --out to write elsewhere."
        )
    work = functools.partial(_run_in, plan, run_dir, execution, deck, progress_bar, bed)
    return _staged(run_dir, finished, LAST_PRODUCTS, RUN_PRODUCTS, work)


def _run_in(
    plan: DemPlan,
    final_dir: Path,
    execution: DemExecution,
    deck: str,
    progress_bar: bool,
    bed: Path | None,
    run_dir: Path,
) -> dict:
    """run_point's work in the (staging) folder `run_dir`; paths in the summary name `final_dir`;
    `bed`: the checked settled bed's restart file, if the run starts from one."""
    deck_path = prepare_run(plan, run_dir, execution.mpi_ranks, bed, deck)
    phases = [("spin-up", plan.spinup_steps), ("sampling", plan.sampling_steps)]
    watcher = ThermoProgress(
        run_dir / "log.liggghts",
        phases if bed is not None else [("settling", plan.settle_steps), *phases],
        label=f"DEM {plan.point_id}",
        bar=progress_bar,
        first_step=plan.settle_steps if bed is not None else 0,
    )
    result = engine.run(deck_path, run_dir, ranks=execution.mpi_ranks, timeout=execution.timeout, progress=watcher)
    check_finished(plan, run_dir)
    (run_dir / BED_FILE).unlink(missing_ok=True)  # a copy; the bed stays in its folder
    t0 = time.perf_counter()
    tables = collisions.tabulate_run(run_dir / "post", plan)
    parse_time = time.perf_counter() - t0
    collisions.write_tables(tables, run_dir)
    series = viewer.write_series(run_dir / "post", plan.timestep)
    if not plan.keep_contact_dumps:
        for dump in plan.dumps:
            (run_dir / dump).unlink(missing_ok=True)
    thermo = engine.thermo_table(result.log)
    # fix check/timestep/gran: ts[1] = dt / Rayleigh time, ts[2] = dt / Hertz time (LIGGGHTS' own)
    checks = {
        "dt_over_rayleigh_time": max(thermo.get("ts[1]", [float("nan")])),
        "dt_over_hertz_time_max": max(thermo.get("ts[2]", [float("nan")])),
    }
    summary = {
        **checks,
        "point_id": plan.point_id,
        "rpm": plan.rpm,
        "distribution": plan.distribution,
        "n_particles": plan.n_particles,
        "timestep": plan.timestep,
        "steps": plan.total_steps,
        "mpi_ranks": execution.mpi_ranks,
        "liggghts_version": engine.version_of_log(result.log),
        **_cost(plan, result, bed),
        "parse_time_s": parse_time,
        "parse_cost_ratio": parse_time / result.wall_time,
        "collision_interval": plan.collision_interval,
        "replicate": plan.replicate,
        "seed": plan.seed,
        "total_collisions": int(tables.pairs["collisions"].sum()),
        "total_encounters": int(tables.pairs["encounters"].sum()),
        "sampling_time": float(tables.pairs["sampling_time"].iloc[0]),
        **tables.diagnostics,
        **{f"series_{k}": str(final_dir / "post" / Path(v).name) for k, v in series.items()},
    }
    write_json(run_dir / "summary.json", summary)
    return summary


def _cost(plan: DemPlan, result: engine.LiggghtsRun, bed: Path | None) -> dict:
    """What the run cost: its own steps (without the settling when it started from a settled bed),
    particle-steps, LIGGGHTS wall and CPU time, particle-steps per second, and the settled bed's
    own cost (shared by every speed that starts from it)."""
    steps = plan.run_steps if bed is not None else plan.total_steps
    particle_steps = float(plan.n_particles) * steps
    record = read_json(bed.with_name(BED_RECORD), "settled-bed record") if bed is not None else {}
    return {
        "run_steps": steps,
        "particle_steps": particle_steps,
        "liggghts_wall_time_s": result.wall_time,
        "liggghts_cpu_time_s": result.cpu_time,
        "particle_steps_per_s": particle_steps / result.wall_time,
        "particle_steps_per_cpu_s": particle_steps / max(result.cpu_time, 1e-9),
        "from_settled_bed": bed is not None,
        "bed_liggghts_wall_time_s": record.get("liggghts_wall_time_s", 0.0),
        "bed_liggghts_cpu_time_s": record.get("liggghts_cpu_time_s", 0.0),
    }
