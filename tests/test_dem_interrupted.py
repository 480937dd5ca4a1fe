"""An interrupted LIGGGHTS run is never accepted as finished (real engine, tiny configuration).

LIGGGHTS answers SIGINT/SIGTERM by writing a forced restart file and exiting 0. These tests
interrupt a real run during its sampling phase and check that `pbmdem dem` fails with a message
saying so, tabulates nothing, and records the interruption (and the removed restart file) in
crash.json.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest
import yaml

pytestmark = pytest.mark.liggghts


def _start_dem(root: Path, tmp_path: Path) -> tuple[subprocess.Popen, Path]:
    cfg = yaml.safe_load((root / "config" / "test.yaml").read_text())
    cfg["dem"]["sampling_time"] = 0.5  # a sampling window of a few seconds to interrupt
    config = tmp_path / "config.yaml"
    config.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "run"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "pbmdem.cli",
            "dem",
            "--config",
            str(config),
            "--rpm",
            "600",
            "--distribution",
            "small",
            "--out",
            str(out),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    return proc, out


def _wait_for_sampling(proc: subprocess.Popen, out: Path, timeout: float = 120.0) -> None:
    """Until the contact dump has frames past the start of the sampling window (the run is made
    in the staging folder beside `out`; its dumps start with the position history before the
    window)."""
    t0 = time.monotonic()
    stage = out.parent / f".{out.name}.staging"
    while time.monotonic() - t0 < timeout:
        if proc.poll() is not None:
            raise AssertionError(f"the run ended before sampling:\n{proc.communicate()}")
        pairs, plan = stage / "post" / "pairs.dump", stage / "plan.json"
        if pairs.exists() and plan.exists():
            p = json.loads(plan.read_text())
            steps = [int(s) for s in re.findall(rb"ITEM: TIMESTEP\n(\d+)\n", pairs.read_bytes())]
            if steps and steps[-1] > p["settle_steps"] + p["spinup_steps"] + 3 * p["collision_interval"]:
                return
        time.sleep(0.02)
    proc.kill()
    raise AssertionError("the run did not reach its sampling phase")


def _liggghts_child(proc: subprocess.Popen) -> psutil.Process:
    for _ in range(100):
        kids = [p for p in psutil.Process(proc.pid).children(recursive=True) if "liggghts" in p.name()]
        if kids:
            return kids[0]
        time.sleep(0.05)
    raise AssertionError("no LIGGGHTS process found under pbmdem dem")


def _check_rejected(proc: subprocess.Popen, out: Path, interrupted_by: str | None) -> None:
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode != 0, stdout + stderr
    assert "interrupted" in stderr and "No tables were written" in stderr, stderr
    for table in ("collisions.csv", "wall_collisions.csv", "summary.json"):
        assert not (out / table).exists(), table
    crash = json.loads((out / "crash.json").read_text())
    problems = " ".join(crash["problems"])
    assert "forced restart" in problems, crash
    if interrupted_by:
        assert f"interrupted by {interrupted_by}" in problems, crash
    # the restart file is removed and recorded
    assert crash["forced_restart_files"] and all(r["removed"] for r in crash["forced_restart_files"]), crash
    assert not list(out.glob("restart_forced_*"))
    plan = json.loads((out / "plan.json").read_text())
    step = crash["forced_restart_files"][0]["step"]
    assert (
        plan["settle_steps"] + plan["spinup_steps"]
        < step
        < (plan["settle_steps"] + plan["spinup_steps"] + plan["sampling_steps"])
    ), (step, plan)


def test_sigterm_to_liggghts_during_sampling_is_a_failure(root, tmp_path):
    """SIGTERM to LIGGGHTS alone (exit code 0, forced restart): the run is judged unfinished."""
    proc, out = _start_dem(root, tmp_path)
    try:
        _wait_for_sampling(proc, out)
        _liggghts_child(proc).send_signal(signal.SIGTERM)
        _check_rejected(proc, out, interrupted_by=None)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


def test_sigterm_to_the_job_during_sampling_is_recorded(root, tmp_path):
    """SIGTERM to every process of the job, as `scancel` or a time limit sends it."""
    proc, out = _start_dem(root, tmp_path)
    try:
        _wait_for_sampling(proc, out)
        _liggghts_child(proc)
        os.killpg(proc.pid, signal.SIGTERM)
        _check_rejected(proc, out, interrupted_by="SIGTERM")
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


def _copy_run(tiny_run, tmp_path, name: str) -> Path:
    import shutil

    from pbmdem.dem.run import check_finished

    run = tmp_path / name
    shutil.copytree(tiny_run["dir"], run)
    check_finished(tiny_run["plan"], run)  # the finished run passes
    return run


def _cut_log(run: Path) -> int:
    """Cut log.liggghts before its last thermo row (as a run that stopped there); returns the
    last step the cut log shows."""
    from pbmdem.dem import engine

    log = run / "log.liggghts"
    lines = log.read_text().splitlines(keepends=True)
    steps = engine.thermo_table(log)["Step"]
    last_row = max(k for k, line in enumerate(lines) if line.split()[:1] == [f"{int(steps[-1])}"])
    log.write_text("".join(lines[:last_row]))
    return int(engine.thermo_table(log)["Step"][-1])


def test_a_run_cut_short_without_a_forced_restart_is_a_failure(tiny_run, tmp_path):
    """The plan check alone (no restart line, exit code 0): a log and dumps that stop early fail
    as an unfinished run."""
    from pbmdem.dem import engine
    from pbmdem.dem.run import check_finished

    run = _copy_run(tiny_run, tmp_path, "cut")
    plan = tiny_run["plan"]
    pairs = run / "post" / "pairs.dump"
    frames = pairs.read_bytes().split(b"ITEM: TIMESTEP\n")
    pairs.write_bytes(b"ITEM: TIMESTEP\n".join(frames[:-1]))
    last = _cut_log(run)
    with pytest.raises(engine.LiggghtsError, match="pairs.dump holds") as err:
        check_finished(plan, run)
    assert f"unfinished: the log's last thermo step is {last}, the plan has {plan.total_steps}" in str(err.value)
    assert "corrupt" not in str(err.value)
    assert "pairs.dump" in json.loads((run / "crash.json").read_text())["problems"][1]


def test_a_short_log_with_complete_dumps_is_unfinished(tiny_run, tmp_path):
    """Issue 25, 7b: every dump complete, but the log stops short of the planned step: refused."""
    from pbmdem.dem import engine
    from pbmdem.dem.run import check_finished

    run = _copy_run(tiny_run, tmp_path, "short_log")
    plan = tiny_run["plan"]
    last = _cut_log(run)
    assert last < plan.total_steps
    with pytest.raises(engine.LiggghtsError) as err:
        check_finished(plan, run)
    assert f"unfinished: the log's last thermo step is {last}, the plan has {plan.total_steps} steps" in str(err.value)
    assert "dump" not in " ".join(json.loads((run / "crash.json").read_text())["problems"])


def test_random_bytes_in_a_dump_of_a_finished_run_are_corruption_not_an_unfinished_run(tiny_run, tmp_path):
    """Issue 25, item 4: 4000 random bytes written into the middle of a finished run's pairs dump."""
    import random

    from pbmdem.dem import engine
    from pbmdem.dem.dumps import DumpFormatError
    from pbmdem.dem.run import check_finished

    run = _copy_run(tiny_run, tmp_path, "corrupt")
    pairs = run / "post" / "pairs.dump"
    data = bytearray(pairs.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 4000] = random.Random(25).randbytes(4000)
    pairs.write_bytes(bytes(data))
    with pytest.raises(DumpFormatError) as err:
        check_finished(tiny_run["plan"], run)
    text = str(err.value)
    assert not isinstance(err.value, engine.LiggghtsError)
    assert "unfinished" not in text and "LIGGGHTS failed" not in text
    assert f"LIGGGHTS finished (its log reaches the planned step {tiny_run['plan'].total_steps})" in text
    found = re.search(r"corrupt: (\S+pairs\.dump): line (\d+) \(byte (\d+)\), frame (\d+)", text)
    assert found, text
    line, byte = int(found.group(2)), int(found.group(3))
    # the named line and byte are where the damage is: at or after the first damaged byte
    assert middle - 200 <= byte <= middle + 4000
    assert data[:byte].count(b"\n") == line - 1
    assert "corrupt" in json.loads((run / "crash.json").read_text())["problems"][0]


