"""One DEM operating point of the granulator: plan, render, run, tabulate.

`plan_point` turns the config and an operating point (impeller rpm, size-distribution name) into
a `DemPlan`: particle numbers per class, the time step (a fraction of the Rayleigh time of the
smallest particle), the number of steps of each phase and the contact-snapshot interval (a
fraction of the Hertz contact duration). `run_point` writes the geometry and deck into a run
folder, runs LIGGGHTS, parses the contact snapshots into collision tables and writes the VTK
series index. Tables are written atomically and only after LIGGGHTS succeeded.
"""

from __future__ import annotations

import math
import os
import shutil
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from pbmdem import deck, geometry, liggghts, progress
from pbmdem.atomic import write_json, write_text

# Hertz contact duration t_c = 2.87 (m*^2 / (R* E*^2 v))^(1/5) (Johnson 1985); snapshots are
# taken every t_c / SNAPSHOTS_PER_CONTACT so that a head-on contact between two of the smallest
# particles at the impeller tip speed is seen at least this many times (measured here: counts change
# by 0.4 % when this interval is halved, 1.9 % when doubled). Measured convergence is
# reported per run (counts with every snapshot vs every second one).
SNAPSHOTS_PER_CONTACT = 2
# Position snapshots (for encounter look-back and impact velocities) are taken every this many
# contact snapshots by default (dem.position_every): a gap of a quarter diameter takes far longer
# to open than that.
POSITION_SNAPSHOT_MULTIPLE = 4


def rpm_text(rpm: float) -> str:
    """The impeller speed as it appears in ids and paths: the shortest decimal that reads back as
    the same float, never in exponent form (so the rules' rpm wildcard `[0-9]+(\\.[0-9]+)?`
    accepts every speed the schema allows, and two different speeds never share an id)."""
    return np.format_float_positional(float(rpm), trim="-")


def point_id(rpm: float, distribution: str) -> str:
    return f"rpm{rpm_text(rpm)}_{distribution}"


def rayleigh_time(radius: float, density: float, youngs: float, poisson: float) -> float:
    """Rayleigh wave time of a sphere: pi R sqrt(rho/G) / (0.1631 nu + 0.8766)."""
    shear = youngs / (2.0 * (1.0 + poisson))
    return math.pi * radius * math.sqrt(density / shear) / (0.1631 * poisson + 0.8766)


def hertz_contact_time(radius: float, density: float, youngs: float, poisson: float, speed: float) -> float:
    """Duration of an elastic Hertz impact of two equal spheres at relative speed `speed`."""
    mass = density * 4.0 / 3.0 * math.pi * radius**3
    m_eff, r_eff = mass / 2.0, radius / 2.0
    e_eff = youngs / (2.0 * (1.0 - poisson**2))
    return 2.87 * (m_eff**2 / (r_eff * e_eff**2 * speed)) ** 0.2


def next_prime(n: int) -> int:
    """Smallest prime >= max(n, 10007) (LIGGGHTS wants prime seeds above 10000)."""
    n = max(int(n), 10007)
    while True:
        if n % 2 and all(n % k for k in range(3, int(n**0.5) + 1, 2)):
            return n
        n += 1


@dataclass
class DemPlan:
    point_id: str
    rpm: float
    distribution: str
    diameters: list[float]
    number_fractions: list[float]
    counts: list[int]
    n_particles: int
    timestep: float
    rayleigh_time: float
    contact_time: float
    collision_interval: int
    settle_steps: int
    spinup_steps: int
    sampling_steps: int
    vtk_every: int
    tip_speed: float
    history_steps: int = 0
    position_interval: int = 1
    encounter_gap_fraction: float = 0.25
    omega: float = 0.0
    replicate: int = 0
    mpi_ranks: int = 1
    seed: int = 20141
    extra: dict = field(default_factory=dict)

    @property
    def sampling_time(self) -> float:
        return self.sampling_steps * self.timestep

    @property
    def window_start_step(self) -> int:
        """Step at which the sampling window opens (end of the spin-up)."""
        return self.settle_steps + self.spinup_steps

    @property
    def particle_steps(self) -> float:
        return float(self.n_particles) * (self.settle_steps + self.spinup_steps + self.sampling_steps)


def class_counts(n_particles: int, fractions: list[float]) -> list[int]:
    """Expected numbers per class for `n_particles` (largest-remainder rounding)."""
    raw = np.asarray(fractions) * n_particles
    counts = np.floor(raw).astype(int)
    counts[np.argsort(-(raw - counts))[: n_particles - counts.sum()]] += 1
    return counts.tolist()


