"""The check of the calibration on data of known parameters, PBM-DEM's output and PBM-constant's with
known noise (rule calibration_check; docs/calibration.md, "The check on known parameters").
"""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.config import Calibration, CoupledLoop
from pbmdem.config.design import pbm_value
from pbmdem.coupling.methods import calibrated_frequency
from pbmdem.tables import STATISTICS
from pbmdem.validation.results import load_run, run_folder

from .batches import Case, run_cases
from .calibration import Estimate, Model, calibrate

FREQUENCY_KEY = "pbm.aggregation.constant_frequency"


def measured_from_series(series: dict[float, list[pd.DataFrame]], times) -> pd.DataFrame:
    """A measured table from model output: per speed the summaries of its replicates (time, d10,
    d50, d90), read at `times`; the value is the replicates' mean and the sd its standard error
    (sd over replicates / sqrt(n)); one replicate: sd 0 (the caller adds its own error)."""
    rows = []
    for rpm, summaries in sorted(series.items()):
        at = np.stack([np.column_stack([np.interp(times, s.time, s[k]) for k in STATISTICS]) for s in summaries])
        mean = at.mean(axis=0)
        n = at.shape[0]
        se = at.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros_like(mean)
        for j, t in enumerate(times):
            row = {"rpm": float(rpm), "time": float(t)}
            row.update({k: float(mean[j, i]) for i, k in enumerate(STATISTICS)})
            row.update({f"{k}_sd": float(se[j, i]) for i, k in enumerate(STATISTICS)})
            rows.append(row)
    return pd.DataFrame(rows)


def with_noise(table: pd.DataFrame, relative_sd: float, seed: int) -> pd.DataFrame:
    """`table` with Gaussian noise of sd `relative_sd` x value added to d10/d50/d90 (seeded), the
    sd columns set to that sd, and each row's sizes sorted so that d10 <= d50 <= d90 still holds."""
    rng = np.random.default_rng(seed)
    out = table.copy()
    values = out[list(STATISTICS)].to_numpy(float)
    noisy = values * (1.0 + relative_sd * rng.standard_normal(values.shape))
    out[list(STATISTICS)] = np.sort(noisy, axis=1)
    for i, k in enumerate(STATISTICS):
        out[f"{k}_sd"] = relative_sd * values[:, i]
    return out


def proof_times(loop: CoupledLoop, step: float) -> np.ndarray:
    """Every `step` s from `step` to the end of the batch."""
    end = loop.batch.pbm.process.end
    return np.arange(step, end + 0.5 * step, step)[: int(end // step)]


def dem_measured(validation_dir, rpms, replicates: int, times) -> pd.DataFrame:
    """The measured table of PBM-DEM's replicates at `rpms` (wildcard text, e.g. "300")."""
    series = {}
    for rpm in rpms:
        runs = [load_run(run_folder(validation_dir, str(rpm), "pbm_dem", k), "PBM-DEM run") for k in range(replicates)]
        series[float(rpm)] = [run.summary for run in runs]
    return measured_from_series(series, times)


def constant_measured(loop: CoupledLoop, model_path, rpms, times, noise: float, seed: int):
    """(measured table with noise, PBM-constant's frequency per speed) at `rpms`."""
    fixed = {float(r): ((FREQUENCY_KEY, calibrated_frequency(loop, model_path, float(r))[0]),) for r in rpms}
    outcomes = run_cases(loop, model_path, [Case(r, fixed[r], kernel="constant") for r in fixed])
    series = {}
    for o in outcomes:
        if o.failed:
            raise RuntimeError(f"PBM-constant at {o.case.rpm:g} rpm failed: {o.failed}")
        series[o.case.rpm] = [pd.DataFrame(o.sizes, columns=list(STATISTICS)).assign(time=o.times)]
    return with_noise(measured_from_series(series, times), noise, seed), fixed


def recovery_rows(case: str, estimate: Estimate, truth: dict[str, float]) -> list[dict]:
    """One row per parameter: the truth against the estimate and its interval."""
    rows = []
    for rec in estimate.table.to_dict(orient="records"):
        true = truth[rec["parameter"]]
        rows.append(
            {
                "case": case,
                "parameter": rec["parameter"],
                "true": true,
                "estimate": rec["estimate"],
                "ci_low": rec["ci_low"],
                "ci_high": rec["ci_high"],
                "relative_error": rec["estimate"] / true - 1.0,
                "recovered": bool(rec["ci_low"] <= true <= rec["ci_high"]),
                "sd_ln_measurement": rec["sd_ln_measurement"],
                "sd_ln_surrogate": rec["sd_ln_surrogate"],
                "chi2_reduced": estimate.info["chi2_reduced"],
                "out_of_domain_intervals": estimate.info["out_of_domain_intervals"],
                "unidentifiable": "; ".join(f"{a} ~ {b} ({r:+.2f})" for a, b, r in estimate.unidentifiable),
            }
        )
    return rows


def calibration_check(
    loop: CoupledLoop,
    model_path: str | Path,
    validation_dir,
    rpms,
    replicates: int,
    settings: Calibration,
    n_jobs: int = 1,
) -> tuple[pd.DataFrame, dict[str, Estimate], dict[str, pd.DataFrame]]:
    """(recovery table, estimate per case, measured table per case) of both cases."""
    keys = settings.parameters
    truth = {k: pbm_value(loop.batch.pbm, k) for k in keys}
    start = {k: v * settings.proof.start_factor for k, v in truth.items()}
    times = proof_times(loop, settings.proof.time_step)
    data = {"pbm_dem": dem_measured(validation_dir, rpms, replicates, times)}
    data["pbm_constant_noise"], fixed = constant_measured(
        loop, model_path, rpms, times, settings.proof.noise, settings.proof.seed
    )
    # the two cases side by side, each evaluating its batches in order: a calibration's evaluation
    # is 3 short batches, too few to gain from a process pool of its own (run_cases). Their n_jobs
    # is for the profile-likelihood scan at the end, which takes PBM-ANN four times as long as
    # PBM-constant: its sides use the core the finished case has left (profile_widths)
    models = {
        "pbm_dem": Model(loop, model_path, keys, "ann", n_jobs=n_jobs),
        "pbm_constant_noise": Model(loop, model_path, keys, "constant", fixed=fixed, n_jobs=n_jobs),
    }
    estimates = dict(zip(models, _calibrate_all(models, data, settings, start, n_jobs), strict=True))
    rows = [row for case, est in estimates.items() for row in recovery_rows(case, est, truth)]
    return pd.DataFrame(rows), estimates, data


def _calibrate_all(models: dict, data: dict, settings: Calibration, start: dict, n_jobs: int) -> list[Estimate]:
    """`calibrate` of each case (in the order of `models`), on up to `n_jobs` forked processes; the
    estimates do not depend on `n_jobs`."""
    cases = list(models)
    if n_jobs <= 1 or len(cases) < 2:
        return [calibrate(models[c], data[c], settings, start) for c in cases]

    with ProcessPoolExecutor(
        max_workers=min(n_jobs, len(cases)), mp_context=multiprocessing.get_context("fork")
    ) as pool:
        futures = [pool.submit(calibrate, models[c], data[c], settings, start) for c in cases]
        return [f.result() for f in futures]