def test_a_dump_missing_its_last_frame_after_a_finished_log_is_corruption(tiny_run, tmp_path):
    from pbmdem.dem.dumps import DumpFormatError
    from pbmdem.dem.run import check_finished

    run = _copy_run(tiny_run, tmp_path, "lost_frame")
    pairs = run / "post" / "pairs.dump"
    frames = pairs.read_bytes().split(b"ITEM: TIMESTEP\n")
    pairs.write_bytes(b"ITEM: TIMESTEP\n".join(frames[:-1]))
    with pytest.raises(DumpFormatError, match=r"corrupt: \S+pairs.dump is well-formed but holds \d+ frames"):
        check_finished(tiny_run["plan"], run)


def test_a_cancelled_job_ends_within_killwait_even_if_the_engine_ignores_sigterm(tmp_path):
    """Issue 25, item 5: `scancel` sends SIGTERM to every process of the job; an engine (or MPI
    launcher) that ignores it must not keep the job step alive past the cluster's KillWait (after
    which SLURM's SIGKILL misses processes re-parented to init). The engine and everything it
    started are killed SIGNAL_KILL s after the signal, and the run is reported."""
    from pbmdem.dem.signals import SIGNAL_KILL

    pids = tmp_path / "pids"
    fake = tmp_path / "stubborn-liggghts"
    fake.write_text(
        "#!/bin/bash\ntrap '' TERM INT\n"
        "bash -c \"trap '' TERM INT; echo \\$\\$ >> $PIDS; sleep 300\" &\n"
        "echo $$ >> $PIDS\nwait\n".replace("$PIDS", str(pids))
    )
    fake.chmod(0o755)
    (tmp_path / "in.granulator").write_text("# not read\n")
    code = "from pbmdem.dem import engine; engine.run('in.granulator', '.', timeout=600)"
    env = dict(os.environ, PBMDEM_LIGGGHTS=str(fake))
    proc = subprocess.Popen(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        env=env,
        text=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    try:
        t_wait = time.monotonic()
        while not (pids.exists() and len(pids.read_text().split()) == 2):
            assert time.monotonic() - t_wait < 30 and proc.poll() is None, proc.communicate()
            time.sleep(0.05)
        started = [int(p) for p in pids.read_text().split()]
        t0 = time.monotonic()
        os.killpg(proc.pid, signal.SIGTERM)  # as scancel: every process of the job
        _, stderr = proc.communicate(timeout=60)
        took = time.monotonic() - t0
        assert proc.returncode != 0
        assert took < SIGNAL_KILL + 3, took
        assert f"killed: still running {SIGNAL_KILL:g} s after SIGTERM" in stderr, stderr
        assert "interrupted by SIGTERM" in stderr
        time.sleep(0.2)
        alive = [p for p in started if psutil.pid_exists(p) and psutil.Process(p).status() != psutil.STATUS_ZOMBIE]
        assert not alive, alive
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        for pid in [int(p) for p in pids.read_text().split()] if pids.exists() else []:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


def test_random_bytes_in_the_binary_positions_of_a_finished_run_are_found_where_they_are(tiny_run, tmp_path):
    """The positions are a binary dump: 4000 random bytes in its middle keep its frame structure
    (the plan check passes: LIGGGHTS did finish), but the tabulation refuses the impossible
    particle ids they leave and names the byte and frame."""
    import random

    from pbmdem.dem import collisions
    from pbmdem.dem.dumps import DumpFormatError
    from pbmdem.dem.run import check_finished

    run = _copy_run(tiny_run, tmp_path, "corrupt_positions")
    path = run / "post" / "positions.bin"
    data = bytearray(path.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 4000] = random.Random(25).randbytes(4000)
    path.write_bytes(bytes(data))
    check_finished(tiny_run["plan"], run)
    with pytest.raises(DumpFormatError) as err:
        collisions.tabulate_run(run / "post", tiny_run["plan"])
    found = re.search(r"corrupt dump: (\S+positions\.bin): byte (\d+), frame (\d+) \(step \d+\)", str(err.value))
    assert found, str(err.value)
    assert middle <= int(found.group(2)) < middle + 4000
