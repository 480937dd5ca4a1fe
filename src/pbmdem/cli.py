"""pbmdem: wet granulation in a high-shear granulator, from DEM collisions to granule sizes.

    pbmdem dem --config config/config.yaml --rpm 600 --distribution fine [--replicate K] [--plan-only]
    pbmdem view --rpm 600 --distribution fine [--time 0.5] [--screenshot out.png]
    pbmdem pbm --config ... --kernel constant|table|ann --rpm 600 [--distribution fine] --out DIR
    pbmdem surrogate train|predict ...
    pbmdem design-space --config ... --model MODEL --out DIR
    pbmdem calibrate --config ... --model MODEL --data measured.csv --out DIR
    pbmdem config --show-defaults | --schema | --check FILE

Every subcommand reads its configuration through `pbmdem.config.load_config` (validated once,
defaults filled in), the same path the workflow takes. Bad input gets one line naming the file,
key or flag, the value and what is allowed, and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from pbmdem import __version__, layout
from pbmdem.config import RPM_MAX
from pbmdem.config import describe as config_cli
from pbmdem.dem import viewer
from pbmdem.design import cli as design_cli
from pbmdem.surrogate import cli as surrogate_cli


def _dem(args: argparse.Namespace) -> int:
    from pbmdem.config import check_rpm, load_config, rpm_text
    from pbmdem.dem import plan_point, run_point
    from pbmdem.dem.plan import check_limits

    rpm = check_rpm(args.rpm, "--rpm")
    cfg = load_config(args.config)
    point = cfg.dem_point(args.distribution)
    if not 0 <= args.replicate < cfg.dem_replicates:
        raise ValueError(f"--replicate {args.replicate}: allowed 0 .. dem.replicates - 1 = {cfg.dem_replicates - 1}")
    plan = check_limits(plan_point(point, rpm, replicate=args.replicate), cfg.dem_execution.limits)
    if args.plan_only:
        from pbmdem.dem.estimate import duration_text, measured_throughput

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
    summary = run_point(point, plan, out, cfg.dem_execution, force=args.force, progress_bar=bar)
    print(json.dumps(summary, indent=2))
    return 0


def _pbm(args: argparse.Namespace) -> int:
    from pbmdem.config import check_rpm, load_config

    rpm = check_rpm(args.rpm, "--rpm")
    cfg = load_config(args.config)
    distribution = args.distribution or cfg.grid.size_distributions[0]
    batch = cfg.pbm_batch(distribution)
    for flag, value, kernels in (
        ("--table", args.table, ("table",)),
        ("--velocity-table", args.velocity_table, ("table",)),
        ("--wall-table", args.wall_table, ("table",)),
        ("--wall-velocity-table", args.wall_velocity_table, ("table",)),
        ("--model", args.model, ("ann",)),
    ):
        if value is not None and args.kernel not in kernels:
            raise ValueError(
                f"{flag} {value} is read with --kernel {' or '.join(kernels)} only, not --kernel {args.kernel}"
            )
    info: dict = {"kernel_source": args.kernel}
    if args.kernel == "ann":
        from pbmdem.coupling import pbm_ann

        if args.model is None:
            raise ValueError("--kernel ann needs --model PATH (a saved surrogate, results/surrogate/model.skops)")
        outcome = pbm_ann(cfg.coupled_loop().replace(batch=batch), args.model, rpm, args.out)
        result = outcome.result
        totals = outcome.totals
        info["coupling_intervals"] = totals["intervals"]
        if totals.get("out_of_domain_count"):
            messages = sorted({r["out_of_domain"] for r in outcome.intervals if r.get("out_of_domain")})
            print(
                f"warning: the surrogate was evaluated outside its training domain in "
                f"{totals['out_of_domain_intervals']} of {totals['intervals']} coupling intervals "
                f"({totals['out_of_domain_count']} warnings); " + "; ".join(messages),
                file=sys.stderr,
            )
        info["surrogate_domain"] = {k: totals.get(k, 0) for k in ("out_of_domain_count", "out_of_domain_intervals")}
    else:
        from pbmdem.pbm.impact_breakage import impact_selection
        from pbmdem.pbm.setup import run_batch

        source = _table_source(batch, args) if args.kernel == "table" else None
        selection = impact_selection(batch.pbm, source) if source is not None else None
        result = run_batch(batch, source, rpm, selection=selection)
    result.info.update(info)
    floor = result.info["grid_floor"]  # breakage fragments merged at the grid's first pivot (run.json)
    if floor["flagged"]:
        from pbmdem.pbm.results import floor_words

        print(f"warning: {floor_words(floor, f'this batch ({distribution}, {rpm:g} rpm)')}", file=sys.stderr)
    paths = result.save(args.out)
    last = result.summary().iloc[-1]
    print(
        json.dumps(
            {
                "out": str(args.out),
                "files": sorted(p.name for p in paths.values()),
                "d50_final_m": float(last["d50"]),
                "number_mean_diameter_final_m": float(last["number_mean_diameter"]),
                "steps": int(result.info["steps"]),
                "wall_time_s": round(result.info["wall_time_s"], 3),
                "grid_floor_merged_fraction": floor["merged_fraction"],
            },
            indent=2,
        )
    )
    return 0


def _table_source(batch, args):
    from pbmdem.pbm.errors import PBMInputError
    from pbmdem.pbm.kernels import TableFrequency
    from pbmdem.pbm.wall_table import WallTable

    success = batch.pbm.aggregation.success
    if args.table is None:
        raise PBMInputError("--kernel table needs --table PATH (a DEM collision table CSV)")
    if args.velocity_table is None and success.velocity_resolved:
        raise PBMInputError(
            f"pbm.aggregation.success.velocity_model = {success.velocity_model!r} needs impact "
            "velocities: --kernel table needs --velocity-table PATH (results/dem/impact_velocity.csv)"
        )
    if batch.pbm.breakage.enabled and (args.wall_table is None or args.wall_velocity_table is None):
        raise PBMInputError(
            "pbm.breakage.enabled = true: --kernel table needs --wall-table PATH and --wall-velocity-table "
            "PATH (results/dem/wall_collisions.csv, wall_impact_velocity.csv) for the selection from impacts"
        )
    walls = None
    if batch.pbm.breakage.enabled:
        walls = WallTable.from_csv(args.wall_table, args.wall_velocity_table, batch.distribution)
    # one distribution's rows: the grid's distributions have different class sizes
    return TableFrequency.from_csv(
        args.table,
        distribution=batch.distribution,
        velocity_path=args.velocity_table,
        walls=walls,
        extrapolation=batch.pbm.aggregation.table_extrapolation,
    )


DESCRIPTION = """pbmdem models wet granulation in a high-shear granulator: LIGGGHTS DEM runs give
collision frequencies between granule size classes, a surrogate (the best of a neural-network
ensemble, Kriging and a response surface on held-out runs) learns them, and a population balance
model (PBM) turns them into granule growth (d10/d50/d90 over the batch). The whole study runs with
`snakemake --cores 2`; these commands do one step by hand."""

EXAMPLES = """examples:
  pbmdem dem --config config/config.yaml --rpm 600 --distribution fine --plan-only
  pbmdem view --rpm 600 --distribution fine --time 0.5 --screenshot shot.png
  pbmdem pbm --config config/config.yaml --kernel ann --model results/surrogate/model.skops --rpm 900 --out out/
  pbmdem surrogate predict --model results/surrogate/model.skops --table results/dem/collisions.csv
  pbmdem design-space --config config/config.yaml --model results/surrogate/model.skops --out out/design
  pbmdem calibrate --config config/config.yaml --model results/surrogate/model.skops \
      --data results/design/measured_pbm_dem.csv --out out/calibration

