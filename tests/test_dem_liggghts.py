"""The DEM stage with the real LIGGGHTS engine on the tiny granulator (no mocks)."""

import dataclasses
import json
import stat
import sys
import textwrap

import numpy as np
import pandas as pd
import pytest

from pbmdem.dem import collisions, deck, engine
from pbmdem.dem.collisions import aggregate
from pbmdem.dem.plan import plan_point
from pbmdem.dem.run import run_point

pytestmark = pytest.mark.liggghts


def test_tiny_run_counts_collisions_for_every_class_pair(tiny_run):
    run_dir, plan = tiny_run["dir"], tiny_run["plan"]
    table = pd.read_csv(run_dir / "collisions.csv")
    k = len(plan.diameters)
    assert len(table) == k * (k + 1) // 2
    assert (table["collisions"] > 0).all(), table
    assert (table["frequency_per_pair"] > 0).all()
    # class counts are the particles actually in the bowl: exactly the planned bed
    per_class = table.loc[table.class_i == table.class_j, "n_i"].to_numpy()
    np.testing.assert_array_equal(per_class, plan.counts)
    assert per_class.sum() == plan.n_particles
    # per-pair normalisation as documented
    row = table.iloc[1]
    assert row.frequency_per_pair == pytest.approx(row.collisions / (row.n_i * row.n_j * row.sampling_time))
    walls = pd.read_csv(run_dir / "wall_collisions.csv")
    assert set(walls["wall"]) == {"bowl", "impeller"}
    assert walls.loc[walls.wall == "impeller", "collisions"].sum() > 0


def test_tiny_run_summary_and_timestep_check(tiny_run):
    summary = json.loads((tiny_run["dir"] / "summary.json").read_text())
    assert summary["n_particles"] == tiny_run["plan"].n_particles
    assert summary["particle_steps_per_s"] > 0
    assert summary["total_collisions"] > 0
    # LIGGGHTS' own check (fix check/timestep/gran) finds dt at the planned fraction of the
    # Rayleigh time of the smallest particle, and well below the Hertz time at the speeds reached
    frac = tiny_run["config"].dem.timestep_fraction
    assert summary["dt_over_rayleigh_time"] == pytest.approx(frac, rel=0.01)
    assert 0 < summary["dt_over_hertz_time_max"] < 0.2


