"""Shared fixtures. DEM fixtures run the real LIGGGHTS engine on the tiny test configuration.

Configurations come through the settings layer like every other path: `tiny_config` and
`default_config` are typed `pbmdem.config.Config` objects; a test that needs an edited
configuration edits the completed mapping (`tiny_mapping`) and builds it with `config_of`.
"""

from __future__ import annotations

import copy
import os
import shutil
import sys
import warnings
from functools import partial
from pathlib import Path

import numpy as np
import pytest

from pbmdem.config import Config, load_config

ROOT = Path(__file__).resolve().parents[1]


def pytest_collection_modifyitems(config, items):
    if shutil.which("liggghts") is None:
        raise pytest.UsageError("LIGGGHTS is not installed: run scripts/bootstrap.sh first (README command 2)")


def leftover_processes(folder: Path, children_of: int | None = None) -> list:
    """Live processes (psutil) the tests started and left: those whose working directory or
    command line lies under `folder` (e.g. the session's temporary folder: a process re-parented
    to init is found too) and, with `children_of` (a PID), every descendant of that process."""
    import psutil

    me = psutil.Process()
    found = {} if children_of is None else {p.pid: p for p in psutil.Process(children_of).children(recursive=True)}
    base = str(folder)
    for proc in psutil.process_iter(["pid", "cwd", "cmdline"]):
        cwd, cmd = proc.info.get("cwd") or "", " ".join(proc.info.get("cmdline") or [])
        if cwd.startswith(base) or base in cmd:
            found[proc.pid] = proc
    alive = []
    for proc in found.values():
        try:
            if proc.pid != me.pid and proc.status() != psutil.STATUS_ZOMBIE:
                alive.append(proc)
        except psutil.Error:
            pass
    return alive


def end_processes(procs: list) -> None:
    """SIGTERM each process by PID, SIGKILL those still alive 3 s later."""
    import psutil

    for proc in procs:
        try:
            proc.terminate()
        except psutil.Error:
            pass
    _, alive = psutil.wait_procs(procs, timeout=3)
    for proc in alive:
        try:
            proc.kill()
        except psutil.Error:
            pass
    psutil.wait_procs(alive, timeout=3)


def pytest_sessionfinish(session, exitstatus):
    """The suite leaves no process behind: whatever a test started and left running (found by
    `leftover_processes`) is ended by PID, named, and fails the run."""
    factory = getattr(session.config, "_tmp_path_factory", None)
    if factory is None or getattr(factory, "_basetemp", None) is None:
        return
    left = leftover_processes(factory.getbasetemp(), children_of=os.getpid())
    if not left:
        return
    names = []
    for proc in left:
        try:
            names.append(f"{proc.pid} {' '.join(proc.cmdline())[:200]}")
        except Exception:
            names.append(str(proc.pid))
    end_processes(left)
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    message = "processes started by the tests were still running at the end (now ended):\n  " + "\n  ".join(names)
    if reporter is not None:
        reporter.ensure_newline()
        reporter.write_line(message, red=True)
    session.exitstatus = pytest.ExitCode.TESTS_FAILED


def config_of(mapping: dict) -> Config:
    """A Config from a (possibly edited) configuration mapping, validated as in the workflow."""
    return Config.from_mapping(mapping)


def snakemake_command(workdir: Path, *args: str, configfile: Path | None = None, project: Path = ROOT) -> list[str]:
    """The command line that runs the workflow of `project` (this checkout, or a copy of it) in
    `workdir`, with `configfile` if given."""
    cmd = [sys.executable, "-m", "snakemake", "-s", str(project / "Snakefile"), "--directory", str(workdir)]
    if configfile is not None:
        cmd += ["--configfile", str(configfile)]
    return [*cmd, *args]


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def tiny_config() -> Config:
    """config/test.yaml as a typed Config (frozen: tests cannot modify it)."""
    return load_config(ROOT / "config" / "test.yaml")


@pytest.fixture
def tiny_mapping(tiny_config) -> dict:
    """A fresh copy of config/test.yaml's completed mapping (defaults filled), to edit."""
    return copy.deepcopy(tiny_config.to_dict())


@pytest.fixture(scope="session")
def default_config() -> Config:
    return load_config(ROOT / "config" / "config.yaml")


@pytest.fixture
def default_mapping(default_config) -> dict:
    return copy.deepcopy(default_config.to_dict())


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory, tiny_config):
    """One real LIGGGHTS run of the tiny granulator (600 rpm, 'small'), contact dumps kept."""
    from pbmdem.dem import plan_point, run_point

    point = tiny_config.dem_point("small")
    point = point.replace(dem=point.dem.replace(keep_contact_dumps=True))
    plan = plan_point(point, 600)
    run_dir = tmp_path_factory.mktemp("tiny_run")
    summary = run_point(plan, run_dir, tiny_config.dem_execution.replace(timeout=600))
    return {"dir": run_dir, "plan": plan, "summary": summary, "config": tiny_config, "point": point}


@pytest.fixture(scope="session")
def tiny_surrogate(tmp_path_factory, tiny_config):
    """A small MLP surrogate trained on synthetic tables at 600-900 rpm for the tiny granulator, with
    frequencies near the tiny config's constant kernel (~3 1/s per pair for its ~300 granules)."""
    from synthetic_tables import make_synthetic_tables, power_law

    from pbmdem.surrogate import CollisionSurrogate, EnsembleMLPRegressorCV, save_surrogate, training_data
    from pbmdem.surrogate.velocity import attach_velocity_bins

    radius = tiny_config.granulator.impeller.blade_length
    table = attach_velocity_bins(
        *make_synthetic_tables(
            radius,
            rpms=(600, 750, 900),
            diameters=(0.0015, 0.003, 0.006),
            n_total_range=(20, 2000),
            seed=2,
            law=partial(power_law, c0=0.6),
            # four random beds and two lopsided ones (mostly large, mostly fine), so that the sizes
            # over the bed's Sauter diameter (rel_small, rel_large) span the tiny batches' beds
            distributions={
                **{f"dist{k}": f for k, f in enumerate(np.random.default_rng(2).dirichlet(np.full(3, 2.0), 4))},
                "fines_among_large": [0.3, 0.2, 0.5],
                "large_among_fines": [0.9, 0.08, 0.02],
            },
        )
    )
    data = training_data(table, radius)
    model = CollisionSurrogate(
        frequency_model=EnsembleMLPRegressorCV(
            hidden_layer_sizes=((4,),),
            alpha=(0.1,),
            seeds=(0, 1),
            max_iter=300,
            solver="lbfgs",
            cv="group_kfold",
            n_splits=3,
        ),
        impeller_radius=radius,
        physics_offset="cross_section",
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(data.X, data.y, groups=data.groups, velocity=data.velocity)
    path = tmp_path_factory.mktemp("surrogate") / "model.skops"
    save_surrogate(model, path)
    return path