Run `pbmdem COMMAND --help` for the options and examples of each command."""

DEM_EXAMPLES = """examples:
  pbmdem dem --config config/config.yaml --rpm 600 --distribution fine --plan-only   # plan and runtime estimate
  pbmdem dem --config config/config.yaml --rpm 600 --distribution fine               # results/dem/rpm600_fine/rep0
  pbmdem dem --config config/config.yaml --rpm 900 --distribution coarse --replicate 2 --out /tmp/run
"""

PBM_EXAMPLES = """examples:
  pbmdem pbm --config config/config.yaml --kernel constant --rpm 600 --out out/constant
  pbmdem pbm --config config/config.yaml --kernel table --table results/dem/collisions.csv \\
      --velocity-table results/dem/impact_velocity.csv --rpm 600 --distribution fine --out out/table
  pbmdem pbm --config config/config.yaml --kernel ann --model results/surrogate/model.skops \\
      --rpm 900 --distribution medium --out out/ann
"""

SURROGATE_EXAMPLES = """examples:
  pbmdem surrogate train --config config/config.yaml --table results/dem/collisions.csv \\
      --velocity-table results/dem/impact_velocity.csv --out out/surrogate
  pbmdem surrogate predict --model results/surrogate/model.skops --table results/dem/collisions.csv
"""

DESIGN_EXAMPLES = """examples:
  pbmdem design-space --config config/config.yaml --model results/surrogate/model.skops --out out/design
  pbmdem design-space --config my.yaml --model results/surrogate/model.skops --out out/design --jobs 1
"""

CALIBRATE_EXAMPLES = """examples:
  pbmdem calibrate --config config/config.yaml --model results/surrogate/model.skops \\
      --data results/design/measured_pbm_dem.csv --out out/calibration
  pbmdem calibrate --config my.yaml --model results/surrogate/model.skops --data measured.csv \\
      --parameters pbm.aggregation.beta0 --out out/beta0

