"""The `pbmdem dem` command: one DEM operating point with LIGGGHTS, or only its plan with a
runtime estimate (a row of `pbmdem.cli.COMMANDS`)."""

from __future__ import annotations

import argparse
import json
import logging
import sys

from pbmdem import layout
from pbmdem.config import RPM_MAX, check_rpm, load_config, rpm_text

from .estimate import duration_text, measured_throughput
from .plan import check_limits, plan_point
from .run import run_point

EXAMPLES = """examples:
  pbmdem dem --config config/config.yaml --rpm 600 --distribution fine --plan-only   # plan and runtime estimate
  pbmdem dem --config config/config.yaml --rpm 600 --distribution fine               # results/dem/rpm600_fine/rep0
  pbmdem dem --config config/config.yaml --rpm 900 --distribution coarse --replicate 2 --out /tmp/run
"""


def _dem(args: argparse.Namespace) -> int:
    rpm = check_rpm(args.rpm, "--rpm")
    cfg = load_config(args.config)
    point = cfg.dem_point(args.distribution)
    if not 0 <= args.replicate < cfg.dem_replicates:
        raise ValueError(f"--replicate {args.replicate}: allowed 0 .. dem.replicates - 1 = {cfg.dem_replicates - 1}")
    plan = check_limits(plan_point(point, rpm, replicate=args.replicate), cfg.dem_execution.limits)
    if args.plan_only:
        throughput = measured_throughput(args.runs)
        ranks = cfg.dem_execution.mpi_ranks
        seconds = throughput.seconds(plan.particle_steps, plan.n_particles, ranks)
        estimate = {
            "wall_time_s": round(seconds, 1),
            "particle_steps": plan.particle_steps,
            "particle_steps_per_s": round(throughput.rate(plan.n_particles)),
            "mpi_ranks": ranks,
            "from": throughput.source,
        }
        print(json.dumps({**plan.to_dict(), "runtime_estimate": estimate}, indent=2))
        print(
            f"estimated LIGGGHTS wall time: {duration_text(seconds)} ({plan.particle_steps / 1e6:.0f} M "
            f"particle-steps at {throughput.rate(plan.n_particles) / 1e6:.2f} M/s per rank, {ranks} rank(s); "
            f"from {throughput.source})",
            file=sys.stderr,
        )
        return 0
    out = args.out or layout.dem_run(rpm_text(rpm), args.distribution, args.replicate)
    # progress: a bar on a terminal, plain log lines (at least every ~10 s) otherwise
    bar = sys.stderr.isatty()
    if not bar:
        logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", stream=sys.stderr)
    summary = run_point(plan, out, cfg.dem_execution, force=args.force, progress_bar=bar)
    print(json.dumps(summary, indent=2))
    return 0


def add_options(dem: argparse.ArgumentParser) -> None:
    """The description, examples and options of `pbmdem dem`."""
    dem.description = (
        "Run LIGGGHTS for one operating point (impeller speed x size distribution) and tabulate its "
        "collisions between size classes."
    )
    dem.epilog = EXAMPLES
    dem.add_argument("--config", required=True, help="workflow config (YAML)")
    dem.add_argument("--rpm", required=True, help=f"impeller speed (1/min), 0 < rpm <= {RPM_MAX}")
    dem.add_argument("--distribution", required=True, help="size distribution name from the config")
    dem.add_argument("--replicate", type=int, default=0, help="replicate (insertion seeds), 0 .. dem.replicates-1")
    dem.add_argument("--out", default=None, help="run folder (default results/dem/<point id>/rep<replicate>)")
    dem.add_argument(
        "--plan-only",
        action="store_true",
        help="print the run plan with an estimate of its wall time (from the measured throughput of "
        "the finished runs in --runs, or the reference machine's) and stop",
    )
    dem.add_argument(
        "--runs",
        default="results/dem/runs.csv",
        help="finished runs whose measured throughput sizes the estimate (default: results/dem/runs.csv)",
    )
    dem.add_argument(
        "--force",
        action="store_true",
        help="replace a finished run in the run folder (refused otherwise: it would make "
        "Snakemake redo everything downstream of that point)",
    )
    dem.set_defaults(func=_dem)