def bed_particle_count(cfg: dict, diameters, fractions) -> int:
    """Particles needed for the configured settled bed height (bed volume x packing / mean volume)."""
    bowl = geometry.bowl_from_config(cfg)
    d = np.asarray(diameters, float)
    mean_volume = float(np.dot(fractions, np.pi / 6.0 * d**3))
    solids = cfg["dem"]["bed_height"] * math.pi * bowl.radius**2 * cfg["dem"]["packing_fraction"]
    return int(round(solids / mean_volume))


REPLICATE_SEED_STRIDE = 7919  # replicate r runs with seeds derived from dem.seed + r x this prime


def phase_time(dem_cfg: dict, phase: str, rpm: float) -> float:
    """Length (s) of the spin-up or sampling phase: `<phase>_revolutions` impeller revolutions,
    but at least `<phase>_time` seconds."""
    revolutions = float(dem_cfg.get(f"{phase}_revolutions", 0.0))
    return max(float(dem_cfg[f"{phase}_time"]), revolutions * 60.0 / float(rpm))


def plan_point(cfg: dict, rpm: float, distribution: str, *, n_particles: int | None = None,
               diameters=None, number_fractions=None, replicate: int = 0) -> DemPlan:
    """Plan a run. `diameters`/`number_fractions`/`n_particles` override the named distribution
    (the coupled PBM-DEM loop hands its own size distribution this way); `replicate` selects the
    insertion seeds (replicates of one point differ only by them)."""
    dist = cfg["size_distributions"].get(distribution) if diameters is None else None
    if diameters is None:
        if dist is None:
            raise ValueError(f"size distribution {distribution!r} is not defined; defined: "
                             f"{sorted(cfg['size_distributions'])}")
        diameters, number_fractions = dist["diameters"], dist["number_fractions"]
    diameters = [float(x) for x in diameters]
    number_fractions = [float(x) for x in number_fractions]
    mat, dem_cfg = cfg["material"], cfg["dem"]
    if n_particles is None:
        n_particles = bed_particle_count(cfg, diameters, number_fractions)
    if n_particles > dem_cfg.get("max_particles", 20000):
        raise ValueError(f"operating point {point_id(rpm, distribution)} needs {n_particles} particles, "
                         f"more than dem.max_particles = {dem_cfg.get('max_particles', 20000)}")
    if n_particles < 2:
        raise ValueError(f"operating point {point_id(rpm, distribution)}: the bed holds {n_particles} "
                         "particles; raise dem.bed_height")
    counts = class_counts(n_particles, number_fractions)
    r_min = 0.5 * min(diameters)
    t_r = rayleigh_time(r_min, mat["density"], mat["youngs_modulus"], mat["poisson_ratio"])
    dt = dem_cfg["timestep_fraction"] * t_r
    imp = geometry.impeller_from_config(cfg)
    tip_speed = 2.0 * math.pi * imp.tip_radius * rpm / 60.0
    t_c = hertz_contact_time(r_min, mat["density"], mat["youngs_modulus"], mat["poisson_ratio"],
                             max(tip_speed, 0.1))
    interval = dem_cfg.get("collision_interval", "auto")
    if interval == "auto":
        interval = max(1, int(t_c / (SNAPSHOTS_PER_CONTACT * dt)))
    position_interval = int(dem_cfg.get("position_every", POSITION_SNAPSHOT_MULTIPLE)) * interval
    steps = lambda seconds: max(1, int(math.ceil(seconds / dt)))  # noqa: E731
    sampling_steps = steps(phase_time(dem_cfg, "sampling", rpm))
    sampling_steps = int(math.ceil(sampling_steps / position_interval) * position_interval)
    spinup_steps = steps(phase_time(dem_cfg, "spinup", rpm))
    history_steps = int(math.ceil(steps(dem_cfg.get("history_time", 0.05)) / position_interval) * position_interval)
    if history_steps >= spinup_steps:
        raise ValueError(f"dem.history_time = {dem_cfg.get('history_time')} s: the position history before the "
                         f"sampling window must be shorter than the spin-up ({spinup_steps * dt:.4g} s at {rpm:g} rpm)")
    return DemPlan(
        point_id=point_id(rpm, distribution), rpm=float(rpm), distribution=distribution,
        diameters=diameters, number_fractions=number_fractions, counts=counts,
        n_particles=int(sum(counts)), timestep=dt, rayleigh_time=t_r, contact_time=t_c,
        collision_interval=int(interval), settle_steps=steps(dem_cfg["settle_time"]),
        spinup_steps=spinup_steps, sampling_steps=sampling_steps,
        vtk_every=steps(dem_cfg.get("vtk_interval", 0.02)), tip_speed=tip_speed,
        history_steps=history_steps, position_interval=int(position_interval),
        encounter_gap_fraction=float(dem_cfg.get("encounter_gap_fraction", 0.25)),
        omega=2.0 * math.pi * float(rpm) / 60.0, replicate=int(replicate),
        mpi_ranks=int(dem_cfg.get("mpi_ranks", 1)),
        seed=int(dem_cfg.get("seed", 20141)) + REPLICATE_SEED_STRIDE * int(replicate),
    )


