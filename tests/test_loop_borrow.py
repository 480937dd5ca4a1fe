"""PBM-DEM loops borrow the DEM grid's run of their feed (and its settled bed) where it is their own
plan, with the real LIGGGHTS engine on the tiny granulator (docs/validation.md, "Borrowed grid runs")."""

import dataclasses
import json

import pandas as pd
import pytest

from pbmdem import coupling
from pbmdem.coupling.providers import covers, dem_rates, interval_run_dir
from pbmdem.dem.estimate import measured_throughput, study_estimate
from pbmdem.dem.plan import plan_bed, plan_point
from pbmdem.dem.run import run_point, settle_bed
from pbmdem.frequency import pairs_of
from pbmdem.readers import read_json

GRID_RPM = 600.0  # a grid speed of config/test.yaml
OTHER_RPM = 900.0  # a validation speed between grid speeds


@pytest.fixture(scope="module")
def grid_run(tiny_config, tmp_path_factory):
    """The grid's settled bed of the validation feed (replicate 0) and its run at a grid speed,
    made as the rules dem_bed and dem_point make them."""
    root = tmp_path_factory.mktemp("grid")
    feed = tiny_config.validation.distribution
    point = tiny_config.dem_point(feed)
    execution = tiny_config.dem_execution
    settle_bed(plan_bed(point, replicate=0), root / "bed", execution)
    run_point(plan_point(point, GRID_RPM, replicate=0), root / "run", execution, bed_dir=root / "bed")
    return {"bed": root / "bed", "run": root / "run", "execution": execution}


def _loop(tiny_config):
    return tiny_config.coupled_loop().replace(coupling_intervals=2)


@pytest.mark.liggghts
def test_a_loop_at_a_grid_speed_borrows_the_grid_run_of_its_feed(tiny_config, grid_run, tmp_path):
    """Interval 0's sample is the feed, whose plan at a grid speed is the grid's run: the loop reads
    that run's tables instead of calling LIGGGHTS, counts its (and its bed's) CPU and wall time as
    its own, and interval 1 (the same sample) reuses it at no cost."""
    out = tmp_path / "pbm_dem"
    timing = coupling.pbm_dem(
        _loop(tiny_config), GRID_RPM, out, grid_run["execution"], 0, grid_run["run"], grid_run["bed"]
    ).totals
    rows = pd.read_csv(out / "intervals.csv")
    summary = read_json(grid_run["run"] / "summary.json", "grid run")
    assert rows.dem_borrowed_run[0] == str(grid_run["run"])
    assert not (out / "interval_00" / "dem").exists() and not (out / "interval_01" / "dem").exists()
    own_cpu = summary["liggghts_cpu_time_s"] + summary["bed_liggghts_cpu_time_s"]
    own_wall = summary["liggghts_wall_time_s"] + summary["bed_liggghts_wall_time_s"] + summary["parse_time_s"]
    assert rows.dem_cpu_time_s[0] == pytest.approx(own_cpu) and own_cpu > 0
    assert rows.dem_borrowed_wall_time_s[0] == pytest.approx(own_wall)
    assert rows.provider_wall_time_s[0] >= own_wall and timing["provider_wall_time_s"] >= own_wall
    assert timing["dem_cpu_time_s"] == pytest.approx(own_cpu)
    # the frequencies handed to the PBM are the grid run's
    k = rows.classes[0]
    assert json.loads(rows.class_frequencies[0]) == pairs_of(dem_rates(grid_run["run"], k).pairs.frequency).tolist()
    assert rows.dem_reused_from_interval.isna()[0] and rows.dem_reused_from_interval[1] == 0
    assert rows.dem_cpu_time_s[1] == 0 and rows.class_frequencies[1] == rows.class_frequencies[0]
    # a replay of the stored loop (benchmarks/bench_replay.py) finds the borrowed run's tables
    for k in (0, 1):
        info = read_json(out / f"interval_{k:02d}" / "interval.json", "interval")
        assert interval_run_dir(out, info) == grid_run["run"]


