"""Every benchmark's quick mode runs: benchmarks that cannot rot unseen (issue 35).

Each script of benchmarks/ is run as a user would, ``python benchmarks/<script> --quick``, in an
empty working directory (no results/: a quick mode makes what it needs, see benchmarks/quick.py)
and must exit 0 and print its figures: the regular expressions of its row in QUICK, a line of
each of its tables. No timing is asserted (speed is a benchmark's figure, never a test's).

A new benchmark is one line in QUICK (the command after ``python benchmarks/``, then the
expressions its output must contain); ``test_every_benchmark_has_a_quick_mode`` fails while a
script of benchmarks/ has none. A script with subcommands runs them all in its one quick mode
(bench_dem.py: point, profile, acceptance, null, runs, skin, cost), or gets one row per subcommand.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"
#: modules of benchmarks/ that the benchmarks import, not benchmarks themselves
HELPERS = {"quick.py"}
#: command (after ``python benchmarks/``) -> regular expressions its output must contain
QUICK = {
    "render_decks.py --quick": (r"test\.yaml: [1-9]\d* decks in ",),
    "bench_breakage_tail.py --quick": (
        r"gengamma held out s=0\.5 +pairs",
        r"noise floor s=0 +impeller",
        r"dem>0_few",
        r"number-weighted selection rate S",
    ),
    "bench_breakage_samples.py --quick": (
        r"rpm 1200: median log10\(estimate / DEM\) of the pair breaking-impact rate",
        r"0\.50 +feed +\S+ +[+-]\d\.\d\d +[+-]\d\.\d\d +[+-]\d\.\d\d",
    ),
    "bench_calibration.py --quick": (r"PBM-constant \+ noise, 2 noise seeds", r"pbm\.aggregation\.beta0 +2 "),
    "bench_dem.py --quick": (
        r"vectorised parse\+count +\d",
        r"settling_s +spinup_s",
        r"pairs within the frequency criterion: \d+ of \d+",
        r"frequency criterion: pairs failing without any change",
        r"permutation p = [\d.]+",
        r"\| rpm600_small/rep0 +\| +\d+ \| +600 \| dmax",
        r"speed-up per point: LIGGGHTS CPU",
    ),
    "bench_design_space.py --quick": (
        r"one PBM-ANN batch, breakage off \(3 warm batches",
        r"wall min [\d.]+ / median [\d.]+ / max [\d.]+ ms; CPU min [\d.]+ / median [\d.]+ / max [\d.]+ ms",
        r"the median batch \([\d.]+ ms\): surrogate [\d.]+ ms, PBM [\d.]+ ms",
        r"12 PBM-ANN batches \(mean and \d+ members\) on 2 process\(es\): .* batches per minute; 0 failed",
        r"batches per minute on 2 process\(es\), 2 round\(s\): min \d+ / median \d+ / max \d+",
    ),
    "bench_pair_features.py --quick": (
        r"pair frequency \(Kriging\) per variant: held-out MAE",
        r"norel +[+-]\d\.\d{3}",
        r"law from 0\.1 m/s +\d+\.\d\d / \d+\.\d\d / \d+\.\d\d",
    ),
    "bench_pbm.py --quick": (
        r"surrogate for PBM-ANN: trained in [\d.]+ s",
        r"batch  min +[\d.]+ ms, median +[\d.]+ ms \| \d+ steps, \d+ bins",
        r"PBM-ANN surrogate \+ PBM min +[\d.]+ ms",
    ),
    "bench_pbm2d.py --quick": (
        r"default batch, dimensions 1 \(3 runs, warm\)",
        r"CPU s:  min [\d.]+  median [\d.]+  max [\d.]+",
        r"one rate evaluation at the end state",
    ),
    "bench_pbm_accuracy.py --quick": (
        r"observed order per halving of ln r: \|M2 err\|",
        r"breakage: aggregation beta = 1",
        r"\*  3 +37 +[\d.]+ / [\d.]+ / [\d.]+",
    ),
    "bench_porosity_strength.py --quick": (r"variant +rpm +d10 +d50 +d90", r"n=2 +1200 +[\d.]+ +[\d.]+"),
    "bench_ranks.py --quick": (r"ranks 2: LIGGGHTS wall [\d.]+ s", r"2 vs 1 ranks: difference [+-]\d+"),
    "bench_replay.py --quick": (
        r"all surrogate +[\d.]+ \([\d.]+-[\d.]+\)",
        r"DEM pair_speed only +[\d.]+",
        r"all DEM reproduces the stored PBM-DEM loops: max \|difference\| of final d10/d50/d90 [\d.e+-]+",
        r"all surrogate reproduces the stored PBM-ANN batch: max \|difference\|",
        r"members' final d50 \(mm\)",
        r"  tail +[\d. ]+ width [\d.]+",
    ),
    "bench_sensitivity.py --quick": (
        r"ranking by ST of d50 \(first to last\)",
        r"wall ms per batch \(ensemble mean, 20 warm batches in one process\): min [\d.]+, median [\d.]+, max [\d.]+",
    ),
    "bench_surrogate_persistence.py --quick": (
        r"model\.skops [\d.]+ kB, model\.json [\d.]+ kB; family EnsembleMLPRegressorCV, wall models bowl, impeller",
        r"load ms \(11 loads in one process\): min [\d.]+, median [\d.]+, max [\d.]+",
    ),
    "bench_surrogate_reproducibility.py --quick": (
        r"\| Prescott, 2 thread\(s\) \| [\d.e+-]+; [\d.e+-]+ \|",
        r"held-out pooled R2 of log10 c",
    ),
    "study_encounters.py --quick": (
        r"snapshot interval h/2 -> h: encounters",
        r"second/first half of the window - 1: [+-][\d.]+%",
    ),
}
#: scripts that run the real LIGGGHTS (tiny cases)
LIGGGHTS = {"bench_dem.py", "bench_ranks.py", "study_encounters.py"}
#: scripts whose quick mode is known to fail (a row here must say why)
REWRITTEN: set[str] = set()
#: a quick mode takes seconds to tens of seconds; this only keeps a hung one from stalling the suite
TIMEOUT_S = 300


def _script(command: str) -> str:
    return command.split()[0]


def _params():
    for command in QUICK:
        marks = []
        if _script(command) in LIGGGHTS:
            marks.append(pytest.mark.liggghts)
        if _script(command) in REWRITTEN:
            marks.append(pytest.mark.xfail(strict=True, reason="quick mode known to fail"))
        yield pytest.param(command, marks=marks, id=command.replace(" --quick", ""))


def test_every_benchmark_has_a_quick_mode():
    scripts = {p.name for p in BENCHMARKS.glob("*.py")} - HELPERS
    covered = {_script(command) for command in QUICK}
    assert not scripts - covered, (
        f"benchmarks without a row in tests/test_benchmarks.py QUICK: {sorted(scripts - covered)}"
    )
    assert not covered - scripts, f"rows of QUICK without a script in benchmarks/: {sorted(covered - scripts)}"
    assert (LIGGGHTS | REWRITTEN) <= scripts


def _run(command: str, cwd: Path) -> subprocess.CompletedProcess:
    """``python benchmarks/<command>`` in ``cwd`` with this checkout's sources first on the path and
    temporary folders under ``cwd`` (so the suite's check for leftover processes sees its children);
    on timeout its whole process group is ended and the test fails."""
    path = [str(ROOT / "src"), *filter(None, [os.environ.get("PYTHONPATH")])]
    env = dict(os.environ, TMPDIR=str(cwd), PYTHONPATH=os.pathsep.join(path))
    argv = [sys.executable, str(BENCHMARKS / _script(command)), *command.split()[1:]]
    pipe = subprocess.PIPE
    proc = subprocess.Popen(argv, cwd=cwd, env=env, stdout=pipe, stderr=pipe, text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        pytest.fail(f"{command} did not finish in {TIMEOUT_S} s; output:\n{out[-3000:]}\n{err[-3000:]}")
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


@pytest.mark.parametrize("command", list(_params()))
def test_quick_mode_runs_and_prints_its_figures(command, tmp_path):
    work = tmp_path / "work"
    work.mkdir()
    done = _run(command, work)
    assert done.returncode == 0, f"{command} exited {done.returncode}:\n{done.stdout[-3000:]}\n{done.stderr[-5000:]}"
    missing = [pattern for pattern in QUICK[command] if not re.search(pattern, done.stdout)]
    assert not missing, f"{command} did not print {missing}; its output:\n{done.stdout[-5000:]}"
    assert not (work / "results").exists(), f"{command} wrote results/ into its working directory"
