"""Calibrated uncertainty of the surrogate's predictions: the coverage of held-out runs by the
nominal predictive interval, the factor on the predicted standard deviation that makes it nominal
(per row, or per run for an error that every pair of a bed shares, as the members' band assumes)
and the cross-fitted check of that factor (docs/surrogate.md, "Calibrated uncertainty").
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.stats import norm

#: The nominal level of the predictive intervals whose coverage is checked on held-out runs.
COVERAGE_LEVEL = 0.90


def interval_z(level: float = COVERAGE_LEVEL) -> float:
    """Half-width of the central ``level`` interval of a standard normal (1.645 for 90 %)."""
    return float(norm.ppf(0.5 + level / 2))


def _usable(y, mean, std):
    """The three as float arrays and the mask of rows with finite values and a positive std."""
    y, mean, std = (np.asarray(a, float) for a in (y, mean, std))
    return y, mean, std, np.isfinite(y) & np.isfinite(mean) & np.isfinite(std) & (std > 0)


def coverage(y, mean, std, scale: float | np.ndarray = 1.0, level: float = COVERAGE_LEVEL) -> float:
    """Share of rows with ``|y - mean| <= z scale std``: the observed coverage of the nominal
    ``level`` normal interval (rows with a non-finite or zero std are left out; NaN if none)."""
    y, mean, std, ok = _usable(y, mean, std)
    scale = np.broadcast_to(np.asarray(scale, float), y.shape)
    if not ok.any():
        return float("nan")
    return float(np.mean(np.abs(y[ok] - mean[ok]) <= interval_z(level) * scale[ok] * std[ok]))


def calibration_scale(y, mean, std, level: float = COVERAGE_LEVEL) -> float:
    """Factor on ``std`` that makes the nominal ``level`` interval cover that share of the rows:
    the ``level`` quantile of ``|y - mean| / std`` over ``z``. NaN without usable rows."""
    y, mean, std, ok = _usable(y, mean, std)
    if ok.sum() < 2:
        return float("nan")
    ratio = np.abs(y[ok] - mean[ok]) / std[ok]
    return float(np.quantile(ratio, level, method="higher") / interval_z(level))


def run_calibration_scale(runs, y, mean, std, level: float = COVERAGE_LEVEL) -> float:
    """:func:`calibration_scale` of the runs' means (one row per run of ``runs``: mean y, mean
    prediction, mean std): the factor for an error shared by every pair of a bed, as the members'."""
    frame = pd.DataFrame({"run": np.asarray(runs).astype(str), "y": y, "mean": mean, "std": np.asarray(std, float)})
    per_run = frame.groupby("run").mean()
    return calibration_scale(per_run["y"], per_run["mean"], per_run["std"], level)


def cross_fitted_coverage(y, mean, std, folds, level: float = COVERAGE_LEVEL) -> float:
    """Coverage of the calibrated interval without calibrating on the rows it is judged on:
    every fold's rows are judged with the scale calibrated on the other folds' held-out rows."""
    y, mean, std, folds = (np.asarray(a) for a in (y, mean, std, folds))
    scale = np.full(len(y), np.nan)
    for k in np.unique(folds):
        rows = folds == k
        scale[rows] = calibration_scale(y[~rows], mean[~rows], std[~rows], level)
    ok = np.isfinite(scale)
    if not ok.any():
        return float("nan")
    return coverage(y[ok], mean[ok], std[ok], scale[ok], level)
