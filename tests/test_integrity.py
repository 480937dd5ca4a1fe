"""Data integrity: bad values are refused with a message naming the file or key and the value,
before anything is deleted; finished runs are never lost or silently rewritten."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from conftest import config_of, snakemake_command

from pbmdem.config import ConfigError, load_config, point_id, rpm_text
from pbmdem.config.describe import config_schema
from pbmdem.dem import collisions, dumps, engine
from pbmdem.dem.collisions import aggregate, run_table
from pbmdem.dem.plan import plan_point
from pbmdem.dem.run import FinishedRunError, is_finished, prepare_run, run_point


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _snakemake(workdir: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        snakemake_command(workdir, *args),
        capture_output=True,
        text=True,
        timeout=600,
    )


# ----------------------------------------------------------------------------- defect 4: duplicate keys
def test_duplicate_key_in_a_config_file_is_refused_with_key_and_line(root, tmp_path):
    text = (root / "config" / "test.yaml").read_text().replace("  seed: 20141\n", "  seed: 20141\n  seed: 7\n")
    path = _write(tmp_path / "dup.yaml", text)
    line = text.splitlines().index("  seed: 7") + 1
    with pytest.raises(ConfigError) as info:
        load_config(path)
    msg = str(info.value)
    assert str(path) in msg and "duplicate key 'seed'" in msg and f"line {line}" in msg


def test_snakemake_refuses_a_duplicate_key(root, tmp_path):
    text = (root / "config" / "test.yaml").read_text().replace("  seed: 20141\n", "  seed: 20141\n  seed: 7\n")
    path = _write(tmp_path / "dup.yaml", text)
    proc = _snakemake(tmp_path, "--configfile", str(path), "-n", "--cores", "1")
    assert proc.returncode != 0
    assert "duplicate key 'seed'" in proc.stderr and "Traceback" not in proc.stderr


# ----------------------------------------------------------------------------- defect 3: non-finite numbers
@pytest.mark.parametrize(
    "text, key", [(".nan", "material.restitution"), (".inf", "material.restitution"), ("-.inf", "material.restitution")]
)
def test_non_finite_config_values_name_key_and_value(root, tmp_path, text, key):
    cfg_text = (root / "config" / "test.yaml").read_text().replace("restitution: 0.4", f"restitution: {text}")
    path = _write(tmp_path / "bad.yaml", cfg_text)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    msg = str(info.value)
    assert key in msg and repr(float(text.replace(".", ""))) in msg and str(path) in msg


def test_nan_speed_in_the_grid_is_refused(tiny_mapping):
    tiny_mapping["grid"]["impeller_rpm"] = [600, float("nan")]
    with pytest.raises(ConfigError, match=r"grid\.impeller_rpm\[1\] = nan"):
        config_of(tiny_mapping)


@pytest.mark.parametrize("rpm", ["0", "inf", "nan", "-5", "1e9", "fast"])
def test_impossible_cli_speeds_are_refused_and_leave_a_finished_run_alone(tiny_run, tmp_path, root, capsys, rpm):
    """Defect 2 and 3: an impossible speed with --out at a finished run is refused, the run untouched."""
    from pbmdem.cli import main

    run = tmp_path / "run"
    shutil.copytree(tiny_run["dir"], run)
    before = {p: (p.stat().st_mtime_ns, p.stat().st_size) for p in run.rglob("*")}
    code = main(
        [
            "dem",
            "--config",
            str(root / "config" / "test.yaml"),
            "--rpm",
            rpm,
            "--distribution",
            "small",
            "--out",
            str(run),
            "--force",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2
    assert "--rpm" in err and repr(rpm) in err and "Traceback" not in err
    assert {p: (p.stat().st_mtime_ns, p.stat().st_size) for p in run.rglob("*")} == before


@pytest.mark.parametrize("rpm", ["0", "inf", "nan"])
def test_impossible_speed_for_the_pbm_cli(root, tmp_path, capsys, rpm):
    from pbmdem.cli import main

    code = main(["pbm", "--config", str(root / "config" / "test.yaml"), "--rpm", rpm, "--out", str(tmp_path / "o")])
    assert code == 2 and "--rpm" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def _dump(path: Path, rows: list[str]) -> Path:
    text = (
        f"ITEM: TIMESTEP\n100\nITEM: NUMBER OF ENTRIES\n{len(rows)}\nITEM: BOX BOUNDS ff ff ff\n"
        "-0.01 0.01\n-0.01 0.01\n0 0.03\nITEM: ENTRIES c_1 c_2 c_3\n"
    )
    return _write(path, text + "".join(r + "\n" for r in rows))


@pytest.mark.parametrize(
    "rows, col", [(["1 2 0.001", "nan 3 0.002"], 1), (["1 2 0.001", "2 3 nan"], 3), (["1 2 inf", "2 3 0.002"], 3)]
)
def test_non_finite_value_in_a_dump_names_file_and_column(tmp_path, rows, col):
    path = _dump(tmp_path / "pairs.dump", rows)
    with pytest.raises(dumps.DumpFormatError) as info:
        dumps.read_dump(path, 3)
    msg = str(info.value)
    assert str(path) in msg and f"column {col}" in msg and "step 100" in msg
    assert "nan" in msg or "inf" in msg


def test_nan_in_a_real_contact_dump_fails_the_tabulation(tiny_run, tmp_path):
    """A NaN overlap in LIGGGHTS' own pair dump must not silently change the count."""
    post = tmp_path / "post"
    shutil.copytree(tiny_run["dir"] / "post", post)
    lines = (post / "pairs.dump").read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if len(line.split()) == 3 and not line.startswith("ITEM"))
    parts = lines[k].split()
    lines[k] = f"{parts[0]} {parts[1]} nan"
    (post / "pairs.dump").write_text("\n".join(lines) + "\n")
    with pytest.raises(dumps.DumpFormatError, match="pairs.dump: non-finite value nan in column 3"):
        collisions.tabulate_run(post, tiny_run["plan"])