The measured table (docs/calibration.md): columns rpm, time (s), d10, d50, d90 (m) and d10_sd,
d50_sd, d90_sd (m), one row per speed and time, times ascending per speed."""


def _dem_options(dem: argparse.ArgumentParser) -> None:
    """The options of `pbmdem dem`."""
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


def _pbm_options(pbm: argparse.ArgumentParser) -> None:
    """The options of `pbmdem pbm`."""
    pbm.add_argument("--config", required=True, type=Path, help="workflow config (YAML)")
    pbm.add_argument(
        "--kernel",
        choices=["constant", "table", "ann"],
        default="constant",
        help="collision-frequency source: constant c_ij, the DEM collision table, or PBM-ANN (the "
        "surrogate, refreshed at each of validation.coupling_intervals, as in the validation)",
    )
    pbm.add_argument("--table", type=Path, help="collision table CSV (with --kernel table)")
    pbm.add_argument(
        "--velocity-table",
        type=Path,
        default=None,
        help="impact-velocity table CSV (results/dem/impact_velocity.csv; with --kernel table); "
        "needed when pbm.aggregation.success.velocity_model is not 'none'",
    )
    for flag, name in (("--wall-table", "wall_collisions.csv"), ("--wall-velocity-table", "wall_impact_velocity.csv")):
        pbm.add_argument(
            flag,
            type=Path,
            default=None,
            help=f"results/dem/{name} (with --kernel table); needed when pbm.breakage.enabled is true",
        )
    pbm.add_argument("--model", type=Path, help="surrogate model file (with --kernel ann)")
    pbm.add_argument("--rpm", required=True, help=f"impeller speed (1/min), 0 < rpm <= {RPM_MAX}")
    pbm.add_argument("--distribution", default=None, help="size distribution name (default: first of the grid)")
    pbm.add_argument("--out", required=True, type=Path, help="output folder (tables, plots, run.json)")
    pbm.set_defaults(func=_pbm)


#: Every command of `pbmdem`: (name, one-line help, description, examples, options), where
#: options(parser) adds the command's arguments and its handler (`set_defaults(func=...)`). A new
#: command is one more row.
COMMANDS = (
    (
        "dem",
        "run one DEM operating point with LIGGGHTS (or only plan it, with a runtime estimate)",
        "Run LIGGGHTS for one operating point (impeller speed x size distribution) and tabulate its "
        "collisions between size classes.",
        DEM_EXAMPLES,
        _dem_options,
    ),
    (
        "pbm",
        "run the population balance model of the batch granulator",
        "Run the PBM for one impeller speed and size distribution.",
        PBM_EXAMPLES,
        _pbm_options,
    ),
    (
        "view",
        "show a DEM run (particles coloured by size, impeller) at a time in seconds",
        viewer.__doc__.split("\n\n")[1].strip(),
        viewer.EXAMPLES,
        viewer.add_options,
    ),
    (
        "surrogate",
        "encounter surrogate: train the model families, predict",
        "Train or query the encounter surrogate (encounter frequency and impact-velocity distribution per class pair).",
        SURROGATE_EXAMPLES,
        surrogate_cli.add_options,
    ),
    (
        "design-space",
        "PBM-ANN over impeller speed x binder rate x a third factor: final sizes and the specification region",
        "Run PBM-ANN (ensemble mean and every member) over the grid of the config's design_space section "
        "and write the table, the maps and the figures of merit.",
        DESIGN_EXAMPLES,
        design_cli.design_space_options,
    ),
    (
        "calibrate",
        "estimate PBM parameters from measured d10/d50/d90 over time with PBM-ANN",
        "Least-squares estimate of the pbm settings of calibration.parameters (or --parameters) from a "
        "measured size table, with confidence intervals that hold the measurement error and the "
        "surrogate's uncertainty, their correlation, the residuals and a fit figure.",
        CALIBRATE_EXAMPLES,
        design_cli.calibrate_options,
    ),
    (
        "config",
        "list every setting with its default, print the config schema, or check a config file",
        "Every setting of a pbmdem configuration, declared once in pbmdem.config.",
        config_cli.EXAMPLES,
        config_cli.add_options,
    ),
)


def build_parser() -> argparse.ArgumentParser:
    """The `pbmdem` parser: one subcommand per row of :data:`COMMANDS`, each with its examples."""
    parser = argparse.ArgumentParser(
        prog="pbmdem", description=DESCRIPTION, epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"pbmdem {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, help_, description, examples, options in COMMANDS:
        command = sub.add_parser(
            name,
            help=help_,
            description=description,
            epilog=examples,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        options(command)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, RuntimeError, OSError) as exc:
        print(f"pbmdem: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