def test_halving_the_snapshot_interval_changes_encounters_by_less_than_5_percent(tiny_run, tiny_config, tmp_path):
    """Run with contact and position snapshots at half the automatic intervals; using every second
    snapshot is then exactly the automatic intervals, so the two counts compare interval h and h/2
    on one trajectory."""
    auto = tiny_run["plan"].collision_interval
    assert auto >= 2
    point = tiny_config.dem_point("small")
    point = point.replace(
        dem=point.dem.replace(collision_interval=auto // 2, keep_contact_dumps=True, sampling_time=0.03)
    )
    plan = plan_point(point, 1200)
    run_point(plan, tmp_path, tiny_config.dem_execution)
    analysis = collisions.RunAnalysis(tmp_path / "post", plan)
    fine = analysis.pair_events(stride=1)[0].encounter.sum()
    coarse = analysis.pair_events(stride=2)[0].encounter.sum()
    assert fine > 200
    assert abs(coarse - fine) / fine < 0.05, (fine, coarse)


def test_encounters_are_fewer_than_new_contacts_and_have_impact_velocities(tiny_run):
    table = pd.read_csv(tiny_run["dir"] / "collisions.csv")
    assert (table["encounters"] > 0).all()
    assert (table["encounters"] < table["collisions"]).all()  # re-touches are not encounters
    assert ((table["impact_velocity_median"] > 0) & (table["impact_velocity_median"] < 10.0)).all()
    velocities = pd.read_csv(tiny_run["dir"] / "impact_velocity.csv")
    per_pair = velocities.groupby(["class_i", "class_j"])["encounters"].sum().to_numpy()
    np.testing.assert_array_equal(per_pair, table["encounters"].to_numpy())
    walls = pd.read_csv(tiny_run["dir"] / "wall_collisions.csv")
    assert (walls["encounters"] <= walls["collisions"]).all()
    assert walls.loc[walls.wall == "impeller", "encounters"].sum() > 0


def test_replicates_differ_only_by_seed_and_aggregate_to_mean_and_se(tiny_run, tiny_config, tmp_path):
    point = tiny_config.dem_point("small")
    plans = [plan_point(point, 600, replicate=r) for r in range(3)]
    base = dataclasses.asdict(plans[0])
    for plan in plans[1:]:
        other = dataclasses.asdict(plan)
        # the replicate and its seeds (dem.seed's and the LIGGGHTS primes the plan derives from it)
        seeds = {"seed", "template_seeds", "distribution_seeds", "insertion_seeds"}
        assert {k for k in base if base[k] != other[k]} == {"replicate", *seeds}
    decks = [deck.granulator_values(p, ranks=1) for p in plans]
    assert {k for k in decks[0] if decks[0][k] != decks[1][k]} <= {"insertion_block", "particle_templates_block"}
    tables = [tiny_run["dir"] / "collisions.csv"]
    for plan in plans[1:]:
        run_dir = tmp_path / f"rep{plan.replicate}"
        run_point(plan, run_dir, tiny_config.dem_execution)
        tables.append(run_dir / "collisions.csv")
    runs = [pd.read_csv(t) for t in tables]
    assert [int(r["replicate"].iloc[0]) for r in runs] == [0, 1, 2]
    assert not runs[0]["encounters"].equals(runs[1]["encounters"])  # other seeds, other realisation
    grid = aggregate(tables, tmp_path / "grid.csv")
    f = np.stack([r["encounter_frequency_per_pair"].to_numpy() for r in runs])
    np.testing.assert_allclose(grid["encounter_frequency_per_pair"], f.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(grid["encounter_frequency_per_pair_se"], f.std(axis=0, ddof=1) / np.sqrt(3), rtol=1e-12)
    assert (grid["n_replicates"] == 3).all()


def test_vtk_series_is_written_and_readable(tiny_run):
    pyvista = pytest.importorskip("pyvista")
    post = tiny_run["dir"] / "post"
    assert (post / "particles.pvd").exists() and (post / "impeller.pvd").exists()
    reader = pyvista.get_reader(str(post / "particles.pvd"))
    assert len(reader.time_values) >= 3
    reader.set_active_time_value(reader.time_values[-1])
    block = reader.read()
    mesh = block[0] if isinstance(block, pyvista.MultiBlock) else block
    assert mesh.n_points == tiny_run["plan"].n_particles
    for name in ("radius", "type", "id"):
        assert name in mesh.point_data
    imp = pyvista.read(sorted(post.glob("impeller_*.vtk"))[-1])
    assert imp.n_cells > 0


def _failing_liggghts(tmp_path):
    """A wrapper around the real engine that cuts the sampling phase short with an unknown fix
    style, so that the real LIGGGHTS fails in the middle of sampling (after writing part of its
    contact dumps)."""
    real = engine.executable()
    script = tmp_path / "liggghts-broken"
    script.write_text(
        textwrap.dedent(f"""\
        #!{sys.executable}
        import os, sys
        args = sys.argv[1:]
        deck = args[args.index("-in") + 1]
        lines = open(deck).read().splitlines()
        last_run = max(i for i, line in enumerate(lines) if line.startswith("run "))
        lines[last_run] = "run 50\\nfix broken all no/such/style"
        open("broken.in", "w").write("\\n".join(lines) + "\\n")
        args[args.index("-in") + 1] = "broken.in"
        os.execv({real!r}, [{real!r}, *args])
        """)
    )
    script.chmod(script.stat().st_mode | stat.S_IEXEC)
    return script


def test_a_failing_run_reports_the_log_and_leaves_no_table(tiny_config, tmp_path, monkeypatch):
    monkeypatch.setenv("PBMDEM_LIGGGHTS", str(_failing_liggghts(tmp_path)))
    point = tiny_config.dem_point("large")
    plan = plan_point(point, 600)
    run_dir = tmp_path / "run"
    with pytest.raises(engine.LiggghtsError) as info:
        run_point(plan, run_dir, tiny_config.dem_execution)
    msg = str(info.value)
    assert "ERROR" in msg and "no/such/style" in msg  # the tail of the log is in the message
    assert not (run_dir / "collisions.csv").exists()
    assert not (run_dir / "wall_collisions.csv").exists()
    crash = json.loads((run_dir / "crash.json").read_text())
    assert crash["problems"] and "no/such/style" in crash["log_tail"]
    assert (run_dir / "post" / "pairs.dump").stat().st_size > 0  # it really failed mid-sampling


def test_missing_engine_gives_install_hint(monkeypatch):
    monkeypatch.setenv("PBMDEM_LIGGGHTS", "liggghts-that-does-not-exist")
    with pytest.raises(engine.LiggghtsError, match="apt-get install --no-install-recommends liggghts"):
        engine.executable()


def test_insertion_shortfall_is_an_error(tiny_config, tmp_path):
    """A bed that cannot be inserted in the settling time must not yield a table with a wrong PSD."""
    point = tiny_config.dem_point("small")
    point = point.replace(dem=point.dem.replace(settle_time=0.004))  # far too short to drop ~400 particles
    plan = plan_point(point, 600)
    with pytest.raises(engine.LiggghtsError, match="insertion did not place them all") as err:
        run_point(plan, tmp_path, tiny_config.dem_execution)
    inserted = json.loads((tmp_path / "crash.json").read_text())["inserted_counts"]
    assert sum(inserted) < plan.n_particles
    for k, (planned, got) in enumerate(zip(plan.counts, inserted)):
        assert (f"class {k}: {planned} particles planned, {got} inserted" in str(err.value)) == (planned != got)
    assert not (tmp_path / "collisions.csv").exists()


def test_dem_cli_plan_only(root, capsys):
    from pbmdem.cli import main

    assert (
        main(
            [
                "dem",
                "--config",
                str(root / "config" / "test.yaml"),
                "--rpm",
                "600",
                "--distribution",
                "small",
                "--plan-only",
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["point_id"] == "rpm600_small" and out["n_particles"] > 100
    assert (
        main(
            [
                "dem",
                "--config",
                str(root / "config" / "test.yaml"),
                "--rpm",
                "600",
                "--distribution",
                "nope",
                "--plan-only",
            ]
        )
        == 2
    )
    assert "'nope' is not defined" in capsys.readouterr().err


def test_two_mpi_ranks(tiny_config, tmp_path):
    """The same deck under `mpirun -np 2` (as on a cluster): domain split along x, same bed."""
    point = tiny_config.dem_point("small")
    plan = plan_point(point, 600)
    summary = run_point(plan, tmp_path, tiny_config.dem_execution.replace(mpi_ranks=2))
    assert "processors      2 1 1" in (tmp_path / "in.granulator").read_text()
    assert "2 by 1 by 1 MPI processor grid" in (tmp_path / "log.liggghts").read_text()
    table = pd.read_csv(tmp_path / "collisions.csv")
    assert summary["n_particles"] == plan.n_particles and summary["mpi_ranks"] == 2
    assert (table.collisions > 0).all()


def _retype(classes_dump, moves: dict[int, int]) -> None:
    """Rewrite the class map: the first `n` particles of atom type `t` become type 1 (`moves`: t -> n)."""
    lines = classes_dump.read_text().splitlines(keepends=True)
    start = next(k for k, line in enumerate(lines) if line.startswith("ITEM: ATOMS")) + 1
    for k in range(start, len(lines)):
        words = lines[k].split()
        if len(words) == 3 and moves.get(int(words[1]), 0) > 0:
            moves[int(words[1])] -= 1
            lines[k] = f"{words[0]} 1 {words[2]}\n"
    assert not any(moves.values())
    classes_dump.write_text("".join(lines))


def test_a_bed_other_than_the_planned_one_fails_the_run(tiny_run, tmp_path):
    """The real tiny run holds exactly its planned counts and passes; its class map rewritten to
    the counts the former deck (one insertion fix over all classes) inserted for this bed, measured
    with LIGGGHTS: [232, 137, 91] for the plan's [230, 138, 92] (the same total), fails the run
    naming the folder and each class that differs."""
    import shutil

    from pbmdem.dem.run import check_finished

    plan = tiny_run["plan"]
    assert plan.counts == [230, 138, 92]
    run = tmp_path / "other_bed"
    shutil.copytree(tiny_run["dir"], run)
    check_finished(plan, run)
    _retype(run / "post" / "classes.dump", {2: 1, 3: 1})
    with pytest.raises(engine.LiggghtsError) as err:
        check_finished(plan, run)
    text = str(err.value)
    assert str(run) in text
    assert "class 0: 230 particles planned, 232 inserted" in text
    assert "class 1: 138 particles planned, 137 inserted" in text
    assert "class 2: 92 particles planned, 91 inserted" in text
    crash = json.loads((run / "crash.json").read_text())
    assert crash["planned_counts"] == [230, 138, 92] and crash["inserted_counts"] == [232, 137, 91]
