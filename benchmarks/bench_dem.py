"""DEM-stage benchmark: engine speed, parse cost and snapshot-interval convergence.

Runs one operating point of a config with the real LIGGGHTS (contact dumps kept), then times the
vectorised parser against a naive line-by-line reader and counts collisions at 1x, 2x and 4x the
snapshot interval. Prints figures; asserts nothing (timings on a shared machine are noisy).

    .venv/bin/python benchmarks/bench_dem.py [--config config/config.yaml] [--rpm 600] [--distribution fine]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from pbmdem.config import load_config
from pbmdem.dem import collisions
from pbmdem.dem.plan import plan_point
from pbmdem.dem.run import run_point


def naive_parse(path: Path) -> int:
    """Line-by-line reader with a Python set per frame (the approach the vectorised parser replaces)."""
    new = 0
    previous: set | None = None
    current: set = set()
    lines = iter(path.read_text().splitlines())
    for line in lines:
        if line.startswith("ITEM: TIMESTEP"):
            if previous is not None or current:
                if previous is not None:
                    new += len(current - previous)
                previous = current
            current = set()
            for _ in range(8):
                next(lines)
            continue
        a, b, delta = line.split()[:3]
        if float(delta) > 0:
            i, j = int(a), int(b)
            current.add((min(i, j), max(i, j)))
    if previous is not None:
        new += len(current - previous)
    return new


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="config/config.yaml")
    parser.add_argument("--rpm", type=float, default=600.0)
    parser.add_argument("--distribution", default="fine")
    args = parser.parse_args()
    cfg = load_config(args.config)
    point = cfg.dem_point(args.distribution)
    point = point.replace(dem=point.dem.replace(keep_contact_dumps=True))
    plan = plan_point(point, args.rpm)
    with tempfile.TemporaryDirectory() as tmp:
        summary = run_point(point, plan, tmp, cfg.dem_execution)
        post = Path(tmp) / "post"
        t0 = time.perf_counter()
        naive_total = naive_parse(post / "pairs.dump")
        naive = time.perf_counter() - t0
        t0 = time.perf_counter()
        analysis = collisions.RunAnalysis(post, plan, cfg.granulator.bowl, cfg.granulator.impeller)
        tables = analysis.tables()
        fast = time.perf_counter() - t0
        pairs = analysis.pairs
        counts = {s: int(len(analysis.pair_events(stride=s)[0].encounter)) for s in (1, 2, 4)}
        size_mb = (post / "pairs.dump").stat().st_size / 1e6
    run = summary["liggghts_wall_time_s"]
    print(
        f"operating point           {plan.point_id}: {plan.n_particles} particles, dt {plan.timestep:.3g} s, "
        f"{plan.settle_steps + plan.spinup_steps + plan.sampling_steps} steps"
    )
    print(f"LIGGGHTS wall time        {run:.1f} s  ({summary['particle_steps_per_s'] / 1e6:.2f} M particle-steps/s)")
    print(f"contact dump              {size_mb:.0f} MB, {pairs.frames} snapshots every {plan.collision_interval} steps")
    print(f"vectorised parse+count    {fast:.2f} s  = {100 * fast / run:.1f} % of the LIGGGHTS run (target < 10 %)")
    print(f"naive line-by-line        {naive:.2f} s  = {100 * naive / run:.1f} % of the LIGGGHTS run")
    print(
        f"new contacts (naive)      {naive_total} (every contact present in the whole record) vs "
        f"vectorised {counts[1]} (in the sampling window)"
    )
    for s, c in counts.items():
        print(
            f"interval {s * plan.collision_interval:4d} steps      {c} new contacts "
            f"({100 * (c - counts[1]) / counts[1]:+.2f} %)"
        )
    print(f"total in table            {int(tables.pairs['collisions'].sum())}")


if __name__ == "__main__":
    main()
