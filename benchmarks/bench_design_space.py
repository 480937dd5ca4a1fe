"""Throughput of many PBM-ANN batches (the design space and the calibration): prints figures, no
assertions.

Runs `--batches` PBM-ANN batches of the default configuration (the validation feed, four coupling
intervals; speeds spread over 300-1200 rpm, the ensemble mean and its members in turn) with
`pbmdem.design.batches.run_cases` on 1 and on `--jobs` processes, and prints for each: wall time,
CPU time of this process and its children, batches per second, and the projected wall time of
1000 batches (the target: at most 60 s on 2 cores). Also one batch split into its parts as the
coupled loop records them (surrogate calls, PBM integration), and what loading the surrogate and
writing the loop's files cost per batch before the batches ran in memory.

The machine is shared: the load average is printed before and after; compare figures of one run.

Run: .venv/bin/python benchmarks/bench_design_space.py [--model results/surrogate/model.skops]
     [--batches 300] [--jobs 2]
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def cpu_seconds() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def cases(n: int, n_members: int):
    from pbmdem.design.batches import Case

    members = (None, *range(n_members))
    return [Case(300.0 + 900.0 * k / max(n - 1, 1), member=members[k % len(members)]) for k in range(n)]


def measure(loop, model, batch_cases, jobs: int) -> dict:
    from pbmdem.design.batches import run_cases

    t0, c0 = time.perf_counter(), cpu_seconds()
    outcomes = run_cases(loop, model, batch_cases, jobs)
    wall, cpu = time.perf_counter() - t0, cpu_seconds() - c0
    return {"wall": wall, "cpu": cpu, "failed": sum(bool(o.failed) for o in outcomes), "n": len(outcomes)}


def parts(loop, model) -> None:
    """One batch as the loop records it, and the costs the in-memory path avoids."""
    from pbmdem.coupling import pbm_ann
    from pbmdem.surrogate import load_surrogate

    t0 = time.perf_counter()
    loaded = load_surrogate(model)
    load = time.perf_counter() - t0
    pbm_ann(loop, loaded, 600.0, None)  # warm
    t0 = time.perf_counter()
    outcome = pbm_ann(loop, loaded, 610.0, None)
    total = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        pbm_ann(loop, model, 620.0, Path(tmp) / "run")  # from the file, as the validation rules run it
        on_disk = time.perf_counter() - t0
    t = outcome.totals
    print(
        f"one PBM-ANN batch in memory: {1e3 * total:.1f} ms = surrogate {1e3 * t['provider_wall_time_s']:.1f} ms "
        f"+ PBM {1e3 * t['pbm_wall_time_s']:.1f} ms + the rest of the loop "
        f"{1e3 * (total - t['total_wall_time_s']):.1f} ms"
    )
    print(
        f"avoided per batch: loading the surrogate {1e3 * load:.0f} ms; loading it and writing the loop's "
        f"files {1e3 * (on_disk - total):.0f} ms (from the file, with an output folder: {1e3 * on_disk:.1f} ms)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=str(ROOT / "results/surrogate/model.skops"))
    parser.add_argument("--config", default=str(ROOT / "config/config.yaml"))
    parser.add_argument("--batches", type=int, default=300)
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()

    from pbmdem.config import load_config
    from pbmdem.design.batches import _surrogate
    from pbmdem.surrogate._threads import single_threaded

    loop = load_config(args.config).coupled_loop()
    print(f"load average before: {os.getloadavg()}; {os.cpu_count()} CPUs")
    n_members = _surrogate(args.model, Path(args.model).stat().st_mtime)[0].n_members
    with single_threaded():
        parts(loop, args.model)
    batch_cases = cases(args.batches, n_members)
    for jobs in sorted({1, args.jobs}):
        m = measure(loop, args.model, batch_cases, jobs)
        rate = m["n"] / m["wall"]
        print(
            f"{m['n']} PBM-ANN batches on {jobs} process(es): wall {m['wall']:.1f} s, CPU {m['cpu']:.1f} s "
            f"({1e3 * m['cpu'] / m['n']:.1f} ms per batch), {rate:.1f} batches/s -> 1000 batches in "
            f"{1000 / rate:.0f} s; {m['failed']} failed"
        )
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
