"""Shared fixtures. DEM fixtures run the real LIGGGHTS engine on the tiny test configuration."""

from __future__ import annotations

import copy
import shutil
from pathlib import Path

import pytest

from pbmdem.config import load_config

ROOT = Path(__file__).resolve().parents[1]


def pytest_collection_modifyitems(config, items):
    if shutil.which("liggghts") is None:
        raise pytest.UsageError("LIGGGHTS is not installed: run scripts/bootstrap.sh first (README command 2)")


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def _tiny_config() -> dict:
    return load_config(ROOT / "config" / "test.yaml")


@pytest.fixture
def tiny_config(_tiny_config) -> dict:
    """A fresh deep copy of config/test.yaml (tests may modify it)."""
    return copy.deepcopy(_tiny_config)


@pytest.fixture(scope="session")
def default_config() -> dict:
    return load_config(ROOT / "config" / "config.yaml")


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory, _tiny_config):
    """One real LIGGGHTS run of the tiny granulator (600 rpm, 'small'), contact dumps kept."""
    from pbmdem import dem

    cfg = copy.deepcopy(_tiny_config)
    cfg["dem"]["keep_contact_dumps"] = True
    plan = dem.plan_point(cfg, 600, "small")
    run_dir = tmp_path_factory.mktemp("tiny_run")
    summary = dem.run_point(cfg, plan, run_dir, timeout=600)
    return {"dir": run_dir, "plan": plan, "summary": summary, "config": cfg}
