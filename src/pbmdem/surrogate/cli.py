"""The ``pbmdem surrogate train|predict`` subcommands (a row of ``pbmdem.cli.COMMANDS``)."""

from __future__ import annotations

import argparse
import json
import logging
import sys
import warnings
from pathlib import Path

import numpy as np

from pbmdem.config import check_rpm, load_config, point_id
from pbmdem.impact import VELOCITY_EDGES
from pbmdem.tables import GRID_PAIRS

from .domain import OutOfDomainWarning
from .persistence import load_surrogate
from .train import train_and_report

TRAIN_EXAMPLES = """examples:
  pbmdem surrogate train --config config/config.yaml --table results/dem/collisions.csv \\
      --velocity-table results/dem/impact_velocity.csv --out out/surrogate --jobs 2
"""

PREDICT_EXAMPLES = """examples:
  pbmdem surrogate predict --model results/surrogate/model.skops --table results/dem/collisions.csv --output pred.csv
  pbmdem surrogate predict --model results/surrogate/model.skops --diameters 0.002 0.004 \\
      --numbers 500 100 --rpm 900
"""


#: ``pbmdem surrogate --help``: the examples of both subcommands
EXAMPLES = TRAIN_EXAMPLES + PREDICT_EXAMPLES.removeprefix("examples:\n")


def add_options(parser: argparse.ArgumentParser) -> None:
    """The description, examples and options of ``pbmdem surrogate``: its subcommands ``train`` and ``predict``."""
    parser.description = (
        "Train or query the encounter surrogate (encounter frequency and impact-velocity distribution per class pair)."
    )
    parser.epilog = EXAMPLES
    sub = parser.add_subparsers(dest="surrogate_command", required=True)

    train = sub.add_parser(
        "train",
        help="train on a collision table (grouped CV, baselines, parity plot)",
        epilog=TRAIN_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    train.add_argument("--table", required=True, type=Path, help="aggregated collision table (CSV)")
    train.add_argument(
        "--velocity-table",
        type=Path,
        default=None,
        help="impact-velocity table (results/dem/impact_velocity.csv); without it only the "
        "encounter frequency is learned",
    )
    train.add_argument(
        "--config",
        type=Path,
        required=True,
        help="workflow config YAML (its surrogate: section and the impeller radius "
        "granulator.impeller.blade_length of the tip-speed feature)",
    )
    train.add_argument(
        "--out", required=True, type=Path, help="output folder: model.skops, model.json, metrics.csv, parity.png"
    )
    train.add_argument("--jobs", type=int, default=None, help="parallel jobs of the grid search")
    train.set_defaults(func=_train)

    pred = sub.add_parser(
        "predict",
        help="predict collision frequencies with a saved surrogate",
        epilog=PREDICT_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    pred.add_argument("--model", required=True, type=Path, help="model.skops (model.json beside it)")
    pred.add_argument("--metadata", type=Path, default=None, help="metadata JSON (default: model.json)")
    src = pred.add_mutually_exclusive_group(required=True)
    src.add_argument("--table", type=Path, help="collision table CSV: predict every row")
    src.add_argument("--diameters", type=float, nargs="+", help="class diameters (m) of one distribution")
    pred.add_argument("--numbers", type=float, nargs="+", help="particles per class (with --diameters)")
    pred.add_argument("--rpm", type=float, help="impeller speed (with --diameters)")
    pred.add_argument(
        "--output", type=Path, default=None, help="CSV (table mode) or JSON (matrix mode); default stdout"
    )
    pred.set_defaults(func=_predict)


def _train(args) -> int:
    cfg = load_config(args.config)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    meta = train_and_report(
        args.table,
        args.out / "model.skops",
        settings=cfg.surrogate.to_dict(),
        impeller_radius=cfg.granulator.impeller.tip_radius,
        n_jobs=args.jobs,
        velocity_table=args.velocity_table,
        pbm_samples=[point_id(p.rpm, p.distribution) for p in cfg.grid.extra_points],
    )
    summary = meta["cv_scores"]["outer_summary"]
    for name, s in summary.items():
        print(
            f"{name:9s} held-out R2(log10 c) {_fmt(s['pooled_r2_log10'])} (replicate noise floor "
            f"{_fmt(s['noise_floor_r2_log10'])})  MAE {_fmt(s['pooled_mae_log10'])} decades"
            + (f"  90 % interval coverage {_fmt(s['coverage_90'])}" if s.get("coverage_90") is not None else "")
        )
    for name, s in meta["cv_scores"]["velocity_summary"].items():
        print(
            f"{name:9s} held-out median impact speed MAE {_fmt(s['pooled_mae_log10'])} decades, "
            f"bin-fraction distance (TV) {_fmt(s['pooled_tv_distance'])}"
        )
    print(f"pair encounter frequency: {meta['family']} ({meta['cv_scores']['selection']})")
    print(f"impact-speed law: {meta['velocity_family']} ({meta['cv_scores']['speed_law_selection']})")
    if meta.get("speed_tail"):
        t = meta["speed_tail"]
        tail = f"a {t['a']:.3g}, beta {t['beta']:.3g}, members' sd of ln a {t['sd_ln_a_between_runs']:.3g}"
        print(f"pooled fast tail from {t['from_m_s']:.3g} m/s: {tail}")
    print(f"wrote {args.out}/model.skops, model.json, metrics.csv, parity.png")
    return 0


def _fmt(x) -> str:
    return "n/a" if x is None else f"{x:.3f}"


def _predict(args) -> int:
    model = load_surrogate(args.model, args.metadata)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", OutOfDomainWarning)
        if args.table is not None:
            table = GRID_PAIRS.read(args.table, need=())  # the features' columns: checked by the model
            log_c, std = model.predict_log10(table, return_std=True)
            out = table.assign(predicted_encounter_frequency_per_pair=10.0**log_c, predicted_std_log10=std)
            if model.has_velocity_model():
                mu, sigma = model.predict_velocity(table, check_domain=False)
                out = out.assign(predicted_impact_velocity_median=10.0**mu, predicted_impact_velocity_sigma_log10=sigma)
            out.to_csv(args.output or sys.stdout, index=False)
        else:
            if args.numbers is None or args.rpm is None:
                raise SystemExit("--diameters needs --numbers and --rpm")
            args.rpm = check_rpm(args.rpm, "--rpm")
            for flag, values in (("--diameters", args.diameters), ("--numbers", args.numbers)):
                bad = [v for v in values if not np.isfinite(v) or v <= 0]
                if bad:
                    raise ValueError(f"{flag} = {bad[0]!r}: every value must be a finite number > 0")
            c, s = model.frequency_matrix(np.array(args.diameters), np.array(args.numbers), args.rpm, return_std=True)
            result = {
                "diameters": args.diameters,
                "numbers": args.numbers,
                "rpm": args.rpm,
                "encounter_frequency_per_pair": c.tolist(),
                "std_log10": s.tolist(),
            }
            if model.has_velocity_model():
                rates = model.encounters(np.array(args.diameters), np.array(args.numbers), args.rpm, check_domain=False)
                result.update(
                    velocity_edges=VELOCITY_EDGES.tolist(), velocity_fractions=rates.velocity_fractions.tolist()
                )
            text = json.dumps(result, indent=2)
            if args.output:
                args.output.write_text(text + "\n", encoding="utf-8")
            else:
                print(text)
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)
    return 0