def _matrix(name: str, value: float, n: int) -> str:
    return " ".join([deck.number(name, value, minimum=0.0)] * (n * n))


def deck_values(cfg: dict, plan: DemPlan) -> dict[str, str]:
    """Validated text for every placeholder of liggghts_templates/granulator.in."""
    num = deck.number
    mat = cfg["material"]
    bowl, imp = geometry.bowl_from_config(cfg), geometry.impeller_from_config(cfg)
    n = len(plan.diameters)
    d_max = max(plan.diameters)
    margin = 0.05 * bowl.diameter
    templates = []
    seed = next_prime(plan.seed)
    for k, d in enumerate(plan.diameters):
        seed = next_prime(seed + 1)
        templates.append(
            f"fix             pts{k + 1} all particletemplate/sphere {num('seed', seed, integer=True)} "
            f"atom_type {k + 1} density constant {num('material.density', mat['density'], minimum=1.0)} "
            f"radius constant {num(f'diameters[{k}]', 0.5 * d, exclusive_minimum=True, minimum=0.0)}"
        )
    weights = " ".join(
        f"pts{k + 1} {num(f'number_fractions[{k}]', w, minimum=0.0, maximum=1.0)}"
        for k, w in enumerate(plan.number_fractions)
    )
    fill_zlo = imp.top + d_max
    fill_zhi = bowl.height - d_max
    # insert in small batches over the first 60 % of the settling phase, so that the fill region
    # never saturates (a saturated region inserts the large templates first and skews the PSD)
    insert_time = 0.6 * plan.settle_steps * plan.timestep
    insert_every = max(1, int(0.002 / plan.timestep))
    ranks = plan.mpi_ranks
    return {
        "point_id": deck.known_name("point_id", plan.point_id.replace(".", "p")),
        "processors": f"{num('mpi_ranks', ranks, integer=True, minimum=1)} 1 1",
        "box_xlo": num("box", -bowl.radius - margin), "box_xhi": num("box", bowl.radius + margin),
        "box_ylo": num("box", -bowl.radius - margin), "box_yhi": num("box", bowl.radius + margin),
        "box_zlo": num("box", -margin), "box_zhi": num("box", bowl.height + margin),
        "n_types": num("n_classes", n, integer=True, minimum=1),
        "neighbor_skin": num("neighbor_skin", 0.5 * d_max, minimum=0.0),
        "youngs_list": " ".join([num("material.youngs_modulus", mat["youngs_modulus"], exclusive_minimum=True,
                                     minimum=0.0)] * n),
        "poisson_list": " ".join([num("material.poisson_ratio", mat["poisson_ratio"], minimum=0.0,
                                      maximum=0.5)] * n),
        "restitution_matrix": _matrix("material.restitution", mat["restitution"], n),
        "friction_matrix": _matrix("material.friction", mat["friction"], n),
        "rolling_matrix": _matrix("material.rolling_friction", mat["rolling_friction"], n),
        "timestep": num("timestep", plan.timestep, exclusive_minimum=True, minimum=0.0),
        "bowl_stl": "bowl.stl", "impeller_stl": "impeller.stl", "post_dir": "post",
        # thermo reads fix check/timestep/gran, so both run at the same interval (LIGGGHTS requires it)
        "check_every": num("check_every", progress.thermo_interval(plan.n_particles, plan.vtk_every),
                           integer=True, minimum=1),
        "particle_templates_block": "\n".join(templates),
        "seed_dist": num("seed", next_prime(seed + 1), integer=True),
        "distribution_weights": weights,
        "fill_radius": num("fill_radius", bowl.radius - d_max, exclusive_minimum=True, minimum=0.0),
        "fill_zlo": num("fill_zlo", fill_zlo, minimum=0.0),
        "fill_zhi": num("fill_zhi", fill_zhi, exclusive_minimum=True, minimum=fill_zlo),
        "seed_insert": num("seed", next_prime(seed + 100), integer=True),
        "n_particles": num("n_particles", plan.n_particles, integer=True, minimum=1),
        "insert_rate": num("insert_rate", plan.n_particles / insert_time, exclusive_minimum=True, minimum=0.0),
        "insert_every": num("insert_every", insert_every, integer=True, minimum=1),
        "thermo_every": num("thermo_every", progress.thermo_interval(plan.n_particles, plan.vtk_every),
                            integer=True, minimum=1),
        "vtk_every": num("vtk_every", plan.vtk_every, integer=True, minimum=1),
        "settle_steps": num("settle_steps", plan.settle_steps, integer=True, minimum=1),
        "spinup_steps": num("spinup_steps", plan.spinup_steps, integer=True, minimum=1),
        "sampling_steps": num("sampling_steps", plan.sampling_steps, integer=True, minimum=1),
        "spinup_pre_steps": num("spinup_pre_steps", plan.spinup_steps - plan.history_steps, integer=True, minimum=1),
        "record_steps": num("record_steps", plan.history_steps + plan.sampling_steps, integer=True, minimum=1),
        "position_interval": num("position_interval", plan.position_interval, integer=True, minimum=1),
        "rotation_period": num("rotation_period", 60.0 / plan.rpm, exclusive_minimum=True, minimum=0.0),
        "collision_interval": num("collision_interval", plan.collision_interval, integer=True, minimum=1),
    }


