"""Coverage of the calibration's intervals: prints figures, no assertions.

The check of rule calibration_check, PBM-constant's output at the validation speeds with Gaussian
noise of `calibration.proof.noise` x the value, calibrated with PBM-constant from start values
`proof.start_factor` x the truth, repeated over `--seeds` noise seeds. For every parameter it
prints how often the truth lay inside the 95 % interval (the target: about 95 %), for the
profile-likelihood interval the calibration reports and for the curvature interval
exp(ln theta +- z sd) from (J^T J)^-1 that it reported before; the spread of the estimates over the
seeds against the intervals' median half-width; and the sum of squares at the truth against the
minimum (below z^2 = 3.84 for a 95 % profile interval that holds the truth, with one parameter).

Needs a trained surrogate (PBM-constant's frequency per speed is calibrated to it, as in the
validation). About 5-40 s per seed, by the machine's load.

Run: .venv/bin/python benchmarks/bench_calibration.py [--config config/config.yaml]
     [--model results/surrogate/model.skops] [--seeds 30] [--out results/bench_calibration.csv] [--quick]

``--quick`` (the suite's smoke test): config/test.yaml, a surrogate trained here in seconds on
synthetic tables (benchmarks/quick.py), 2 seeds, the rows in a temporary folder.
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]


def coverage_rows(config: str, model_path: str, seeds: int) -> pd.DataFrame:
    from pbmdem.config import load_config
    from pbmdem.config.design import pbm_value
    from pbmdem.design.calibration import Model, Residuals, _z, calibrate
    from pbmdem.design.proof import constant_measured, proof_times, with_noise
    from pbmdem.tables import STATISTICS

    cfg = load_config(config)
    loop, settings = cfg.coupled_loop(), cfg.calibration
    rpms = [float(r) for r in cfg.validation.rpm]
    keys = settings.parameters
    truth = {k: pbm_value(loop.batch.pbm, k) for k in keys}
    start = {k: v * settings.proof.start_factor for k, v in truth.items()}
    times = proof_times(loop, settings.proof.time_step)
    clean, fixed = constant_measured(loop, model_path, rpms, times, 0.0, 0)
    clean = clean.assign(**{f"{s}_sd": 0.0 for s in STATISTICS})
    model = Model(loop, model_path, keys, "constant", fixed=fixed)
    z = _z(settings.confidence)
    rows = []
    for seed in range(seeds):
        began = time.perf_counter()
        data = with_noise(clean, settings.proof.noise, seed)
        est = calibrate(model, data, settings, start)
        residuals = Residuals(model, data, settings.statistics, settings.relative_error_floor)
        chi2_truth = float(np.sum(residuals(np.log([truth[k] for k in keys])) ** 2))
        for rec in est.table.to_dict(orient="records"):
            true, x = truth[rec["parameter"]], np.log(rec["estimate"])
            low, high = np.exp(x - z * rec["sd_ln_curvature"]), np.exp(x + z * rec["sd_ln_curvature"])
            rows.append(
                {
                    "seed": seed,
                    "parameter": rec["parameter"],
                    "true": true,
                    "estimate": rec["estimate"],
                    "ci_low": rec["ci_low"],
                    "ci_high": rec["ci_high"],
                    "inside_profile": bool(rec["ci_low"] <= true <= rec["ci_high"]),
                    "inside_curvature": bool(low <= true <= high),
                    "half_width_ln_profile": 0.5 * np.log(rec["ci_high"] / rec["ci_low"]),
                    "half_width_ln_curvature": z * rec["sd_ln_curvature"],
                    "chi2_estimate": est.info["chi2"],
                    "chi2_truth": chi2_truth,
                    "evaluations": est.info["evaluations"],
                }
            )
        print(
            f"seed {seed}: "
            + ", ".join(
                f"{r['parameter'].split('.')[-1]} {r['estimate']:.4g} [{r['ci_low']:.4g}, {r['ci_high']:.4g}]"
                f"{'' if r['inside_profile'] else ' (truth outside)'}"
                for r in rows[-len(keys) :]
            )
            + f"; chi2 truth - min {chi2_truth - est.info['chi2']:.2f}; {time.perf_counter() - began:.1f} s",
            flush=True,
        )
    return pd.DataFrame(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default=str(ROOT / "config/config.yaml"))
    parser.add_argument("--model", default=str(ROOT / "results/surrogate/model.skops"))
    parser.add_argument("--seeds", type=int, default=30)
    parser.add_argument("--out", default=str(ROOT / "results/bench_calibration.csv"))
    parser.add_argument("--quick", action="store_true", help="tiny config, quick surrogate, 2 seeds (smoke test)")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    with tempfile.TemporaryDirectory() as tmp:
        if args.quick:
            import quick

            args.config, args.seeds, args.out = str(quick.TEST_CONFIG), 2, str(Path(tmp) / "bench_calibration.csv")
            args.model = str(quick.timed_surrogate(tmp)[0])
        rows = coverage_rows(args.config, args.model, args.seeds)
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        rows.to_csv(args.out, index=False)
        summarise(rows, args)


def summarise(rows: pd.DataFrame, args) -> None:
    """Print the coverage per parameter over the seeds."""
    summary = rows.groupby("parameter").agg(
        seeds=("seed", "size"),
        coverage_profile=("inside_profile", "mean"),
        coverage_curvature=("inside_curvature", "mean"),
        sd_ln_of_estimates=("estimate", lambda e: float(np.std(np.log(e), ddof=1))),
        median_half_width_profile=("half_width_ln_profile", "median"),
        median_half_width_curvature=("half_width_ln_curvature", "median"),
        median_evaluations=("evaluations", "median"),
    )
    print(f"\nPBM-constant + noise, {args.seeds} noise seeds (target coverage 0.95; half-widths in ln):")
    print(summary.to_string(float_format=lambda v: f"{v:.4g}"))
    rise = rows.drop_duplicates("seed")
    print(
        f"sum of squares at the truth above the minimum: median {np.median(rise.chi2_truth - rise.chi2_estimate):.2f}"
    )
    print(f"rows: {args.out}")


if __name__ == "__main__":
    main()
