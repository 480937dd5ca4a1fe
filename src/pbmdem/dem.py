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
import shutil
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from pbmdem import deck, geometry, liggghts
from pbmdem.atomic import write_json, write_text

# Hertz contact duration t_c = 2.87 (m*^2 / (R* E*^2 v))^(1/5) (Johnson 1985); snapshots are
# taken every t_c / SNAPSHOTS_PER_CONTACT so that a head-on contact between two of the smallest
# particles at the impeller tip speed is seen at least this many times (measured here: counts change
# by 0.4 % when this interval is halved, 1.9 % when doubled). Measured convergence is
# reported per run (counts with every snapshot vs every second one).
SNAPSHOTS_PER_CONTACT = 2


def point_id(rpm: float, distribution: str) -> str:
    return f"rpm{float(rpm):g}_{distribution}"


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
    mpi_ranks: int = 1
    seed: int = 20141
    extra: dict = field(default_factory=dict)

    @property
    def sampling_time(self) -> float:
        return self.sampling_steps * self.timestep

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


def plan_point(cfg: dict, rpm: float, distribution: str, *, n_particles: int | None = None,
               diameters=None, number_fractions=None) -> DemPlan:
    """Plan a run. `diameters`/`number_fractions`/`n_particles` override the named distribution
    (the coupled PBM-DEM loop hands its own size distribution this way)."""
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
    steps = lambda seconds: max(1, int(math.ceil(seconds / dt)))  # noqa: E731
    sampling_steps = steps(dem_cfg["sampling_time"])
    sampling_steps = int(math.ceil(sampling_steps / interval) * interval)
    return DemPlan(
        point_id=point_id(rpm, distribution), rpm=float(rpm), distribution=distribution,
        diameters=diameters, number_fractions=number_fractions, counts=counts,
        n_particles=int(sum(counts)), timestep=dt, rayleigh_time=t_r, contact_time=t_c,
        collision_interval=int(interval), settle_steps=steps(dem_cfg["settle_time"]),
        spinup_steps=steps(dem_cfg["spinup_time"]), sampling_steps=sampling_steps,
        vtk_every=steps(dem_cfg.get("vtk_interval", 0.02)), tip_speed=tip_speed,
        mpi_ranks=int(dem_cfg.get("mpi_ranks", 1)), seed=int(dem_cfg.get("seed", 20141)),
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
        "check_every": num("check_every", max(1, plan.vtk_every), integer=True, minimum=1),
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
        "thermo_every": num("thermo_every", max(1, plan.vtk_every), integer=True, minimum=1),
        "vtk_every": num("vtk_every", plan.vtk_every, integer=True, minimum=1),
        "settle_steps": num("settle_steps", plan.settle_steps, integer=True, minimum=1),
        "spinup_steps": num("spinup_steps", plan.spinup_steps, integer=True, minimum=1),
        "sampling_steps": num("sampling_steps", plan.sampling_steps, integer=True, minimum=1),
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


def planned_dumps(plan: DemPlan) -> dict[str, tuple[int, int]]:
    """Frames and last step each contact dump of a finished run holds: one at the start of the
    sampling (`dump_modify first yes`), then one at every multiple of the interval up to the end."""
    start = plan.settle_steps + plan.spinup_steps
    end = start + plan.sampling_steps
    every = plan.collision_interval
    multiples = end // every - (start + every - 1) // every + 1
    frames = multiples + (1 if start % every else 0)
    last = end // every * every if multiples > 0 else start
    return {"post/pairs.dump": (frames, last), "post/walls.dump": (frames, last)}


def check_finished(plan: DemPlan, run_dir: str | Path) -> None:
    """Raise LiggghtsError (and write crash.json) unless the run reached every planned step and
    contact snapshot. LIGGGHTS exits 0 when interrupted, so the exit code proves nothing."""
    liggghts.check_finished(run_dir, plan.settle_steps + plan.spinup_steps + plan.sampling_steps,
                            planned_dumps(plan))


def run_point(cfg: dict, plan: DemPlan, run_dir: str | Path, timeout: float | None = None) -> dict:
    """Run LIGGGHTS for `plan` in `run_dir`, then tabulate collisions and index the VTK files.

    Returns a summary dict (also written to `run_dir/summary.json`). Raises LiggghtsError on
    failure, leaving `crash.json` and the log in `run_dir` and no collision table.
    """
    from pbmdem import collisions, vtk_series  # local: keep this module light to import

    run_dir = Path(run_dir)
    for name in ("collisions.csv", "wall_collisions.csv", "summary.json"):
        (run_dir / name).unlink(missing_ok=True)
    deck_path = prepare_run(cfg, plan, run_dir)
    result = liggghts.run(deck_path, run_dir, ranks=plan.mpi_ranks, timeout=timeout)
    check_finished(plan, run_dir)
    t0 = time.perf_counter()
    tables = collisions.tabulate_run(run_dir / "post", plan)
    parse_time = time.perf_counter() - t0
    collisions.write_tables(tables, run_dir)
    series = vtk_series.write_series(run_dir / "post", plan.timestep)
    if not cfg["dem"].get("keep_contact_dumps", False):
        for dump in ("pairs.dump", "walls.dump"):
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
        "total_collisions": int(tables.pairs["collisions"].sum()),
        **tables.diagnostics, **{f"series_{k}": str(v) for k, v in series.items()},
    }
    write_json(run_dir / "summary.json", summary)
    return summary


def run_operating_point(cfg: dict, rpm: float, distribution: str, run_dir: str | Path) -> dict:
    """Plan and run one grid point of the config (the Snakemake rule's entry point)."""
    plan = plan_point(cfg, rpm, distribution)
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
    return {
        "granulator": cfg["granulator"], "material": cfg["material"], "dem": result_settings(cfg["dem"]),
        "size_distributions": {distribution: cfg["size_distributions"][distribution]},
    }


def run_table(summaries: list[str | Path], out: str | Path):
    """One row per run with its size, cost and convergence figures (atomically written CSV)."""
    import json

    import pandas as pd

    from pbmdem.atomic import write_csv

    rows = [json.loads(Path(p).read_text()) for p in summaries]
    frame = pd.DataFrame(rows).drop(columns=[c for c in ("particles_per_class",) if c in rows[0]], errors="ignore")
    frame = frame.sort_values(["rpm", "distribution"]).reset_index(drop=True)
    write_csv(out, frame)
    return frame
