"""Convergence and cost of the global sensitivity analysis (rule sensitivity): prints figures, no
assertions.

Runs `pbmdem.design.sensitivity.sensitivity` (the rule's library call: SALib's Saltelli sample,
PBM-ANN for the ensemble mean and each member over `--jobs` processes, SALib's estimator) at the
base sample N, 2N and (full mode) 4N, and prints the Sobol' indices of the ensemble mean side by
side with their confidence intervals (the intervals should halve with every fourfold N, and the
indices stay within them), the ranking of the factors by ST of d50 for the mean and each member,
and for each N the batches, wall time, CPU time (this process and its finished children) and
batches per minute. Then the time of single batches, warm, run one after the other in this process:
min / median / max of wall and CPU time.

Full mode: the config's ranges and `--model` (a surrogate of a default run). `--quick`: the tiny
configuration (config/test.yaml) with a small surrogate trained here on synthetic tables, N = 4 and
8 (well under a minute); for a smoke test, not for figures. The machine is shared: the load average
is printed before and after.

Run: .venv/bin/python benchmarks/bench_sensitivity.py [--quick] [--model results/surrogate/model.skops]
     [--config config/config.yaml] [--n 128] [--jobs 2] [--mean-only] [--batches 20]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def cpu_seconds() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def run(loop, model, settings, members: bool) -> tuple:
    from pbmdem.design.sensitivity import sensitivity

    t0, c0 = time.perf_counter(), cpu_seconds()
    table, info = sensitivity(loop, model, settings, members=members)
    return table, info, time.perf_counter() - t0, cpu_seconds() - c0


def side_by_side(tables: dict) -> None:
    """The mean's S1 and ST with their interval half-widths at every N, one line per factor and output."""
    sizes = list(tables)
    head = "".join(f"{'N = ' + str(n):>30s}" for n in sizes)
    for index in ("S1", "ST"):
        print(f"\n{index} of the ensemble mean (± half-width of the interval)")
        print(f"{'output':7s}{'factor':32s}{head}")
        first = tables[sizes[0]]
        mean = first[first.member.astype(str) == "mean"]
        for output, parameter in zip(mean.output, mean.parameter):
            cells = []
            for n in sizes:
                t = tables[n]
                row = t[(t.member.astype(str) == "mean") & (t.output == output) & (t.parameter == parameter)].iloc[0]
                cells.append(f"{row[index]:>20.3f} ± {row[index + '_conf']:.3f}")
            print(f"{output:7s}{parameter:32s}{''.join(cells)}")


def rankings(tables: dict) -> None:
    """The factors by ST of d50, for the mean and each member, at every N."""
    from pbmdem.design.sensitivity import label
    from pbmdem.report.sensitivity import ranking

    print("\nranking by ST of d50 (first to last)")
    for n, t in tables.items():
        d50 = t[t.output == "d50"]
        for member in dict.fromkeys(d50.member.astype(str)):
            order = ranking(d50[d50.member.astype(str) == member])
            print(f"  N = {n:5d} {member:>5s}: " + " > ".join(label(p) for p in order))


def single_batches(loop, model, settings, count: int) -> None:
    """Wall and CPU time of `count` warm batches of the study's first samples, one after the other."""
    import numpy as np

    from pbmdem.design.batches import run_case
    from pbmdem.design.sensitivity import PbmAnnOutputs, salib_problem, sample
    from pbmdem.surrogate._threads import single_threaded

    factors = settings.factors()
    x = sample(salib_problem(factors), settings.base_samples, settings.seed)
    outputs = PbmAnnOutputs(loop, str(model), tuple(f.key for f in factors), None, 1, settings.impeller_rpm.low)
    cases = outputs.cases(x[: count + 1])
    walls, cpus = [], []
    with single_threaded():
        run_case(loop, model, cases[0])  # warm: surrogate loaded, PBM compiled
        for case in cases[1:]:
            t0, c0 = time.perf_counter(), time.process_time()
            run_case(loop, model, case)
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
    for name, values in (("wall", walls), ("CPU", cpus)):
        ms = 1e3 * np.asarray(values)
        print(
            f"  {name:4s} ms per batch (ensemble mean, {len(values)} warm batches in one process): "
            f"min {ms.min():.1f}, median {statistics.median(ms):.1f}, max {ms.max():.1f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="tiny config, synthetic surrogate, N = 4 and 8")
    parser.add_argument("--model", default=str(ROOT / "results/surrogate/model.skops"))
    parser.add_argument("--config", default=str(ROOT / "config/config.yaml"))
    parser.add_argument("--n", type=int, default=None, help="base sample N (default: the config's)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--mean-only", action="store_true", help="the ensemble mean only (no members)")
    parser.add_argument("--batches", type=int, default=20, help="single batches timed")
    args = parser.parse_args()

    import logging

    from pbmdem.config import load_config

    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    tmp = tempfile.TemporaryDirectory()
    if args.quick:
        cfg = load_config(ROOT / "config/test.yaml")
        import quick  # benchmarks/quick.py: a small surrogate on synthetic tables

        model = quick.surrogate(Path(tmp.name), cfg)
        n, factors_of_n = 4, (1, 2)
    else:
        cfg = load_config(args.config)
        model = Path(args.model)
        if not model.exists():
            raise SystemExit(f"surrogate {model} does not exist: run the default workflow or pass --model")
        n, factors_of_n = args.n or cfg.sensitivity.base_samples, (1, 2, 4)
    loop = cfg.coupled_loop()
    settings = cfg.sensitivity.replace(n_jobs=args.jobs)
    print(f"load average before: {os.getloadavg()}; {os.cpu_count()} CPUs; config {cfg.sensitivity.to_dict()}")
    print(f"surrogate {model}")
    tables = {}
    for k in factors_of_n:
        table, info, wall, cpu = run(loop, model, settings.replace(base_samples=k * n), not args.mean_only)
        tables[k * n] = table
        print(
            f"N = {k * n}: {info['batches']} batches ({info['samples']} samples x {info['batches'] // info['samples']} "
            f"surrogates) on {args.jobs} process(es): wall {wall:.1f} s, CPU {cpu:.1f} s, "
            f"{60 * info['batches'] / wall:.0f} batches/min, {1e3 * cpu / info['batches']:.1f} ms CPU per batch; "
            f"out of domain {info['out_of_domain_samples']}, failed {info['failed_samples']}"
        )
    side_by_side(tables)
    rankings(tables)
    print(f"\nsingle batches ({'tiny' if args.quick else 'default'} config):")
    single_batches(loop, model, settings, args.batches)
    print(f"load average after: {os.getloadavg()}")
    tmp.cleanup()


if __name__ == "__main__":
    main()
