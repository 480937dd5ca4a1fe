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
import importlib
import sys

from pbmdem import __version__

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

#: Every command of `pbmdem`: (name, one-line help, "module:function"), where function(parser), in
#: the command's own module, adds the command's description, examples, arguments and handler
#: (`set_defaults(func=...)`). A new command is one more row.
COMMANDS = (
    (
        "dem",
        "run one DEM operating point with LIGGGHTS (or only plan it, with a runtime estimate)",
        "dem.cli:add_options",
    ),
    ("pbm", "run the population balance model of the batch granulator", "coupling.cli:add_options"),
    ("view", "show a DEM run (particles coloured by size, impeller) at a time in seconds", "dem.viewer:add_options"),
    ("surrogate", "encounter surrogate: train the model families, predict", "surrogate.cli:add_options"),
    (
        "design-space",
        "PBM-ANN over impeller speed x binder rate x a third factor: final sizes and the specification region",
        "design.cli:design_space_options",
    ),
    (
        "calibrate",
        "estimate PBM parameters from measured d10/d50/d90 over time with PBM-ANN",
        "design.cli:calibrate_options",
    ),
    (
        "config",
        "list every setting with its default, print the config schema, or check a config file",
        "config.describe:add_options",
    ),
)


def build_parser(commands=None) -> argparse.ArgumentParser:
    """The `pbmdem` parser: one subcommand per row of :data:`COMMANDS`, with the options and
    examples of those named in `commands` (default: every one); the others have their name and
    help only, so that their modules are not imported."""
    parser = argparse.ArgumentParser(
        prog="pbmdem", description=DESCRIPTION, epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"pbmdem {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, help_, where in COMMANDS:
        command = sub.add_parser(name, help=help_, formatter_class=argparse.RawDescriptionHelpFormatter)
        if commands is None or name in commands:
            module, function = where.split(":")
            # the command's module only, by name: importing every command's module (scikit-learn,
            # numba, the coupled loops) cost 4.1 s (measured, python -X importtime), `config` needs 0.6 s
            getattr(importlib.import_module(f"pbmdem.{module}"), function)(command)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    # the command is the first word that is not an option (pbmdem's own options take no value)
    parser = build_parser([word for word in argv if not word.startswith("-")][:1])
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, RuntimeError, OSError) as exc:
        print(f"pbmdem: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
