"""Bounded plans: an operating point whose DEM plan exceeds dem.limits, or a grid with more than
grid.max_points points, is refused before anything runs (planner, command line, Snakefile)."""

from __future__ import annotations

import subprocess
import time

import pytest
import yaml
from conftest import config_of, snakemake_command

from pbmdem.cli import main
from pbmdem.config import ConfigError
from pbmdem.dem import plan_point, run_point
from pbmdem.dem.plan import check_limits, check_workflow_plans


@pytest.mark.parametrize("name", ["config.yaml", "test.yaml"])
def test_the_shipped_configs_plan_well_inside_the_limits(root, name):
    from pbmdem.config import load_config

    cfg = load_config(root / "config" / name)
    check_workflow_plans(cfg)  # raises if any run of the workflow is beyond the bounds
    limits = cfg.dem_execution.limits
    plans = [plan_point(cfg.dem_point(dist), rpm) for rpm, dist in cfg.grid.points()]
    # the defaults sit a comfortable factor above the largest run (pbmdem.config.dem.DemLimits states it)
    assert max(p.total_steps for p in plans) * 10 < limits.max_steps
    assert max(p.total_steps * p.timestep for p in plans) * 10 < limits.max_simulated_time
    assert max(p.particle_steps for p in plans) * 10 < limits.max_particle_steps
    assert cfg.grid.count() * 10 < cfg.grid.max_points


def test_a_vanishing_speed_is_refused_by_the_planner_naming_each_bound(tiny_mapping):
    tiny_mapping["grid"]["impeller_rpm"] = [1e-9]
    tiny_mapping["dem"]["spinup_revolutions"] = 1.0  # as in config/config.yaml: the spin-up lasts a revolution
    cfg = config_of(tiny_mapping)
    with pytest.raises(ConfigError) as err:
        check_workflow_plans(cfg)
    text = str(err.value)
    assert "rpm0.000000001_small" in text
    for key in ("max_steps", "max_simulated_time", "max_particle_steps"):
        assert f"dem.limits.{key} = " in text


@pytest.mark.parametrize("key, value", [("max_steps", 1000), ("max_simulated_time", 0.05), ("max_particle_steps", 1e5)])
def test_each_bound_is_enforced_alone(tiny_config, key, value):
    plan = plan_point(tiny_config.dem_point("small"), 600)
    limits = tiny_config.dem_execution.limits
    assert check_limits(plan, limits) is plan
    with pytest.raises(ConfigError, match=rf"dem\.limits\.{key} = {value:g}") as err:
        check_limits(plan, limits.replace(**{key: value}))
    assert str(err.value).count("dem.limits.") == 1


def test_run_point_refuses_an_unbounded_plan_before_touching_the_disk(tiny_config, tmp_path):
    point = tiny_config.dem_point("small")
    plan = plan_point(point, 600)
    execution = tiny_config.dem_execution
    execution = execution.replace(limits=execution.limits.replace(max_steps=plan.total_steps - 1))
    with pytest.raises(ConfigError, match=r"dem\.limits\.max_steps"):
        run_point(point, plan, tmp_path / "run", execution)
    assert not any(tmp_path.iterdir())


def test_plan_only_refuses_a_vanishing_speed(root, capsys):
    code = main(
        ["dem", "--config", str(root / "config" / "config.yaml"), "--rpm", "1e-9", "--distribution", "fine"]
        + ["--plan-only"]
    )
    captured = capsys.readouterr()
    assert code == 2
    assert captured.out == ""
    assert "dem.limits.max_steps = 5e+06" in captured.err
    assert "Traceback" not in captured.err


def test_a_huge_grid_is_refused_quickly_with_its_count(tiny_mapping):
    tiny_mapping["grid"]["impeller_rpm"] = [100.0 + k for k in range(1000)]
    tiny_mapping["grid"]["size_distributions"] = [f"d{k}" for k in range(1000)]
    t0 = time.perf_counter()
    with pytest.raises(ConfigError) as err:
        config_of(tiny_mapping)
    assert time.perf_counter() - t0 < 30
    assert "= 1000000 operating points, more than grid.max_points = 1000" in str(err.value)


def test_snakemake_dry_run_refuses_an_unbounded_point_before_the_dag(root, tmp_path):
    cfg = yaml.safe_load((root / "config" / "test.yaml").read_text())
    cfg["grid"]["impeller_rpm"] = [1e-9, 600]
    cfg["dem"]["sampling_revolutions"] = 0.5
    config = tmp_path / "config.yaml"
    config.write_text(yaml.safe_dump(cfg))
    proc = subprocess.run(
        snakemake_command(tmp_path, "-n", "--cores", "1", configfile=config),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "pbmdem: error: invalid configuration" in proc.stderr
    assert "rpm0.000000001_small" in proc.stderr and "dem.limits.max_steps" in proc.stderr
    assert "Job stats" not in proc.stdout + proc.stderr
