"""Calibrated uncertainty of the surrogate's predictions: the coverage of held-out runs by the
nominal predictive interval, the factor on the predicted standard deviation that makes it nominal
(per row, or per run for an error that every pair of a bed shares, as the members' band assumes)
and the cross-fitted check of that factor (docs/surrogate.md, "Calibrated uncertainty"); the
members of that calibrated distribution that PBM-ANN runs (:class:`CalibratedMember` at
:func:`member_quantiles`).
"""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd
from scipy.stats import norm

from .tail import member_tail

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


def member_quantiles(n: int) -> np.ndarray:
    """``n`` standard-normal quantiles at ``(k + 1/2) / n``: symmetric, mean 0 (0 for n = 1)."""
    return norm.ppf((np.arange(int(n)) + 0.5) / int(n))


class CalibratedMember:
    """One member of a fitted model's uncertainty: the quantile ``z`` of its predictive normal with
    the standard deviation widened or narrowed by a calibration factor.

    ``model.predict_array(X, return_std=True)`` gives the mean and the standard deviation of every
    output; the member predicts ``mean + z scale std`` and has no spread of its own.
    """

    def __init__(self, model, z: float, scale: float):
        self.model, self.z, self.scale = model, float(z), float(scale)
        self.n_members_ = 1

    def predict_array(self, X, return_std: bool = False):
        mean, std = self.model.predict_array(np.asarray(X, dtype=np.float64), return_std=True)
        out = mean + self.z * self.scale * std
        return (out, np.zeros_like(out)) if return_std else out

    def predict(self, X, return_std: bool = False):
        return self.predict_array(X, return_std=return_std)


def member_at(surrogate, z: float):
    """A copy of the fitted ``CollisionSurrogate`` that predicts at the standard-normal quantile ``z``
    alone (``CollisionSurrogate.member``): its frequency and speed-law models as
    :class:`CalibratedMember` at ``z`` (each with its own calibration factor), its wall models
    likewise, its pooled tail's a times exp(-z spread) (:func:`~.tail.member_tail`)."""
    out = copy.copy(surrogate)
    out.frequency_model_ = CalibratedMember(surrogate.frequency_model_, z, surrogate.uncertainty_scale)
    if surrogate.velocity_model_ is not None:
        out.velocity_model_ = CalibratedMember(surrogate.velocity_model_, z, surrogate.velocity_uncertainty_scale)
    walls = getattr(surrogate, "wall_models_", None) or {}
    out.wall_models_ = {wall: member_at(model, z) for wall, model in walls.items()}
    out.speed_tail_ = member_tail(surrogate.speed_tail_, z)
    return out
