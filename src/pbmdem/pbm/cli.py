"""``pbmdem pbm`` subcommand: one batch granulation run of the PBM (wired in by ``add_cli``).

    pbmdem pbm --config config/config.yaml --kernel constant --rpm 600 --distribution fine --out DIR
    pbmdem pbm --config ... --kernel table --table results/dem/collisions.csv \
        [--velocity-table results/dem/impact_velocity.csv] ...
    pbmdem pbm --config ... --kernel ann --model results/surrogate/model.skops ...
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def add_cli(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser("pbm", help="run the population balance model of the batch granulator",
                              description="Run the PBM for one impeller speed and size distribution.")
    p.add_argument("--config", required=True, type=Path, help="workflow config (YAML) with an optional pbm: section")
    p.add_argument("--kernel", choices=["constant", "table", "ann"], default="constant",
                   help="collision-frequency source: constant c_ij, DEM collision table, or the ANN surrogate")
    p.add_argument("--table", type=Path, help="collision table CSV (with --kernel table)")
    p.add_argument("--velocity-table", type=Path, default=None,
                   help="impact-velocity table CSV (results/dem/impact_velocity.csv; with --kernel table); "
                        "needed when pbm.aggregation.success.velocity_model is not 'none'")
    p.add_argument("--model", type=Path, help="surrogate model file (with --kernel ann)")
    p.add_argument("--rpm", required=True, help="impeller speed (1/min), 0 < rpm <= 20000")
    p.add_argument("--distribution", default=None, help="size distribution name (default: first of the grid)")
    p.add_argument("--out", required=True, type=Path, help="output folder (tables, plots, run.json)")
    p.set_defaults(func=run_cli)
    return p


def make_source(kind: str, config: dict, table=None, model=None, distribution: str | None = None,
                velocity_table=None):
    """The collision-frequency source named on the command line."""
    from .errors import PBMInputError
    from .settings import resolve_settings, velocity_resolved

    settings = resolve_settings(config)
    if velocity_table is not None and kind != "table":
        raise PBMInputError(f"--velocity-table {velocity_table} is read with --kernel table only, not --kernel {kind}")
    if kind == "table" and velocity_table is None and velocity_resolved(settings):
        raise PBMInputError("pbm.aggregation.success.velocity_model = "
                            f"{settings['aggregation']['success']['velocity_model']!r} needs impact velocities: "
                            "--kernel table needs --velocity-table PATH (results/dem/impact_velocity.csv)")
    if kind == "constant":
        from .kernels import ConstantFrequency

        return ConstantFrequency(settings["aggregation"]["constant_frequency"],
                                 settings["aggregation"]["constant_impact_velocity"])
    if kind == "table":
        if table is None:
            raise PBMInputError("--kernel table needs --table PATH (a DEM collision table CSV)")
        from .kernels import TableFrequency

        # one distribution's rows: the grid's distributions have different class sizes
        return TableFrequency.from_csv(table, distribution=distribution, velocity_path=velocity_table,
                                       extrapolation=settings["aggregation"]["table_extrapolation"])
    if kind == "ann":
        if model is None:
            raise PBMInputError("--kernel ann needs --model PATH (a saved collision surrogate)")
        from pbmdem.coupling import SampledSurrogateSource, sample_settings, settings_from_config

        return SampledSurrogateSource(model, sample_settings(settings_from_config(config)))
    raise PBMInputError(f"--kernel {kind!r}; allowed: constant, table, ann")


def run_cli(args) -> int:
    from pbmdem.config import check_rpm, load_config

    from .settings import run_pbm

    args.rpm = check_rpm(args.rpm, "--rpm")
    config = load_config(args.config)
    distribution = args.distribution or config["grid"]["size_distributions"][0]
    source = make_source(args.kernel, config, args.table, args.model, distribution, args.velocity_table)
    result = run_pbm(config, source, args.rpm, distribution)
    result.info["kernel_source"] = args.kernel
    domain = source.domain_report() if hasattr(source, "domain_report") else None
    if domain is not None:
        result.info["surrogate_domain"] = domain
        if domain["out_of_domain_evaluations"]:
            print(f"warning: the surrogate was evaluated outside its training domain in "
                  f"{domain['out_of_domain_evaluations']} of {domain['surrogate_evaluations']} kernel evaluations "
                  f"(by input: {domain['out_of_domain_by_feature']}); first: "
                  + "; ".join(domain["out_of_domain_first"].values()), file=sys.stderr)
    paths = result.save(args.out)
    last = result.summary().iloc[-1]
    print(json.dumps({"out": str(args.out), "files": sorted(p.name for p in paths.values()),
                      "d50_final_m": float(last["d50"]), "number_mean_diameter_final_m": float(last["number_mean_diameter"]),
                      "steps": int(result.info["steps"]), "wall_time_s": round(result.info["wall_time_s"], 3)}, indent=2))
    return 0
