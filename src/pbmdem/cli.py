"""The `pbmdem` command line.

    pbmdem dem --config config/config.yaml --rpm 600 --distribution fine --out results/dem/rpm600_fine/rep0
    pbmdem view RUN_DIR [--step N] [--screenshot out.png]
    pbmdem pbm --config ... --kernel constant|table|ann ...
    pbmdem surrogate train|predict ...

Each stage registers its own subcommand (`add_cli(subparsers)` in its module).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys


def _dem(args: argparse.Namespace) -> int:
    from pbmdem.config import check_rpm, load_config
    from pbmdem.dem import plan_point, run_point

    rpm = check_rpm(args.rpm, "--rpm")
    cfg = load_config(args.config)
    plan = plan_point(cfg, rpm, args.distribution, replicate=args.replicate)
    if args.plan_only:
        print(json.dumps(plan.__dict__, indent=2))
        return 0
    # progress: a bar on a terminal, plain log lines (at least every ~10 s) otherwise
    bar = sys.stderr.isatty()
    if not bar:
        logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", stream=sys.stderr)
    summary = run_point(cfg, plan, args.out, timeout=cfg["dem"].get("timeout"), force=args.force, progress_bar=bar)
    print(json.dumps(summary, indent=2))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="pbmdem", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    dem = sub.add_parser("dem", help="run one DEM operating point with LIGGGHTS")
    dem.add_argument("--config", required=True, help="workflow config (YAML)")
    dem.add_argument("--rpm", required=True, help="impeller speed (1/min), 0 < rpm <= 20000")
    dem.add_argument("--distribution", required=True, help="size distribution name from the config")
    dem.add_argument("--replicate", type=int, default=0, help="replicate (insertion seeds), 0 .. dem.replicates-1")
    dem.add_argument("--out", default=None, help="run folder (default results/dem/<point id>/rep<replicate>)")
    dem.add_argument("--plan-only", action="store_true", help="print the run plan and stop")
    dem.add_argument("--force", action="store_true",
                     help="replace a finished run in the run folder (refused otherwise: it would make "
                          "Snakemake redo everything downstream of that point)")
    dem.set_defaults(func=_dem)

    from pbmdem import viewer

    viewer.add_cli(sub)
    from pbmdem.pbm import cli as pbm_cli

    pbm_cli.add_cli(sub)
    from pbmdem.surrogate import cli as surrogate_cli

    surrogate_cli.add_cli(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if getattr(args, "command", None) == "dem" and args.out is None:
            from pbmdem.config import check_rpm
            from pbmdem.dem import point_id

            args.out = f"results/dem/{point_id(check_rpm(args.rpm, '--rpm'), args.distribution)}/rep{args.replicate}"
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, RuntimeError, OSError) as exc:
        print(f"pbmdem: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
