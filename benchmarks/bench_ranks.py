"""MPI ranks benchmark: one DEM point on 1 and 2 (or more) ranks, with several seeds.

For each number of ranks and each `dem.seed`, runs the point with the real LIGGGHTS
(`mpirun -np N`) and prints the wall time and the total collisions; then the mean +- standard
error of the collisions per rank count (the seeds are the replicates), and whether 1 and N ranks
agree within their combined standard error x 2. Prints figures, asserts nothing.

    .venv/bin/python benchmarks/bench_ranks.py [--config config/test.yaml] [--rpm 600]
        [--distribution small] [--ranks 1 2] [--seeds 20141 30011 40009] [--quick]

``--quick`` (the suite's smoke test, about 10-25 s): the first seed only (no standard errors).
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from pathlib import Path

from pbmdem.config import load_config
from pbmdem.dem.plan import plan_point
from pbmdem.dem.run import run_point

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default=str(ROOT / "config" / "test.yaml"))
    parser.add_argument("--rpm", type=float, default=600)
    parser.add_argument("--distribution", default="small")
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--seeds", type=int, nargs="+", default=[20141, 30011, 40009])
    parser.add_argument("--quick", action="store_true", help="the first seed only (smoke test)")
    args = parser.parse_args()
    if args.quick:
        args.seeds = args.seeds[:1]
    base = load_config(args.config)
    results: dict[int, list[tuple[float, int]]] = {}
    for ranks in args.ranks:
        for seed in args.seeds:
            point = base.dem_point(args.distribution)
            point = point.replace(dem=point.dem.replace(seed=seed))
            plan = plan_point(point, args.rpm)
            execution = base.dem_execution.replace(mpi_ranks=ranks, timeout=3600.0)
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                summary = run_point(plan, tmp, execution)
                wall = time.perf_counter() - t0
            results.setdefault(ranks, []).append((summary["liggghts_wall_time_s"], summary["total_collisions"]))
            print(
                f"ranks {ranks} seed {seed}: {plan.n_particles} particles, "
                f"LIGGGHTS {summary['liggghts_wall_time_s']:.1f} s "
                f"(point {wall:.1f} s), {summary['total_collisions']} collisions",
                flush=True,
            )
    stats = {}
    for ranks, rows in results.items():
        walls, counts = [w for w, _ in rows], [c for _, c in rows]
        mean = statistics.mean(counts)
        se = statistics.stdev(counts) / math.sqrt(len(counts)) if len(counts) > 1 else float("nan")
        stats[ranks] = (mean, se)
        print(
            f"ranks {ranks}: LIGGGHTS wall {statistics.mean(walls):.1f} s (mean of {len(walls)}), "
            f"total collisions {mean:.0f} +- {se:.0f} (SE)"
        )
    if 1 in stats:
        for ranks, (mean, se) in stats.items():
            if ranks == 1:
                continue
            diff, combined = mean - stats[1][0], math.hypot(se, stats[1][1])
            print(f"{ranks} vs 1 ranks: difference {diff:+.0f} = {diff / combined:+.2f} combined SE")


if __name__ == "__main__":
    main()