def prepare_run(cfg: dict, plan: DemPlan, run_dir: str | Path) -> Path:
    """Write geometry, deck and plan into `run_dir` (emptied of any earlier attempt's output)."""
    run_dir = Path(run_dir)
    post = run_dir / "post"
    if post.exists():
        shutil.rmtree(post)
    post.mkdir(parents=True)
    for stale in ("crash.json", "log.liggghts"):
        (run_dir / stale).unlink(missing_ok=True)
    geometry.write_granulator(cfg, run_dir)
    write_text(run_dir / "in.granulator", deck.render("granulator.in", deck_values(cfg, plan)))
    write_json(run_dir / "plan.json", asdict(plan) | {"sampling_time": plan.sampling_time})
    return run_dir / "in.granulator"


class FinishedRunError(ValueError):
    """The run folder holds a finished run; it is only replaced when asked to (force)."""


FINISHED_MARKERS = ("collisions.csv", "summary.json")


def is_finished(run_dir: str | Path) -> bool:
    """A run folder holds a finished run once its collision table or summary exists."""
    return any((Path(run_dir) / name).exists() for name in FINISHED_MARKERS)


# what a run writes into its folder (besides whatever LIGGGHTS itself adds)
RUN_PRODUCTS = ("bowl.stl", "impeller.stl", "in.granulator", "plan.json", "log.liggghts", "screen.liggghts",
                "crash.json", "post", "wall_collisions.csv", "impact_velocity.csv", *FINISHED_MARKERS)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)


def _move_into(stage: Path, run_dir: Path) -> None:
    """Move a finished (or crashed) attempt from `stage` into `run_dir`: the old run's finished
    markers go first (so a half-replaced folder never looks finished), products of the old run
    that the new one lacks (e.g. a stale crash.json) are removed, the new markers come last.
    Anything else in `run_dir` is left alone."""
    run_dir.mkdir(parents=True, exist_ok=True)
    for name in FINISHED_MARKERS:
        (run_dir / name).unlink(missing_ok=True)
    for name in RUN_PRODUCTS:
        if not (stage / name).exists() and (run_dir / name).exists():
            _remove(run_dir / name)
    last = [stage / n for n in ("wall_collisions.csv", "impact_velocity.csv", *FINISHED_MARKERS)
            if (stage / n).exists()]
    for item in [p for p in sorted(stage.iterdir()) if p not in last] + last:
        target = run_dir / item.name
        if target.is_dir() and not target.is_symlink():
            shutil.rmtree(target)
        os.replace(item, target)
    stage.rmdir()


