"""The `pbmdem design-space` and `pbmdem calibrate` commands (rows of `pbmdem.cli.COMMANDS`)."""

from __future__ import annotations

import argparse
import functools
import json
import logging
import sys
from pathlib import Path

from pbmdem.config import load_config
from pbmdem.config.design import pbm_value

from .calibration import Model, calibrate, read_measured
from .outputs import write_design_space, write_estimate

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


def _jobs(jobs: int | None) -> int | None:
    if jobs is not None and jobs < 1:
        raise ValueError(f"--jobs {jobs}: allowed 1 or more processes")
    return jobs


def _model_path(path: Path) -> Path:
    if not path.is_file():
        raise FileNotFoundError(f"--model {path}: no such file (a saved surrogate, results/surrogate/model.skops)")
    return path


def _with_logging(command):
    """`command` with INFO logging on stderr and the coupled loops' per-interval lines held back for
    its duration only (hundreds of batches would flood the terminal)."""

    @functools.wraps(command)
    def run(args: argparse.Namespace) -> int:
        logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr)
        loops = logging.getLogger("pbmdem.coupling")
        level = loops.level
        loops.setLevel(logging.WARNING)
        try:
            return command(args)
        finally:
            loops.setLevel(level)

    return run


def _design_space(args: argparse.Namespace) -> int:
    cfg = load_config(args.config)
    jobs = _jobs(args.jobs)
    design = cfg.design_space if jobs is None else cfg.design_space.replace(n_jobs=jobs)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    table = write_design_space(
        cfg.coupled_loop(),
        _model_path(args.model),
        design,
        out / "design_space.csv",
        out / "design_space.png",
        out / "design_space.json",
    )
    print(json.dumps({"out": str(out), "points": len(table), **table.spec_status.value_counts().to_dict()}, indent=2))
    return 0


def _calibrate(args: argparse.Namespace) -> int:
    cfg = load_config(args.config)
    settings = cfg.calibration
    if args.parameters:
        settings = settings.replace(parameters=tuple(args.parameters))
    loop = cfg.coupled_loop()
    for key in settings.parameters:
        try:
            pbm_value(loop.batch.pbm, key)
        except ValueError as exc:
            raise ValueError(f"--parameters: {exc}") from None
    data = read_measured(args.data, loop.batch.pbm.process.end)
    model = Model(loop, _model_path(args.model), settings.parameters, "ann", n_jobs=_jobs(args.jobs))
    estimate = calibrate(model, data, settings)
    write_estimate(estimate, args.out, title=str(args.data.name))
    print(estimate.table[["parameter", "estimate", "ci_low", "ci_high"]].to_string(index=False))
    for a, b, r in estimate.unidentifiable:
        print(f"warning: {a} and {b} are not identifiable from these data (correlation {r:+.3f})", file=sys.stderr)
    return 0


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", required=True, type=Path, help="workflow config (YAML)")
    parser.add_argument("--model", required=True, type=Path, help="saved surrogate (results/surrogate/model.skops)")
    parser.add_argument("--out", required=True, type=Path, help="output folder")


def design_space_options(design: argparse.ArgumentParser) -> None:
    """The description, examples and options of `pbmdem design-space`."""
    design.description = (
        "Run PBM-ANN (ensemble mean and every member) over the grid of the config's design_space section "
        "and write the table, the maps and the figures of merit."
    )
    design.epilog = DESIGN_EXAMPLES
    _common(design)
    design.add_argument("--jobs", type=int, default=None, help="processes (default: design_space.n_jobs)")
    design.set_defaults(func=_with_logging(_design_space))


def calibrate_options(cal: argparse.ArgumentParser) -> None:
    """The description, examples and options of `pbmdem calibrate`."""
    cal.description = (
        "Least-squares estimate of the pbm settings of calibration.parameters (or --parameters) from a "
        "measured size table, with confidence intervals that hold the measurement error and the "
        "surrogate's uncertainty, their correlation, the residuals and a fit figure."
    )
    cal.epilog = CALIBRATE_EXAMPLES
    _common(cal)
    cal.add_argument("--data", required=True, type=Path, help="measured size table (CSV, docs/calibration.md)")
    cal.add_argument(
        "--parameters", nargs="+", default=None, help="config keys to estimate (default: calibration.parameters)"
    )
    cal.add_argument("--jobs", type=int, default=2, help="processes (default 2)")
    cal.set_defaults(func=_with_logging(_calibrate))
