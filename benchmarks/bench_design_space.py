"""PBM-ANN batches: one batch, warm, and the throughput of many (the design space, the sensitivity
analysis and the calibration). Prints figures, no assertions.

1. **One batch** of the default configuration (the validation feed, its coupling intervals, the
   surrogate's ensemble mean, in memory, the surrogate loaded once), warm (after one batch that
   loads numba's cache, the thread pools and scikit-learn's lazy imports), `--repeat` times (>= 20)
   at the validation's speeds in turn: min / median / max of the wall and CPU time of this process,
   with breakage on (the default) and off. Then the median batch split into its parts: the
   surrogate's calls (`provider_wall_time_s`), the PBM's integration (`pbm_wall_time_s`), of it the
   compiled step loop (`pbm.fast_steps`, timed by wrapping `FastSteps.advance`; the rest of the
   PBM's time is Python: the runs' set-up, the kernel's and selection's preparation, the records)
   and the breakage selection's evaluations in Python (wrapping `ImpactSelection.__call__`: the
   first step of a run; the compiled loop evaluates it at the other steps), and the rest of the
   loop (sample, class-frequency source).
2. **Throughput**: `--batches` batches (speeds over the grid's range; the ensemble mean and each
   member in turn, as the design space runs them) with `pbmdem.design.batches.run_cases` on 1 and
   on `--jobs` processes, `--rounds` times each: wall and CPU time (this process and its children)
   and batches per minute of every round, then their min / median / max.

The targets of issue 35: one batch <= 10 ms with breakage, <= 5 ms without (median, warm); >= 10,000
batches per minute on 2 cores. The machine may be shared: the load average is printed before and
after; compare figures of one run.

Run: .venv/bin/python benchmarks/bench_design_space.py [--model results/surrogate/model.skops]
     [--repeat 30] [--batches 2000] [--rounds 3] [--jobs 2] [--quick]
`--quick` (for the test suite): trains a small surrogate on synthetic tables (benchmarks/quick.py)
unless `--model` is given, and runs a few batches of each kind.
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def cpu_seconds(children: bool = True) -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    total = own.ru_utime + own.ru_stime
    if children:
        kids = resource.getrusage(resource.RUSAGE_CHILDREN)
        total += kids.ru_utime + kids.ru_stime
    return total


def spread(values, scale: float = 1e3, unit: str = "ms") -> str:
    v = np.asarray(values, float) * scale
    return f"min {v.min():.2f} / median {np.median(v):.2f} / max {v.max():.2f} {unit}"


def without_breakage(loop):
    pbm = loop.batch.pbm
    return loop.replace(batch=loop.batch.replace(pbm=pbm.replace(breakage=pbm.breakage.replace(enabled=False))))


class Timer:
    """Wraps the method ``name`` of ``cls`` to add up its time and calls (``close`` restores it)."""

    def __init__(self, cls, name: str):
        self.cls, self.name, self.original, self.seconds, self.calls = cls, name, getattr(cls, name), 0.0, 0
        timer = self

        def timed(*args):
            t0 = time.perf_counter()
            out = timer.original(*args)
            timer.seconds += time.perf_counter() - t0
            timer.calls += 1
            return out

        setattr(cls, name, timed)

    def close(self):
        setattr(self.cls, self.name, self.original)


def one_batch(loop, model, speeds, repeat: int, label: str) -> None:
    """`repeat` warm in-memory batches at `speeds` in turn: their wall and CPU time and the parts of
    the batch of median wall time."""
    from pbmdem.coupling import pbm_ann

    pbm_ann(loop, model, speeds[0], None, log_each=False)  # warm: numba's cache, thread pools, imports
    from pbmdem.pbm.fast_steps import FastSteps
    from pbmdem.pbm.impact_breakage import ImpactSelection

    walls, cpus, parts, finals = [], [], [], []
    timer, steps = Timer(ImpactSelection, "__call__"), Timer(FastSteps, "advance")
    try:
        for k in range(repeat):
            rpm = speeds[k % len(speeds)]
            timer.seconds, timer.calls, steps.seconds = 0.0, 0, 0.0
            t0, c0 = time.perf_counter(), time.process_time()
            outcome = pbm_ann(loop, model, rpm, None, log_each=False)
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
            t = outcome.totals
            parts.append((t["provider_wall_time_s"], t["pbm_wall_time_s"], timer.seconds, timer.calls, steps.seconds))
            if k < len(speeds):
                s = outcome.result.summary()
                finals.append((rpm, [float(s[q].iloc[-1]) for q in ("d10", "d50", "d90")]))
    finally:
        timer.close()
        steps.close()
    print(f"one PBM-ANN batch, {label} ({repeat} warm batches at {', '.join(f'{s:g}' for s in speeds)} rpm):")
    print(f"  wall {spread(walls)}; CPU {spread(cpus)}")
    k = int(np.argsort(walls)[len(walls) // 2])
    surrogate, pbm, selection, calls, compiled = parts[k]
    print(
        f"  the median batch ({1e3 * walls[k]:.2f} ms): surrogate {1e3 * surrogate:.2f} ms, PBM {1e3 * pbm:.2f} ms "
        f"(of it the compiled step loop {1e3 * compiled:.2f} ms, the breakage selection in Python "
        f"{1e3 * selection:.2f} ms in {calls} evaluations: the first step of a run; the compiled loop evaluates it "
        f"at the others), rest of the loop {1e3 * (walls[k] - surrogate - pbm):.2f} ms"
    )
    for rpm, final in finals:
        print(f"  final d10 / d50 / d90 at {rpm:g} rpm: " + " / ".join(f"{1e3 * q:.9f}" for q in final) + " mm")


def throughput(loop, model_path, n: int, jobs: int, n_members: int, speeds, rounds: int) -> None:
    from pbmdem.design.batches import Case, run_cases

    members = (None, *range(n_members))
    lo, hi = min(speeds), max(speeds)
    cases = [Case(lo + (hi - lo) * k / max(n - 1, 1), member=members[k % len(members)]) for k in range(n)]
    for j in sorted({1, jobs}):
        per_minute = []
        for r in range(rounds):
            t0, c0 = time.perf_counter(), cpu_seconds()
            outcomes = run_cases(loop, model_path, cases, j)
            wall, cpu = time.perf_counter() - t0, cpu_seconds() - c0
            failed = sum(bool(o.failed) for o in outcomes)
            per_minute.append(60 * len(outcomes) / wall)
            print(
                f"{len(outcomes)} PBM-ANN batches (mean and {n_members} members) on {j} process(es): round {r + 1}, "
                f"wall {wall:.2f} s, CPU {cpu:.2f} s ({1e3 * cpu / len(outcomes):.2f} ms per batch): "
                f"{per_minute[-1]:.0f} batches per minute; {failed} failed"
            )
        v = np.asarray(per_minute)
        print(
            f"  batches per minute on {j} process(es), {rounds} round(s): "
            f"min {v.min():.0f} / median {np.median(v):.0f} / max {v.max():.0f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=None, help="a trained surrogate (default: results/surrogate/model.skops)")
    parser.add_argument("--config", default=None, help="default: config/config.yaml (--quick: config/test.yaml)")
    parser.add_argument("--repeat", type=int, default=30, help="warm single batches per kind (>= 20 for a statement)")
    parser.add_argument("--batches", type=int, default=2000, help="batches of the throughput measurement")
    parser.add_argument("--rounds", type=int, default=3, help="throughput measurements per process count")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--quick", action="store_true", help="a small surrogate and a few batches (smoke test)")
    args = parser.parse_args()

    import tempfile

    from pbmdem.config import load_config
    from pbmdem.surrogate import load_surrogate
    from pbmdem.surrogate._threads import single_threaded

    cfg = load_config(args.config or ROOT / "config" / ("test.yaml" if args.quick else "config.yaml"))
    loop = cfg.coupled_loop()
    tmp = tempfile.TemporaryDirectory()
    model_path = args.model
    if model_path is None and args.quick:
        import quick

        model_path = quick.surrogate(Path(tmp.name), cfg)
        print(f"surrogate: a small one trained on synthetic tables ({model_path})")
    elif model_path is None:
        model_path = str(ROOT / "results/surrogate/model.skops")
    repeat, batches, rounds = (3, 12, 2) if args.quick else (args.repeat, args.batches, args.rounds)
    print(f"load average before: {', '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs")
    model = load_surrogate(model_path)
    speeds = [float(r) for r in cfg.validation.rpm]
    with single_threaded():
        one_batch(loop, model, speeds, repeat, "breakage on" if loop.batch.pbm.breakage.enabled else "breakage off")
        if loop.batch.pbm.breakage.enabled:
            one_batch(without_breakage(loop), model, speeds, repeat, "breakage off")
    grid = [float(r) for r in cfg.grid.impeller_rpm]
    throughput(loop, model_path, batches, args.jobs, model.n_members, grid, rounds)
    print(f"load average after: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    tmp.cleanup()


if __name__ == "__main__":
    main()
