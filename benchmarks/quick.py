"""Inputs for the benchmarks' ``--quick`` modes, made in seconds from a clean clone (no results/).

A quick mode checks that a benchmark still runs and prints its figures (tests/test_benchmarks.py
runs every one); its numbers are for the machinery, not for science. Where a benchmark reads the
workflow's outputs, this module makes small stand-ins with known laws:

* :func:`dem_tables`: the grid tables of ``results/dem`` (pairs, impact speeds, walls and their
  impact speeds) from tests/synthetic_tables.py, for the tiny configuration's impeller;
* :func:`dem_grid`: a real (tiny) ``results/dem``: LIGGGHTS runs of one point of the tiny
  configuration, replicated, from settled beds, tabulated as the workflow's collision_tables and
  speed_response rules do;
* :func:`surrogate`: a surrogate trained on those tables as the workflow's ``train_surrogate``
  produces it (frequency and impact-speed models, a wall model per wall, the configuration's
  speed law), but with the MLP family fixed and without the held-out evaluation that chooses the
  family and calibrates the uncertainty (minutes on the tiny configuration, seconds here).

Not part of the package: src/pbmdem holds the product; this is a benchmark helper.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the synthetic tables live with the tests
#: the tiny configuration of the tests: a 30 mm bowl, a few hundred particles
TEST_CONFIG = ROOT / "config" / "test.yaml"
#: synthetic DEM grid: speeds, class diameters (m) and feeds (number fractions) that span the tiny
#: configuration's validation and design speeds and the sizes its PBM grows to, with few rows:
#: every row's speed law is a maximum-likelihood fit (about 0.05-0.1 s each for the generalised gamma)
RPMS = (300, 750, 1200)
DIAMETERS = (0.002, 0.005, 0.012)
FEEDS = {"fine": (0.6, 0.3, 0.1), "coarse": (0.3, 0.4, 0.3)}
#: particles in a run of the synthetic grid (the tiny configuration's beds hold about 300-500)
N_TOTAL = (300, 600)
#: file names of the grid tables, as in results/dem
TABLE_FILES = {
    "pairs": "collisions.csv",
    "velocities": "impact_velocity.csv",
    "walls": "wall_collisions.csv",
    "wall_velocities": "wall_impact_velocity.csv",
}


def config(path: str | Path = TEST_CONFIG):
    """The typed configuration (``pbmdem.config.Config``) of ``path``, the tiny one by default."""
    from pbmdem.config import load_config

    return load_config(path)


def dem_tables(folder: str | Path, cfg=None, seed: int = 0) -> Path:
    """The four grid tables of a DEM grid (``TABLE_FILES``) written to ``folder`` and returned:
    synthetic tables (tests/synthetic_tables.py: a power law for the encounter frequency,
    log-normal impact speeds, walls by `synthetic_tables.wall_law`) for the
    impeller of ``cfg`` (default: the tiny configuration), speeds :data:`RPMS`, sizes :data:`DIAMETERS`."""
    from functools import partial

    from synthetic_tables import (
        CONTACTS_PER_ENCOUNTER,
        make_synthetic_tables,
        make_synthetic_wall_tables,
        power_law,
    )

    cfg = cfg or config()
    radius = cfg.granulator.impeller.tip_radius
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    # c0 = 0.03: the lower end of the DEM's encounter frequencies per pair (as bench_pbm's surrogate)
    pairs, velocities = make_synthetic_tables(
        radius,
        rpms=RPMS,
        distributions=FEEDS,
        diameters=DIAMETERS,
        n_total_range=N_TOTAL,
        law=partial(power_law, c0=0.03),
        seed=seed,
    )
    walls, wall_velocities = make_synthetic_wall_tables(pairs, radius, seed=seed + 1)
    # the columns of the grid tables' contract (pbmdem.tables) that the synthetic tables leave out:
    # the raw contacts' standard error (a fixed multiple of the encounters') and the replicates
    replicates = int(pairs["n_replicates"].iloc[0])
    pairs["frequency_per_pair_se"] = CONTACTS_PER_ENCOUNTER * pairs["encounter_frequency_per_pair_se"]
    velocities["n_replicates"] = replicates
    wall_velocities["n_replicates"] = replicates
    frames = {"pairs": pairs, "velocities": velocities, "walls": walls, "wall_velocities": wall_velocities}
    for key, frame in frames.items():
        frame.to_csv(folder / TABLE_FILES[key], index=False)
    return folder


def surrogate(folder: str | Path, cfg=None, tables: str | Path | None = None) -> Path:
    """A trained surrogate written to ``folder``/model.skops (with its model.json) and returned.

    Trained on the grid tables in ``tables`` (default: :func:`dem_tables` written to
    ``folder``/dem) with ``cfg``'s ``surrogate:`` settings (default: the tiny configuration's), its
    first hyperparameter candidate and the MLP family; walls as the workflow trains them."""
    from pbmdem.impact import WALLS
    from pbmdem.surrogate._threads import single_threaded
    from pbmdem.surrogate.features import training_data
    from pbmdem.surrogate.persistence import save_surrogate
    from pbmdem.surrogate.settings import build_surrogate
    from pbmdem.surrogate.walls import wall_training_data
    from pbmdem.tables import GRID_PAIRS, GRID_VELOCITIES, GRID_WALL_VELOCITIES, GRID_WALLS

    cfg = cfg or config()
    folder = Path(folder)
    tables = Path(tables) if tables is not None else dem_tables(folder / "dem", cfg)
    pairs = GRID_PAIRS.read(tables / TABLE_FILES["pairs"])
    velocities = GRID_VELOCITIES.read(tables / TABLE_FILES["velocities"])
    walls = GRID_WALLS.read(tables / TABLE_FILES["walls"])
    wall_velocities = GRID_WALL_VELOCITIES.read(tables / TABLE_FILES["wall_velocities"])
    settings = cfg.surrogate.to_dict()
    settings.update(hidden_layer_sizes=settings["hidden_layer_sizes"][:1], alpha=settings["alpha"][:1])
    radius, law, zeros = cfg.granulator.impeller.tip_radius, settings["speed_law"], settings["zero_collisions"]
    # one BLAS thread: the speed-law fits (L-BFGS-B per row) ran 3x slower with two on a busy machine
    with warnings.catch_warnings(), single_threaded():
        warnings.simplefilter("ignore")  # convergence warnings of the small MLPs
        data = training_data(pairs, radius, zeros, velocity_table=velocities, speed_law=law)
        model = build_surrogate(settings, radius, n_jobs=1, family="mlp")
        model.fit(data.X, data.y, groups=data.groups, velocity=data.velocity)
        model.wall_models_ = {}
        for wall in WALLS:
            wd = wall_training_data(walls, wall_velocities, wall, radius, zeros, law)
            wall_model = build_surrogate(settings, radius, n_jobs=1, family="mlp")
            model.wall_models_[wall] = wall_model.fit(wd.X, wd.y, groups=wd.groups, velocity=wd.velocity)
    path = folder / "model.skops"
    save_surrogate(model, path, extra={"training_table": str(tables), "note": "benchmarks/quick.py"})
    return path


def timed_surrogate(folder: str | Path, cfg=None) -> tuple[Path, float]:
    """(:func:`surrogate` of ``folder``, its wall time in s), with a line saying what was made."""
    t0 = time.perf_counter()
    path = surrogate(folder, cfg)
    wall = time.perf_counter() - t0
    print(f"quick: surrogate trained on synthetic DEM tables in {wall:.1f} s ({path})", flush=True)
    return path, wall


def dem_grid(root: str | Path, cfg=None, rpm: float = 600.0, distribution: str = "small", replicates: int = 2) -> Path:
    """A DEM grid of one point, run with the real LIGGGHTS in ``root``/dem as the workflow lays it
    out (pbmdem.layout: a settled bed per replicate, the runs from their beds) and tabulated as
    its rules do (the grid tables, collisions_replicates.csv, runs.csv, flow_development.csv);
    returns ``root``/dem. A few seconds per replicate with the tiny configuration (the default)."""
    from pbmdem import layout
    from pbmdem.atomic import write_csv
    from pbmdem.dem.collisions import aggregate, read_tables, run_table
    from pbmdem.dem.plan import plan_bed, plan_point
    from pbmdem.dem.run import run_point, settle_bed
    from pbmdem.dem.speed_response import flow_development
    from pbmdem.tables import RUNS

    cfg = cfg or config()
    root = Path(root)
    point = cfg.dem_point(distribution)
    runs = []
    for rep in range(replicates):
        bed = Path(layout.dem_bed(distribution, rep, root=str(root)))
        settle_bed(plan_bed(point, replicate=rep), bed, cfg.dem_execution)
        run = Path(layout.dem_run(f"{rpm:g}", distribution, rep, root=str(root)))
        run_point(plan_point(point, rpm, replicate=rep), run, cfg.dem_execution, bed_dir=bed)
        runs.append(run)
    dem = Path(layout.dem(root=str(root)))
    for kind, name in TABLE_FILES.items():
        aggregate([r / name for r in runs], dem / name, kind=kind)
    write_csv(dem / "collisions_replicates.csv", read_tables([r / "collisions.csv" for r in runs], "pairs"))
    run_table([r / "summary.json" for r in runs], dem / "runs.csv")
    write_csv(dem / "flow_development.csv", flow_development(RUNS.read(dem / "runs.csv")))
    return dem