@pytest.mark.liggghts
def test_a_loop_at_another_speed_runs_its_own_from_the_grid_bed(tiny_config, grid_run, tmp_path):
    """At a speed the grid does not run, the grid run is not the interval's plan (another speed):
    interval 0 runs LIGGGHTS itself, from the grid's settled bed of the feed (the settling does not
    depend on the speed), and counts the bed's time as its own."""
    out = tmp_path / "pbm_dem"
    coupling.pbm_dem(_loop(tiny_config), OTHER_RPM, out, grid_run["execution"], 0, grid_run["run"], grid_run["bed"])
    rows = pd.read_csv(out / "intervals.csv")
    assert "dem_borrowed_run" not in rows or rows.dem_borrowed_run.isna().all()
    run = out / "interval_00" / "dem"
    dem = read_json(run / "summary.json", "interval run")
    assert dem["from_settled_bed"] and dem["rpm"] == OTHER_RPM
    assert rows.dem_settled_bed[0] == str(grid_run["bed"])
    assert rows.dem_borrowed_wall_time_s[0] == pytest.approx(dem["bed_liggghts_wall_time_s"])
    assert rows.dem_cpu_time_s[0] == pytest.approx(dem["liggghts_cpu_time_s"] + dem["bed_liggghts_cpu_time_s"])
    assert rows.dem_reused_from_interval[1] == 0


@pytest.mark.liggghts
def test_a_plan_the_grid_run_does_not_cover_is_not_borrowed(tiny_config, grid_run, tmp_path):
    """covers() holds the grid run's plan to the interval's: another replicate (seeds), another speed
    or a longer sampling window than the grid's is not covered, a shorter window is. A loop of
    replicate 1 handed replicate 0's run and bed runs and settles its own."""
    point = tiny_config.dem_point(tiny_config.validation.distribution)
    plan = plan_point(point, GRID_RPM, replicate=0)
    assert covers(grid_run["run"], plan) == ""
    shorter = dataclasses.replace(plan, sampling_steps=plan.sampling_steps - plan.position_interval)
    assert covers(grid_run["run"], shorter) == ""
    longer = dataclasses.replace(plan, sampling_steps=plan.sampling_steps + plan.position_interval)
    assert "sampling_steps" in covers(grid_run["run"], longer)
    assert "replicate" in covers(grid_run["run"], plan_point(point, GRID_RPM, replicate=1))
    assert "rpm" in covers(grid_run["run"], plan_point(point, OTHER_RPM, replicate=0))
    assert "no finished run" in covers(tmp_path, plan)

    out = tmp_path / "rep1"
    coupling.pbm_dem(_loop(tiny_config), GRID_RPM, out, grid_run["execution"], 1, grid_run["run"], grid_run["bed"])
    rows = pd.read_csv(out / "intervals.csv")
    assert "dem_borrowed_run" not in rows or rows.dem_borrowed_run.isna().all()
    assert "dem_settled_bed" not in rows or rows.dem_settled_bed.isna().all()
    dem = read_json(out / "interval_00" / "dem" / "summary.json", "interval run")
    assert not dem["from_settled_bed"] and dem["replicate"] == 1


def test_the_dry_run_estimate_counts_the_borrowed_intervals(default_config, tmp_path):
    """The default validation loops (3 replicates at 300, 750, 900 and 1200 rpm, fine feed): the
    first interval at the grid speeds 300 and 1200 borrows the grid's run (6 LIGGGHTS calls fewer),
    at 750 and 900 it starts from the grid's settled bed (its settling not counted)."""
    cfg = default_config
    loops = [(rpm, rep) for rpm in cfg.validation.rpm for rep in range(cfg.validation.dem_replicates)]
    estimate = study_estimate(cfg, [], loops, tmp_path)  # no runs.csv there: the reference throughput
    rate, loop = measured_throughput(None), cfg.coupled_loop()
    expected = 0.0
    for rpm, rep in loops:
        plan = plan_point(loop.dem_point(), rpm, replicate=rep)
        one = rate.seconds(plan.particle_steps, plan.n_particles)
        if rpm in cfg.grid.impeller_rpm:  # borrowed: the first interval costs nothing
            expected += (loop.coupling_intervals - 1) * one
        else:  # the first interval without its settling
            expected += loop.coupling_intervals * one - rate.seconds(
                plan.n_particles * plan.settle_steps, plan.n_particles
            )
    assert estimate.borrowed_intervals == 6 and estimate.loop_intervals == len(loops) * loop.coupling_intervals
    assert estimate.loop_seconds == pytest.approx(expected, rel=1e-12)
    assert "6 borrow the grid's run of their feed" in estimate.text()
