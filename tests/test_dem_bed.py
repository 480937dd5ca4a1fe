"""One settled bed for every speed, with the real LIGGGHTS engine on the tiny granulator."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from pbmdem.config import ConfigError
from pbmdem.dem import engine
from pbmdem.dem.dumps import read_classes
from pbmdem.dem.plan import plan_bed, plan_point
from pbmdem.dem.run import BED_FILE, BED_RECORD, check_bed, run_point, settle_bed

BENCHMARKS = str(Path(__file__).resolve().parents[1] / "benchmarks")
sys.path.insert(0, BENCHMARKS)  # loop_times lives with the DEM benchmark
try:
    from bench_dem import loop_times
finally:
    sys.path.remove(BENCHMARKS)

pytestmark = pytest.mark.liggghts

SPEEDS = (600, 1200)


@pytest.fixture(scope="module")
def bed_runs(tiny_config, tmp_path_factory):
    """A settled bed, runs at two speeds from it, and a fresh run that settles its own bed."""
    root = tmp_path_factory.mktemp("bed")
    point = tiny_config.dem_point("small")
    execution = tiny_config.dem_execution
    bed = plan_bed(point, replicate=0)
    record = settle_bed(bed, root / "bed", execution)
    plans = {rpm: plan_point(point, rpm) for rpm in SPEEDS}
    for rpm, plan in plans.items():
        run_point(plan, root / f"rpm{rpm}", execution, bed_dir=root / "bed")
    run_point(plans[SPEEDS[0]], root / "fresh", execution)
    return {"root": root, "point": point, "bed": bed, "record": record, "plans": plans}


def _classes(run_dir):
    """Particle ids and classes of a run, sorted by id (a dump lists them in memory order)."""
    ids, classes = read_classes(run_dir / "post" / "classes.dump")
    order = np.argsort(ids)
    return ids[order], classes[order]


def _first_thermo(log):
    table = engine.thermo_table(log)
    return {k: table[k][0] for k in ("Step", "Atoms", "KinEng")}


def test_a_settled_bed_holds_the_particles_and_classes_of_a_fresh_run(bed_runs):
    root, bed = bed_runs["root"], bed_runs["bed"]
    assert (root / "bed" / BED_FILE).stat().st_size > 0
    record = json.loads((root / "bed" / BED_RECORD).read_text())
    assert record["bed"]["n_particles"] == bed.n_particles
    # the bed ends at the planned settling step with every particle inserted
    last = engine.thermo_table(root / "bed" / "log.liggghts")
    assert last["Step"][-1] == bed.settle_steps
    assert last["Atoms"][-1] == bed.n_particles
    ids_fresh, classes_fresh = _classes(root / "fresh")
    for rpm in SPEEDS:
        ids, classes = _classes(root / f"rpm{rpm}")
        assert len(ids) == bed.n_particles
        np.testing.assert_array_equal(ids, ids_fresh)
        np.testing.assert_array_equal(classes, classes_fresh)
    assert np.bincount(classes_fresh, minlength=len(bed.counts)).sum() == bed.n_particles


def test_a_run_from_the_bed_is_the_run_that_settles_its_own(bed_runs):
    """The restart is exact: from the same seeds, a run from the settled bed and a run that settles
    its own bed give the same collision tables, to the last count."""
    root = bed_runs["root"]
    for name in ("collisions.csv", "wall_collisions.csv", "impact_velocity.csv"):
        from_bed = (root / f"rpm{SPEEDS[0]}" / name).read_text()
        fresh = (root / "fresh" / name).read_text()
        assert from_bed == fresh, name


def test_runs_at_two_speeds_from_one_bed_differ_only_in_the_speed(bed_runs):
    root, bed, plans = bed_runs["root"], bed_runs["bed"], bed_runs["plans"]
    settled = engine.thermo_table(root / "bed" / "log.liggghts")
    end_of_bed = {"Step": settled["Step"][-1], "Atoms": settled["Atoms"][-1], "KinEng": settled["KinEng"][-1]}
    for rpm in SPEEDS:
        # each run starts where the bed ended: same step, same particles, same kinetic energy
        assert _first_thermo(root / f"rpm{rpm}" / "log.liggghts") == pytest.approx(end_of_bed)
        summary = json.loads((root / f"rpm{rpm}" / "summary.json").read_text())
        assert summary["from_settled_bed"] is True
        assert summary["run_steps"] == plans[rpm].spinup_steps + plans[rpm].sampling_steps
        assert not (root / f"rpm{rpm}" / BED_FILE).exists()  # the copy is removed, the bed stays
    # the two plans share the bed; what differs follows from the speed alone
    a, b = (plans[rpm].to_dict() for rpm in SPEEDS)
    assert plans[SPEEDS[0]].bed == plans[SPEEDS[1]].bed == bed
    speed_fields = {"point_id", "rpm", "tip_speed", "omega", "contact_time", "collision_interval", "position_interval"}
    speed_fields |= {"spinup_steps", "sampling_steps", "history_steps", "sampling_time"}
    assert {k for k in a if a[k] != b[k]} <= speed_fields
    assert a["rpm"] != b["rpm"]
    # and the two runs' flows differ (the impeller turned at different speeds)
    enc = [json.loads((root / f"rpm{rpm}" / "summary.json").read_text())["total_encounters"] for rpm in SPEEDS]
    assert enc[0] != enc[1]


def test_a_run_refuses_a_bed_that_is_not_its_own(bed_runs, tiny_config):
    root, point = bed_runs["root"], bed_runs["point"]
    other = plan_point(point, 600, replicate=1)  # other insertion seeds: another bed
    with pytest.raises(ConfigError, match=r"bed\.json: bed\.replicate = 0, but the run rpm600_small \(replicate 1\)"):
        check_bed(other, root / "bed")
    softer = point.replace(material=point.material.replace(youngs_modulus=0.5 * point.material.youngs_modulus))
    with pytest.raises(ConfigError, match=r"bed\.json: bed\.timestep"):
        check_bed(plan_point(softer, 600), root / "bed")


def test_the_logs_time_each_phase(bed_runs):
    """loop_times (benchmarks/bench_dem.py) reads LIGGGHTS' timing block of every `run`: the bed's settling, and the
    spin-up and the recording (history and sampling window) of a run from the bed."""
    root, bed, plans = bed_runs["root"], bed_runs["bed"], bed_runs["plans"]
    (settling,) = loop_times(root / "bed" / "log.liggghts")
    assert settling["steps"] == bed.settle_steps
    for rpm in SPEEDS:
        plan = plans[rpm]
        spinup, record = loop_times(root / f"rpm{rpm}" / "log.liggghts")
        assert spinup["steps"] == plan.spinup_steps - plan.history_steps
        assert record["steps"] == plan.history_steps + plan.sampling_steps
        for block in (spinup, record):
            assert block["wall"] > 0 and block["Pair"] > 0
            assert sum(block.get(k, 0.0) for k in ("Pair", "Neigh", "Comm", "Outpt", "Other")) <= 1.01 * block["wall"]
    fresh = loop_times(root / "fresh" / "log.liggghts")
    assert [b["steps"] for b in fresh][0] == bed.settle_steps and len(fresh) == 3


def test_a_bed_that_fails_leaves_its_crash_record_and_no_bed(tiny_config, tmp_path, monkeypatch):
    """LIGGGHTS stops with an error in the bed's deck: the job fails naming the bed folder, which
    holds crash.json and the log, and no bed.json (so no run can start from it)."""
    import sys

    real = engine.executable()
    wrapper = tmp_path / "liggghts-broken"
    wrapper.write_text(
        f"#!{sys.executable}\n"
        "import os, sys\n"
        "args = sys.argv[1:]\n"
        "deck = args[args.index('-in') + 1]\n"
        "text = open(deck).read().replace('write_restart', 'fix broken all no/such/style\\nwrite_restart')\n"
        "open('broken.in', 'w').write(text)\n"
        "args[args.index('-in') + 1] = 'broken.in'\n"
        f"os.execv({real!r}, [{real!r}, *args])\n"
    )
    wrapper.chmod(0o755)
    monkeypatch.setenv("PBMDEM_LIGGGHTS", str(wrapper))
    point = tiny_config.dem_point("small")
    bed_dir = tmp_path / "bed"
    with pytest.raises(engine.LiggghtsError, match=str(bed_dir)):
        settle_bed(plan_bed(point), bed_dir, tiny_config.dem_execution)
    crash = json.loads((bed_dir / "crash.json").read_text())
    assert "no/such/style" in crash["log_tail"]
    assert not (bed_dir / BED_RECORD).exists() and not (bed_dir / BED_FILE).exists()
    assert not list(tmp_path.glob(".*staging"))