# ----------------------------------------------------------------------------- defect 5: operating-point ids
def test_every_allowed_speed_gives_an_id_the_rule_wildcard_accepts(root):
    snakefile = (root / "Snakefile").read_text()
    wildcard = re.search(r'rpm=r"([^"]+)"', snakefile).group(1)
    limits = config_schema()["$defs"]["OperatingGrid"]["properties"]["impeller_rpm"]["items"]
    assert limits["exclusiveMinimum"] == 0
    speeds = [1e-9, 1.5e-7, 0.1 + 0.2, 0.5, 1, 600, 1234.567, 1234.5678901, 19999.999999, limits["maximum"]]
    ids = set()
    for rpm in speeds:
        text = rpm_text(rpm)
        assert re.fullmatch(wildcard, text), (rpm, text)
        assert float(text) == float(rpm)  # the rule reads the speed back from the wildcard
        ids.add(point_id(rpm, "fine"))
    assert len(ids) == len(speeds)  # close speeds never share a run folder
    assert point_id(600.0, "fine") == "rpm600_fine"


def test_snakemake_plans_a_tiny_speed(root, tmp_path, tiny_mapping):
    cfg = tiny_mapping
    cfg["grid"]["impeller_rpm"] = [1e-9, 1234.567]
    path = _write(tmp_path / "c.yaml", yaml.safe_dump(cfg))
    proc = _snakemake(tmp_path, "--configfile", str(path), "-n", "--cores", "1", "results/dem/collisions.csv")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "rpm0.000000001_small" in proc.stdout + proc.stderr
    assert "rpm1234.567_large" in proc.stdout + proc.stderr


# ----------------------------------------------------------------------------- defect 10: tidy errors
def test_snakemake_lists_every_config_error_tidily(root, tmp_path, tiny_mapping):
    cfg = tiny_mapping
    cfg["material"]["restitution"] = 7.0
    cfg["material"]["density"] = "heavy"
    cfg["grid"]["impeller_rpm"] = [600, -3]
    cfg["dem"]["foo"] = 1
    path = _write(tmp_path / "bad.yaml", yaml.safe_dump(cfg))
    proc = _snakemake(tmp_path, "--configfile", str(path), "-n", "--cores", "1")
    assert proc.returncode != 0
    err = proc.stderr
    for key, value in (
        ("material.restitution", "7.0"),
        ("material.density", "'heavy'"),
        ("grid.impeller_rpm[1]", "-3"),
        ("dem", "'foo'"),
    ):
        assert key in err and value in err, (key, err)
    assert "allowed" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) < 15  # no schema or config dump
    assert not (tmp_path / "results").exists()


