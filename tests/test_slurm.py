"""The cluster route end to end: the tiny workflow through `--profile profiles/slurm` on a real
single-node SLURM cluster (scripts/slurm_cluster.sh), with real LIGGGHTS as 2-rank MPI jobs.

1. start the cluster (installs slurm-wlm, munge, libpmix-dev when missing; needs root);
2. run the tiny configuration's workflow through the SLURM profile;
3. `scancel` one DEM job during its sampling phase: the workflow reports it failed and nothing
   is tabulated from it;
4. rerun: the workflow completes, redoing only the cancelled point and what depends on it; a
   local run afterwards (another executor) has nothing to do;
5. every DEM point ran as a 2-rank MPI job through the executor (the profile's `tasks: 2`).

Every step has a hard timeout; the cluster's daemons are stopped by PID in the fixture's
finalizer, also when a step fails. A cluster that cannot start fails the test with its logs.
Figures (startup, workflow wall times) are printed, not asserted.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from conftest import snakemake_command

pytestmark = [pytest.mark.liggghts, pytest.mark.workflow, pytest.mark.slurm]

CANCEL = ("1200", "large")  # the DEM point cancelled during its sampling
RANKS = 2  # the profile's tasks for dem_point


@pytest.fixture(scope="module")
def cluster(root, tmp_path_factory):
    """A running single-node SLURM cluster; stopped (every daemon by PID) whatever happens."""
    if os.geteuid() != 0:
        pytest.fail("the SLURM test needs root (it installs slurm-wlm/munge and runs the daemons); CI runs as root")
    script = root / "scripts" / "slurm_cluster.sh"
    state = tmp_path_factory.mktemp("slurm-state")
    env = dict(os.environ, PBMDEM_SLURM_STATE=str(state))

    def stop():
        return subprocess.run(["bash", str(script), "stop"], env=env, capture_output=True, text=True, timeout=120)

    t0 = time.perf_counter()
    try:
        proc = subprocess.run(["bash", str(script), "start"], env=env, capture_output=True, text=True, timeout=900)
    except subprocess.TimeoutExpired as exc:
        stop()
        pytest.fail(f"the SLURM cluster did not start within 900 s:\n{exc.stdout}\n{exc.stderr}")
    if proc.returncode != 0:
        stop()
        pytest.fail(f"the SLURM cluster did not start:\n{proc.stdout}\n{proc.stderr}")
    print(f"\n[slurm] cluster start (incl. any installs): {time.perf_counter() - t0:.1f} s; {proc.stdout.strip()}")
    try:
        yield {"env": env, "state": state, "script": script}
    finally:
        out = stop()
        print(f"[slurm] {out.stdout.strip()} {out.stderr.strip()}")


# polling faster than the profile's 10 s keeps the test short; everything else is the profile
FAST = ["--slurm-init-seconds-before-status-checks", "1", "--seconds-between-status-checks", "2"]


def _run(cmd, env, timeout, cwd):
    try:
        return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout, cwd=cwd)
    except subprocess.TimeoutExpired as exc:
        raise AssertionError(f"timed out after {timeout} s: {' '.join(cmd)}\n{exc.stdout}\n{exc.stderr}") from None


def _job_counts(text: str) -> dict[str, int]:
    return {
        w[0]: int(w[1])
        for w in (line.split() for line in text.splitlines())
        if len(w) == 2 and w[1].isdigit() and w[0] != "total"
    }


def _cancel_in_sampling(proc: subprocess.Popen, workdir: Path, env: dict, timeout: float = 500) -> str:
    """Wait until the DEM point CANCEL is in its sampling phase, then scancel its SLURM job."""
    rpm, dist = CANCEL
    # the run is made in a staging folder beside rep0/; its dumps begin with the position history
    stage = workdir / "results" / "dem" / f"rpm{rpm}_{dist}" / ".rep0.staging"
    logs = workdir / "results" / "logs" / "slurm" / "rule_dem_point"
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if proc.poll() is not None:
            raise AssertionError(
                "the workflow ended before the DEM job could be cancelled:\n" + proc.stdout.read() + proc.stderr.read()
            )
        pairs, plan = stage / "post" / "pairs.dump", stage / "plan.json"
        job_logs = sorted(logs.glob(f"{rpm}_{dist}*/*.log"))
        if pairs.exists() and plan.exists() and job_logs:
            p = json.loads(plan.read_text())
            steps = [int(s) for s in re.findall(rb"ITEM: TIMESTEP\n(\d+)\n", pairs.read_bytes())]
            in_window = steps and steps[-1] > p["settle_steps"] + p["spinup_steps"] + 3 * p["collision_interval"]
        else:
            in_window = False
        if in_window:
            jobid = job_logs[-1].stem
            subprocess.run(["scancel", jobid], env=env, check=True, timeout=30)
            return jobid
        time.sleep(0.1)
    raise AssertionError(f"DEM point {rpm}/{dist} did not reach its sampling phase within {timeout} s")


def test_tiny_workflow_through_the_slurm_profile(cluster, root, tmp_path):
    """The steps 2-5 of the module docstring; every process the test started (the workflow, its
    SLURM jobs and whatever they run under the work folder) is ended by PID at the end, also when
    a step fails."""
    workdir = tmp_path / "wd"
    workdir.mkdir()
    env = dict(cluster["env"], PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    started: list[subprocess.Popen] = []
    try:
        _workflow_with_a_cancel(root, workdir, env, started)
    except BaseException:
        _end_everything(started, workdir, env, check=False)  # the step's own failure is the report
        raise
    _end_everything(started, workdir, env, check=True)


def _end_everything(started: list, workdir: Path, env: dict, check: bool) -> None:
    """End, by PID, the processes this test started: its workflow processes with everything below
    them, its SLURM jobs (scancel by job id) and any process left under `workdir` (a job step
    re-parented to init); with `check`, fail if one was still running once its jobs were gone."""
    import psutil
    from conftest import end_processes, leftover_processes

    procs = []
    for proc in started:
        try:
            procs += [psutil.Process(proc.pid), *psutil.Process(proc.pid).children(recursive=True)]
        except psutil.Error:
            pass
    end_processes(procs)
    for proc in started:
        if proc.poll() is None:
            proc.kill()
        proc.communicate()
    jobs = subprocess.run(["squeue", "-h", "-o", "%i"], env=env, capture_output=True, text=True, timeout=30)
    for jobid in jobs.stdout.split():
        subprocess.run(["scancel", jobid], env=env, capture_output=True, timeout=30)
    t0 = time.monotonic()
    while leftover_processes(workdir) and time.monotonic() - t0 < 20:  # the jobs end on SIGTERM
        time.sleep(0.5)
    left = leftover_processes(workdir)
    names = [f"{p.pid} {' '.join(p.cmdline())[:200]}" for p in left]
    end_processes(left)
    assert not (check and names), (
        "processes of the SLURM test were still running after its jobs were cancelled: " + "; ".join(names)
    )


def _workflow_with_a_cancel(root: Path, workdir: Path, env: dict, started: list) -> None:
    cfg = yaml.safe_load((root / "config" / "test.yaml").read_text())
    # a sampling window long enough to cancel a job inside it (the tiny one lasts ~0.3 s)
    cfg["dem"]["sampling_time"] = 0.08
    cfg["validation"]["rpm"] = [600]  # one coupled loop (2-rank jobs take the whole 2-core node)
    cfg["dem"]["replicates"] = 1  # one run per point keeps the cluster test short
    configfile = workdir / "config.yaml"
    configfile.write_text(yaml.safe_dump(cfg))
    profile = ["--profile", str(root / "profiles" / "slurm"), *FAST]

    # 2./3. the workflow through SLURM, one DEM job cancelled during sampling
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        snakemake_command(workdir, *profile, configfile=configfile),
        env=env,
        cwd=workdir,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    started.append(proc)
    try:
        jobid = _cancel_in_sampling(proc, workdir, env)
        stdout, stderr = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    first = time.perf_counter() - t0
    out = stdout + stderr
    assert proc.returncode != 0, out[-5000:]
    assert re.search(
        rf"Error in rule dem_point:.*?SLURM-jobid.*?{jobid}|{jobid}.*?(CANCELLED|failed)", out, re.DOTALL
    ), out[-5000:]
    res = workdir / "results"
    cancelled = res / "dem" / f"rpm{CANCEL[0]}_{CANCEL[1]}" / "rep0"
    for table in ("collisions.csv", "wall_collisions.csv", "summary.json"):
        assert not (cancelled / table).exists(), f"{table} was written from a cancelled run"
    assert not (res / "dem" / "collisions.csv").exists()  # nothing aggregated from the grid
    crash = json.loads((cancelled / "crash.json").read_text())
    assert any("interrupted" in p for p in crash["problems"]), crash
    finished = [
        (r, d) for r in cfg["grid"]["impeller_rpm"] for d in cfg["grid"]["size_distributions"] if (f"{r}", d) != CANCEL
    ]
    for rpm, dist in finished:  # keep-going: the other points finished
        assert (res / "dem" / f"rpm{rpm}_{dist}" / "rep0" / "collisions.csv").exists(), (rpm, dist)

    # 4. the rerun redoes the cancelled point and what depends on it, nothing else
    dry = _run(snakemake_command(workdir, *profile, "-n", "--quiet", "rules", configfile=configfile), env, 120, workdir)
    counts = _job_counts(dry.stdout + dry.stderr)
    assert counts.get("dem_point") == 1, dry.stdout + dry.stderr
    assert "pbm_constant" not in counts and "pbm_dem_coupled" not in counts, counts
    t1 = time.perf_counter()
    rerun = _run(snakemake_command(workdir, *profile, configfile=configfile), env, 600, workdir)
    second = time.perf_counter() - t1
    assert rerun.returncode == 0, (rerun.stdout + rerun.stderr)[-5000:]
    assert (cancelled / "collisions.csv").exists() and not (cancelled / "crash.json").exists()
    assert (res / "report" / "tables" / "provenance.csv").exists()
    # another executor (local) sees nothing to do: the executor and its resources are not params
    local = _run(snakemake_command(workdir, "-n", "--cores", "2", configfile=configfile), env, 120, workdir)
    assert "Nothing to be done" in local.stdout + local.stderr, local.stdout + local.stderr

    # 5. the DEM points ran as 2-rank MPI jobs under SLURM's launcher
    for rpm, dist in [*finished, CANCEL]:
        run = res / "dem" / f"rpm{rpm}_{dist}" / "rep0"
        assert json.loads((run / "plan.json").read_text())["mpi_ranks"] == RANKS
        assert re.search(rf"Loop time of .* on {RANKS} procs", (run / "log.liggghts").read_text())
    slurm_logs = sorted((res / "logs" / "slurm" / "rule_dem_point").glob("*/*.log"))
    assert slurm_logs, "no SLURM job logs under results/logs/slurm"
    print(f"[slurm] tiny workflow with one cancel: {first:.1f} s; rerun: {second:.1f} s (status checks every 2 s)")