def planned_dumps(plan: DemPlan) -> dict[str, tuple[int, int]]:
    """Frames and last step each dump of a finished run holds: one at the start of the recording
    (`dump_modify first yes`, the position history before the sampling window), then one at every
    multiple of its interval up to the end."""
    start = plan.window_start_step - plan.history_steps
    end = plan.window_start_step + plan.sampling_steps

    def frames_and_last(every: int) -> tuple[int, int]:
        multiples = end // every - (start + every - 1) // every + 1
        return multiples + (1 if start % every else 0), (end // every * every if multiples > 0 else start)

    contacts = frames_and_last(plan.collision_interval)
    return {"post/pairs.dump": contacts, "post/walls.dump": contacts,
            "post/positions.dump": frames_and_last(plan.position_interval)}


def check_finished(plan: DemPlan, run_dir: str | Path) -> None:
    """Raise LiggghtsError (and write crash.json) unless the run reached every planned step and
    contact snapshot. LIGGGHTS exits 0 when interrupted, so the exit code proves nothing."""
    liggghts.check_finished(run_dir, plan.settle_steps + plan.spinup_steps + plan.sampling_steps,
                            planned_dumps(plan))


def run_point(cfg: dict, plan: DemPlan, run_dir: str | Path, timeout: float | None = None, *,
              force: bool = False, progress_bar: bool = False) -> dict:
    """Run LIGGGHTS for `plan` in `run_dir`, then tabulate collisions and index the VTK files.

    Everything is validated before any file is touched: the speed and the whole deck, and a
    finished run in `run_dir` is refused unless `force`. The run is made in a staging folder
    beside `run_dir` and moved into place only after it succeeded, so a failure (or a signal)
    never removes a finished run. Returns a summary dict (also `run_dir/summary.json`). Raises
    LiggghtsError on failure, leaving `crash.json` and the log in `run_dir` (or, when `run_dir`
    holds a finished run, in the staging folder named in the message) and no collision table.
    """
    from pbmdem.config import check_rpm

    run_dir = Path(run_dir)
    check_rpm(plan.rpm, f"operating point {plan.point_id}: impeller rpm")
    deck.render("granulator.in", deck_values(cfg, plan))  # raises on any bad value, before any I/O
    finished = is_finished(run_dir)
    if finished and not force:
        raise FinishedRunError(
            f"{run_dir} already holds a finished run ({', '.join(n for n in FINISHED_MARKERS if (run_dir / n).exists())}); "
            "refusing to overwrite it (rerunning would give it new time stamps, so Snakemake would redo "
            "everything downstream). Use --force to replace it, or --out to write elsewhere.")
    where = run_dir.resolve()
    stage = where.parent / f".{where.name}.staging"
    if stage.exists():
        shutil.rmtree(stage)
    stage.mkdir(parents=True)
    try:
        summary = _run_in(cfg, plan, stage, run_dir, timeout, progress_bar)
    except BaseException as exc:
        if not finished:  # nothing to protect: keep the crash and the logs in the run folder
            _move_into(stage, run_dir)
            if len(exc.args) == 1 and isinstance(exc.args[0], str):
                exc.args = (exc.args[0].replace(str(stage), str(run_dir)),)
        elif len(exc.args) == 1 and isinstance(exc.args[0], str):
            exc.args = (f"{exc.args[0]}\n(the finished run in {run_dir} is untouched; this attempt is in {stage})",)
        raise
    _move_into(stage, run_dir)
    return summary


def _run_in(cfg: dict, plan: DemPlan, run_dir: Path, final_dir: Path, timeout: float | None,
            progress_bar: bool = False) -> dict:
    """run_point's work in the (staging) folder `run_dir`; paths in the summary name `final_dir`."""
    from pbmdem import collisions, vtk_series  # local: keep this module light to import
    from pbmdem.progress import ThermoProgress

    deck_path = prepare_run(cfg, plan, run_dir)
    watcher = ThermoProgress(run_dir / "log.liggghts", [("settling", plan.settle_steps), ("spin-up", plan.spinup_steps),
                                                        ("sampling", plan.sampling_steps)],
                             label=f"DEM {plan.point_id}", bar=progress_bar)
    result = liggghts.run(deck_path, run_dir, ranks=plan.mpi_ranks, timeout=timeout, progress=watcher)
    check_finished(plan, run_dir)
    t0 = time.perf_counter()
    tables = collisions.tabulate_run(run_dir / "post", plan, geometry.bowl_from_config(cfg),
                                     geometry.impeller_from_config(cfg))
    parse_time = time.perf_counter() - t0
    collisions.write_tables(tables, run_dir)
    series = vtk_series.write_series(run_dir / "post", plan.timestep)
    if not cfg["dem"].get("keep_contact_dumps", False):
        for dump in ("pairs.dump", "walls.dump", "positions.dump"):
            (run_dir / "post" / dump).unlink(missing_ok=True)
    thermo = liggghts.thermo_table(result.log)
    # fix check/timestep/gran: ts[1] = dt / Rayleigh time, ts[2] = dt / Hertz time (LIGGGHTS' own)
    checks = {"dt_over_rayleigh_time": max(thermo.get("ts[1]", [float("nan")])),
              "dt_over_hertz_time_max": max(thermo.get("ts[2]", [float("nan")]))}
    summary = {
        **checks,
        "point_id": plan.point_id, "rpm": plan.rpm, "distribution": plan.distribution,
        "n_particles": plan.n_particles, "timestep": plan.timestep,
        "steps": plan.settle_steps + plan.spinup_steps + plan.sampling_steps,
        "particle_steps": plan.particle_steps, "liggghts_wall_time_s": result.wall_time,
        "particle_steps_per_s": plan.particle_steps / result.wall_time,
        "parse_time_s": parse_time, "parse_cost_ratio": parse_time / result.wall_time,
        "collision_interval": plan.collision_interval,
        "replicate": plan.replicate, "seed": plan.seed,
        "total_collisions": int(tables.pairs["collisions"].sum()),
        "total_encounters": int(tables.pairs["encounters"].sum()),
        "sampling_time": float(tables.pairs["sampling_time"].iloc[0]),
        **tables.diagnostics, **{f"series_{k}": str(final_dir / "post" / Path(v).name) for k, v in series.items()},
    }
    write_json(run_dir / "summary.json", summary)
    return summary


def run_operating_point(cfg: dict, rpm: float, distribution: str, run_dir: str | Path, replicate: int = 0) -> dict:
    """Plan and run one replicate of a grid point of the config (the Snakemake rule's entry point)."""
    plan = plan_point(cfg, rpm, distribution, replicate=replicate)
    return run_point(cfg, plan, run_dir, timeout=cfg["dem"].get("timeout"))


# dem: settings that change how a run is executed, not its result (the same run on 1 or 2 ranks
# gives statistically the same tables). They are kept out of the rules' params, so changing them
# reruns nothing that has finished; the rule scripts add them back from the live config and
# the job's resources (`execution_settings`).
EXECUTION_KEYS = ("mpi_ranks", "timeout")


def result_settings(dem_cfg: dict) -> dict:
    """The dem: section without its execution-only keys."""
    return {k: v for k, v in dem_cfg.items() if k not in EXECUTION_KEYS}


def with_execution(cfg: dict, config: dict, resources=None) -> dict:
    """`cfg` (rule params) with the execution settings of the live `config` put back; a job's
    `tasks` resource (set by a cluster profile) overrides dem.mpi_ranks."""
    execution = {k: config.get("dem", {})[k] for k in EXECUTION_KEYS if k in config.get("dem", {})}
    tasks = resources.get("tasks") if resources is not None else None
    if tasks:
        execution["mpi_ranks"] = int(tasks)
    out = dict(cfg)
    out["dem"] = {**cfg["dem"], **execution}
    return out


def point_config(cfg: dict, distribution: str) -> dict:
    """The part of the config that determines one DEM point's result (used as rule params, so
    that editing another point or another stage, or an execution-only setting, does not re-run
    this one)."""
    # the number of replicates decides which runs exist, not what one run computes
    dem_cfg = {k: v for k, v in result_settings(cfg["dem"]).items() if k != "replicates"}
    return {
        "granulator": cfg["granulator"], "material": cfg["material"], "dem": dem_cfg,
        "size_distributions": {distribution: cfg["size_distributions"][distribution]},
    }


def run_table(summaries: list[str | Path], out: str | Path):
    """One row per run with its size, cost and convergence figures (atomically written CSV)."""
    import json

    import pandas as pd

    from pbmdem.atomic import write_csv

    from pbmdem.readers import read_json

    rows = [read_json(p, "DEM run summary") for p in summaries]
    frame = pd.DataFrame(rows).drop(columns=[c for c in ("particles_per_class",) if c in rows[0]], errors="ignore")
    frame = frame.sort_values(["rpm", "distribution"]).reset_index(drop=True)
    write_csv(out, frame)
    return frame