# ----------------------------------------------------------------------------- defects 2 and 8: finished runs
def _state(folder: Path) -> dict:
    return {p.relative_to(folder): (p.stat().st_mtime_ns, p.stat().st_size) for p in folder.rglob("*")}


def test_manual_run_refuses_to_rewrite_a_finished_point(tiny_run, tmp_path, root, capsys):
    from pbmdem.cli import main

    run = tmp_path / "rpm600_small"
    shutil.copytree(tiny_run["dir"], run)
    before = _state(run)
    code = main(
        [
            "dem",
            "--config",
            str(root / "config" / "test.yaml"),
            "--rpm",
            "600",
            "--distribution",
            "small",
            "--out",
            str(run),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "already holds a finished run" in err and "--force" in err
    assert _state(run) == before
    assert not list(tmp_path.glob(".*staging"))


def test_forced_run_that_fails_leaves_the_finished_run_untouched(tiny_run, tmp_path, root, monkeypatch, capsys):
    """Real LIGGGHTS, cut short mid-sampling: the finished run must survive a forced rerun that fails."""
    from test_dem_liggghts import _failing_liggghts

    from pbmdem.cli import main

    run = tmp_path / "rpm600_small"
    shutil.copytree(tiny_run["dir"], run)
    before = _state(run)
    monkeypatch.setenv("PBMDEM_LIGGGHTS", str(_failing_liggghts(tmp_path)))
    code = main(
        [
            "dem",
            "--config",
            str(root / "config" / "test.yaml"),
            "--rpm",
            "600",
            "--distribution",
            "small",
            "--out",
            str(run),
            "--force",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "no/such/style" in err and "untouched" in err
    assert _state(run) == before
    stage = tmp_path / ".rpm600_small.staging"
    assert (stage / "crash.json").exists() and not (stage / "collisions.csv").exists()


def test_forced_run_replaces_a_finished_point(tiny_config, tmp_path):
    """Real LIGGGHTS: --force swaps the new run in; stale products of the old one go, nothing else does."""
    point = tiny_config.dem_point("large")
    plan = plan_point(point, 1200)
    execution = tiny_config.dem_execution
    run = tmp_path / "run"
    run.mkdir()
    _write(run / "notes.txt", "the user's own file")
    _write(run / "crash.json", "{}")  # a stale crash of an earlier attempt
    _write(run / "summary.json", json.dumps({"old": True}))
    with pytest.raises(FinishedRunError):
        run_point(plan, run, execution)
    summary = run_point(plan, run, execution, force=True)
    assert json.loads((run / "summary.json").read_text()) == json.loads(json.dumps(summary))
    assert (run / "collisions.csv").exists() and not (run / "crash.json").exists()
    assert (run / "notes.txt").read_text() == "the user's own file"
    assert Path(summary["series_particles"]).parent == run / "post" and Path(summary["series_particles"]).exists()
    assert not list(tmp_path.glob(".*staging")) and not list(tmp_path.glob(".*replaced"))


# ----------------------------------------------------------------------------- defect 7: out-of-domain warnings
@pytest.fixture(scope="module")
def small_surrogate(tmp_path_factory):
    """A surrogate trained on synthetic tables at 300-900 rpm (so 5000 rpm is outside its domain)."""
    import warnings

    from synthetic_tables import make_synthetic_table

    from pbmdem.surrogate import CollisionSurrogate, EnsembleMLPRegressorCV, save_surrogate, training_data

    radius = 0.0265
    table = make_synthetic_table(radius, rpms=(300, 600, 900), diameters=(0.002, 0.0025, 0.003), seed=4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # convergence of this deliberately tiny fit is not the point
        data = training_data(table, radius)
        model = CollisionSurrogate(
            EnsembleMLPRegressorCV(
                hidden_layer_sizes=((4,),), alpha=(0.1,), seeds=(0, 1), max_iter=300, activation="tanh", solver="lbfgs"
            ),
            impeller_radius=radius,
            physics_offset="cross_section",
        )
        model.fit(data.X, data.y, groups=data.groups)
    path = tmp_path_factory.mktemp("surrogate") / "model.skops"
    save_surrogate(model, path)
    return path


def test_pbm_cli_with_the_ann_kernel_reports_out_of_domain_use(small_surrogate, root, tmp_path, capsys):
    from pbmdem.cli import main

    out = tmp_path / "pbm"
    code = main(
        [
            "pbm",
            "--config",
            str(root / "config" / "test.yaml"),
            "--kernel",
            "ann",
            "--model",
            str(small_surrogate),
            "--rpm",
            "5000",
            "--distribution",
            "small",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    err = capsys.readouterr().err
    assert "outside its training domain" in err and "tip_speed" in err  # 5000 rpm: tip speed far out
    info = json.loads((out / "run.json").read_text())
    n = info["coupling_intervals"]
    assert (
        info["surrogate_domain"]
        == {"out_of_domain_intervals": n, "out_of_domain_count": info["surrogate_domain"]["out_of_domain_count"]}
        and info["surrogate_domain"]["out_of_domain_count"] >= n > 0
    )
    intervals = __import__("pandas").read_csv(out / "intervals.csv")
    assert len(intervals) == n and intervals.out_of_domain.str.contains("tip_speed").all()


def test_validation_loops_log_count_and_report_out_of_domain_use(small_surrogate, tiny_config, tmp_path, caplog):
    import logging

    from pbmdem import coupling
    from pbmdem.report.statements import out_of_domain, out_of_domain_sentence
    from pbmdem.validation.comparison import domain_counts
    from pbmdem.validation.results import SpeedResults, load_run

    vdir = tmp_path / "validation"
    caplog.set_level(logging.INFO, logger="pbmdem")
    loop = tiny_config.coupled_loop()
    coupling.pbm_ann(loop, small_surrogate, 5000.0, vdir / "rpm5000" / "pbm_ann")
    coupling.pbm_constant(loop, small_surrogate, 5000.0, vdir / "rpm5000" / "pbm_constant")
    intervals = __import__("pandas").read_csv(vdir / "rpm5000" / "pbm_ann" / "intervals.csv")
    n = tiny_config.validation.coupling_intervals
    assert len(intervals) == n and (intervals.out_of_domain_count > 0).all()
    assert intervals.out_of_domain.str.contains("outside the training range").all()
    timing = json.loads((vdir / "rpm5000" / "pbm_ann" / "timing.json").read_text())
    assert timing["out_of_domain_intervals"] == n
    constant = json.loads((vdir / "rpm5000" / "pbm_constant" / "timing.json").read_text())
    assert constant["out_of_domain_count"] > 0
    text = caplog.text
    assert "surrogate out of its training domain" in text  # logged as they happen
    assert f"interval {n} of {n}" in text and "PBM wall time" in text and "out-of-domain" in text
    speed = SpeedResults(
        "5000",
        [],
        load_run(vdir / "rpm5000" / "pbm_ann", "PBM-ANN result"),
        load_run(vdir / "rpm5000" / "pbm_constant", "PBM-constant result"),
        None,
    )
    counts = domain_counts(speed)
    assert counts["ann_out_of_domain_intervals"] == n and counts["constant_calibration_out_of_domain_warnings"] > 0
    statement = out_of_domain_sentence("5000", out_of_domain(speed))
    assert "outside its training domain" in statement and f"in {n} of {n} coupling intervals" in statement
    assert "calibration sample was outside it" in statement


# ----------------------------------------------------------------------------- defect 9: resume after kill -9
def test_the_readme_resume_command_works_after_kill_9_of_snakemake(root, tmp_path, tiny_mapping):
    """kill -9 Snakemake while a (real) LIGGGHTS job runs; the README's exact command resumes."""
    import signal
    import stat
    import textwrap
    import time

    readme = (root / "README.md").read_text()
    assert "`.venv/bin/snakemake --unlock && .venv/bin/snakemake --cores 2`" in readme
    cfg = tiny_mapping
    cfg["grid"]["impeller_rpm"] = [600]
    config = _write(tmp_path / "c.yaml", yaml.safe_dump(cfg))
    started = tmp_path / "started"
    slow = tmp_path / "liggghts-slow"
    real = engine.executable()
    slow.write_text(
        textwrap.dedent(f"""\
        #!{sys.executable}
        import os, sys, time
        open({str(started)!r}, "a").write(f"{{os.getpid()}}\\n")
        time.sleep(600)
        os.execv({real!r}, [{real!r}, *sys.argv[1:]])
        """)
    )
    slow.chmod(slow.stat().st_mode | stat.S_IEXEC)
    base = snakemake_command(tmp_path, configfile=config)
    target = "results/dem/collisions.csv"
    proc = subprocess.Popen(
        [*base, "--cores", "1", target],
        env=dict(os.environ, PBMDEM_LIGGGHTS=str(slow)),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 300
        while not started.exists() and time.monotonic() < deadline:
            time.sleep(0.5)
        assert started.exists(), "no LIGGGHTS job started"
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        for pid in started.read_text().split() if started.exists() else []:
            try:
                os.kill(int(pid), signal.SIGKILL)
            except ProcessLookupError:
                pass
    blocked = subprocess.run([*base, "--cores", "1", target], capture_output=True, text=True, timeout=600)
    assert blocked.returncode != 0 and "cannot be locked" in blocked.stdout + blocked.stderr
    # the README's command (with the target of this test)
    unlock = subprocess.run([*base, "--unlock"], capture_output=True, text=True, timeout=600)
    assert unlock.returncode == 0, unlock.stderr[-2000:]
    resumed = subprocess.run([*base, "--cores", "1", target], capture_output=True, text=True, timeout=900)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert "workflow specific profile" in resumed.stderr  # profiles/default was read
    table = __import__("pandas").read_csv(tmp_path / target)
    assert set(table.point_id) == {"rpm600_small", "rpm600_large"}


# ----------------------------------------------------------------------------- progress of DEM jobs
def test_dem_progress_is_read_from_liggghts_thermo_while_it_runs(tiny_config, tmp_path, caplog, capsys):
    """Real LIGGGHTS: the progress reader sees the run move through its phases while it runs."""
    import logging

    from pbmdem.dem.progress import ThermoProgress

    point = tiny_config.dem_point("small")
    point = point.replace(dem=point.dem.replace(vtk_interval=0.002))  # ~60 thermo lines: less than a stdio buffer
    plan = plan_point(point, 600)
    deck = prepare_run(plan, tmp_path, ranks=1)
    seen = []

    class Recording(ThermoProgress):
        def update(self):
            super().update()
            seen.append((self.step, self.phase(), self.atoms))

    phases = [("settling", plan.settle_steps), ("spin-up", plan.spinup_steps), ("sampling", plan.sampling_steps)]
    caplog.set_level(logging.INFO, logger="pbmdem.dem.progress")
    progress = Recording(tmp_path / "log.liggghts", phases, label="DEM test", bar=True, log_every=0.0)
    engine.run(deck, tmp_path, timeout=600, progress=progress, poll=0.02)
    total = plan.settle_steps + plan.spinup_steps + plan.sampling_steps
    steps = [s for s, _, _ in seen]
    assert steps == sorted(steps) and steps[-1] == total  # the last thermo line is the last step
    running = {s for s in steps[:-1] if 0 < s < total}
    assert len(running) >= 5, steps  # seen moving while running (the deck flushes each thermo line)
    assert {p for _, p, _ in seen} >= {"settling", "sampling"}
    assert seen[-1][2] == plan.n_particles
    lines = [r.getMessage() for r in caplog.records if r.name == "pbmdem.dem.progress"]
    assert any(
        re.search(
            rf"DEM test: (settling|spin-up|sampling), step \d+ of {total} \(\d+ %\), \d+ particles, "
            r"elapsed \d+:\d\d, remaining ~",
            line,
        )
        for line in lines
    ), lines
    assert f"step {total} of {total}" in lines[-1]
    assert f"{total}/{total}" in capsys.readouterr().err  # tqdm's bar, complete


def test_progress_of_a_run_from_a_settled_bed_counts_from_the_bed_s_last_step(tmp_path):
    """LIGGGHTS goes on counting steps after read_restart: the reader subtracts the bed's steps."""
    from pbmdem.dem.progress import ThermoProgress

    log = tmp_path / "log.liggghts"
    rows = "".join(f"{step} 100 0.0\n" for step in (1000, 1400, 1800, 2200))
    log.write_text(f"Step Atoms KinEng\n{rows}Loop time of 1.0 on 1 procs\n")
    progress = ThermoProgress(log, [("spin-up", 800), ("sampling", 400)], first_step=1000)
    progress.update()
    assert progress.step == 1200 and progress.phase() == "sampling" and progress.atoms == 100
    assert "step 1200 of 1200 (100 %)" in progress.status()


def test_dem_cli_logs_progress_lines_when_not_on_a_terminal(root, tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "pbmdem.cli",
            "dem",
            "--config",
            str(root / "config" / "test.yaml"),
            "--rpm",
            "600",
            "--distribution",
            "small",
            "--out",
            str(tmp_path / "run"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert re.search(
        r"pbmdem.dem.progress: DEM rpm600_small: (settling|spin-up|sampling), step \d+ of \d+ "
        r"\(\d+ %\), \d+ particles, elapsed",
        proc.stderr,
    ), proc.stderr
    assert "engine stopped at step" in proc.stderr


# ----------------------------------------------------------------------------- defect 6: errors name the file
@pytest.mark.parametrize("text", ["", "a,b\n1,2\n", "d_i,d_j,frequency_per_pair\n0.002,0.002,nan\n", "\x00\x01garbage"])
def test_bad_collision_table_for_the_pbm_names_the_file(tmp_path, text):
    from pbmdem.pbm.errors import PBMInputError
    from pbmdem.pbm.kernels import TableFrequency

    path = _write(tmp_path / "collisions.csv", text)
    with pytest.raises(PBMInputError) as info:
        TableFrequency.from_csv(path)
    assert str(path) in str(info.value)


def test_bad_tables_and_summaries_name_the_file(tmp_path):
    from pbmdem.readers import InputFileError
    from pbmdem.surrogate.train import train_and_report
    from pbmdem.validation.results import load_run

    bad = _write(tmp_path / "bad.csv", "x,y\n1,2\n")
    with pytest.raises(InputFileError, match=re.escape(str(bad)) + ".*point_id"):
        aggregate([bad], tmp_path / "grid.csv")
    with pytest.raises(InputFileError, match=re.escape(str(bad))):
        train_and_report(bad, tmp_path / "model.skops", settings={}, impeller_radius=0.0265)
    empty = _write(tmp_path / "summary.json", "{not json")
    with pytest.raises(InputFileError, match=re.escape(str(empty))):
        run_table([empty], tmp_path / "runs.csv")
    folder = tmp_path / "v" / "rpm600" / "pbm_ann"
    folder.mkdir(parents=True)
    _write(folder / "summary.csv", "time,d10,d50,d90\n0,0.001,0.001,0.001\n1,0.001,nan,0.002\n")
    _write(folder / "final_bins.csv", "diameter,mass_fraction\n0.001,1\n")
    _write(folder / "timing.json", "{}")
    with pytest.raises(InputFileError, match=re.escape(str(folder / "summary.csv")) + ".*d50.*row 2"):
        load_run(folder, "PBM-ANN result")
    _write(folder / "summary.csv", "time,d10,d50,d90\n0,0.001,0.001,0.001\n1,0.001,0.002,0.002\n")
    with pytest.raises(InputFileError, match=re.escape(str(folder / "timing.json")) + ".*total_wall_time_s"):
        load_run(folder, "PBM-ANN result")


@pytest.mark.parametrize("edit", ["format_version", "versions", "velocity_edges"])
def test_a_model_sidecar_of_another_version_is_a_version_error(small_surrogate, tmp_path, edit):
    from pbmdem.surrogate import load_surrogate
    from pbmdem.surrogate.persistence import IncompatibleVersionError, metadata_path_for

    model = tmp_path / "model.skops"
    shutil.copy(small_surrogate, model)
    meta = json.loads(metadata_path_for(small_surrogate).read_text())
    if edit == "format_version":
        meta["format_version"] = 4  # the layout before the surrogate object itself was stored
    elif edit == "versions":
        del meta["versions"]
    else:
        meta["velocity_edges"] = meta["velocity_edges"][1:]
    metadata_path_for(model).write_text(json.dumps(meta))
    with pytest.raises(IncompatibleVersionError) as info:
        load_surrogate(model)
    assert str(metadata_path_for(model)) in str(info.value) and "retrain" in str(info.value)


# ----------------------------------------------------------------------------- progress of the surrogate
def test_surrogate_cross_validation_logs_each_fold_and_candidate(caplog):
    import logging
    import warnings

    from synthetic_tables import make_synthetic_table

    from pbmdem.surrogate import CollisionSurrogate, EnsembleMLPRegressorCV, cross_validate_models, training_data
    from pbmdem.surrogate.evaluation import default_baselines

    table = make_synthetic_table(0.0265, rpms=(300, 600, 900), seed=4)
    model = CollisionSurrogate(
        EnsembleMLPRegressorCV(
            hidden_layer_sizes=((4,), (6,)), alpha=(0.1,), seeds=(0,), max_iter=200, activation="tanh", solver="lbfgs"
        ),
        impeller_radius=0.0265,
        physics_offset="cross_section",
    )
    caplog.set_level(logging.INFO, logger="pbmdem.surrogate")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        metrics, _ = cross_validate_models(
            training_data(table, 0.0265), {"mlp": model, **default_baselines()}, cv="group_kfold", n_splits=3
        )
    folds = [r.getMessage() for r in caplog.records if r.getMessage().startswith("CV fold")]
    assert len(folds) == 3 and folds[-1].startswith("CV fold 3 of 3 done") and "mlp R2" in folds[0]
    assert "remaining ~" in folds[0]
    candidates = [r.getMessage() for r in caplog.records if r.getMessage().startswith("hyperparameter candidate")]
    assert len(candidates) == 3 * 2  # two candidates in each outer fold's inner search


@pytest.mark.parametrize(
    "args, flag",
    [
        (["--rpm", "nan"], "--rpm"),
        (["--rpm", "0"], "--rpm"),
        (["--rpm", "600", "--diameters", "0.002", "nan"], "--diameters"),
    ],
)
def test_surrogate_predict_refuses_non_finite_inputs(small_surrogate, capsys, args, flag):
    from pbmdem.cli import main

    base = {"--rpm": "600", "--diameters": ["0.002", "0.003"], "--numbers": ["10", "20"]}
    argv = ["surrogate", "predict", "--model", str(small_surrogate), "--numbers", "10", "20"]
    if "--diameters" not in args:
        argv += ["--diameters", *base["--diameters"]]
    assert main(argv + args) == 2
    err = capsys.readouterr().err
    assert flag in err and ("nan" in err or "0" in err) and "Traceback" not in err


def test_surrogate_train_config_with_duplicate_or_nan_is_refused(root, tmp_path, capsys):
    from pbmdem.cli import main

    table = _write(tmp_path / "t.csv", "point_id\n")
    for name, text in (
        ("dup.yaml", "surrogate:\n  max_iter: 10\n  max_iter: 20\n"),
        ("nan.yaml", "surrogate:\n  alpha: [.nan]\n"),
    ):
        path = _write(tmp_path / name, text)
        assert (
            main(["surrogate", "train", "--table", str(table), "--config", str(path), "--out", str(tmp_path / "out")])
            == 2
        )
        err = capsys.readouterr().err
        assert str(path) in err and ("duplicate key 'max_iter'" in err or "surrogate.alpha[0] = nan" in err)
        assert not (tmp_path / "out").exists()


def test_a_failed_first_run_is_kept_in_and_named_by_its_run_folder(tiny_config, tmp_path, monkeypatch):
    from test_dem_liggghts import _failing_liggghts

    monkeypatch.setenv("PBMDEM_LIGGGHTS", str(_failing_liggghts(tmp_path)))
    run = tmp_path / "run"
    point = tiny_config.dem_point("small")
    with pytest.raises(engine.LiggghtsError) as info:
        run_point(plan_point(point, 600), run, tiny_config.dem_execution)
    assert str(run) in str(info.value) and "staging" not in str(info.value)
    assert (run / "crash.json").exists() and (run / "log.liggghts").exists() and not is_finished(run)
    assert not list(tmp_path.glob(".*staging"))
