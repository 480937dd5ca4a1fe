"""The `pbmdem pbm` command: the population balance model of one batch with a constant kernel,
the DEM collision table, or PBM-ANN (the surrogate refreshed at every coupling interval, as in the
validation): a row of `pbmdem.cli.COMMANDS`, here because PBM-ANN is a coupled loop."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from pbmdem.config import RPM_MAX, check_rpm, load_config
from pbmdem.pbm.errors import PBMInputError
from pbmdem.pbm.impact_breakage import impact_selection
from pbmdem.pbm.kernels import TableFrequency
from pbmdem.pbm.results import floor_words
from pbmdem.pbm.setup import run_batch
from pbmdem.pbm.wall_table import WallTable

from .methods import pbm_ann

EXAMPLES = """examples:
  pbmdem pbm --config config/config.yaml --kernel constant --rpm 600 --out out/constant
  pbmdem pbm --config config/config.yaml --kernel table --table results/dem/collisions.csv \\
      --velocity-table results/dem/impact_velocity.csv --rpm 600 --distribution fine --out out/table
  pbmdem pbm --config config/config.yaml --kernel ann --model results/surrogate/model.skops \\
      --rpm 900 --distribution medium --out out/ann
"""


def _pbm(args: argparse.Namespace) -> int:
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
        source = _table_source(batch, args) if args.kernel == "table" else None
        selection = impact_selection(batch.pbm, source) if source is not None else None
        result = run_batch(batch, source, rpm, selection=selection)
    result.info.update(info)
    floor = result.info["grid_floor"]  # breakage fragments merged at the grid's first pivot (run.json)
    if floor["flagged"]:
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


def add_options(pbm: argparse.ArgumentParser) -> None:
    """The description, examples and options of `pbmdem pbm`."""
    pbm.description = "Run the PBM for one impeller speed and size distribution."
    pbm.epilog = EXAMPLES
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
