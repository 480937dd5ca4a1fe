"""Baselines for the encounter surrogate, evaluated on the same grouped folds.

* :class:`HGBBaseline`: ``HistGradientBoostingRegressor`` on the surrogate's features and target
  (log10 frequency per pair).
* :class:`PhysicalScaling`: a one-constant kinetic-theory scaling

  .. math:: c_{ij} = K \\, (d_i + d_j)^2 \\, v_{tip} / V_{bed},

  collision cross-section ~ (d_i + d_j)^2, relative velocity ~ impeller tip speed, and the
  probability that a given pair meets ~ 1 / bed volume. The bed volume is taken as the run's
  solid volume ``sum_k n_k pi d_k^3 / 6`` (the packing fraction, a constant, is absorbed in K).
  K is fitted by least squares in log space: ``log10 K`` = mean residual. Its impact-speed law
  (when the table carries velocity bins) is one log-normal for all pairs with the median
  proportional to the tip speed: ``log10(median / v_tip)`` and ``sigma`` are the means of the
  per-pair log-normal fits.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.ensemble import HistGradientBoostingRegressor
from sklearn.metrics import r2_score
from sklearn.utils.validation import check_is_fitted

from ._threads import single_threaded
from .velocity import bin_counts, fit_lognormal, lognormal_fractions, velocity_rows
from .features import (
    DEFAULT_IMPELLER_RADIUS,
    TARGET_NAME,
    make_features,
    pair_table,
    prepare_training_table,
    run_descriptors,
    tip_speed,
)


class _LogTableRegressor(RegressorMixin, BaseEstimator):
    """Shared predict/score: models fit on a collision table and predict in physical units."""

    def predict(self, table):
        return 10.0 ** self.predict_log10(table)

    def score(self, X, y=None, sample_weight=None):
        data = prepare_training_table(X, self.zero_policy)
        return float(r2_score(data[TARGET_NAME], self.predict_log10(data), sample_weight=sample_weight))


class HGBBaseline(_LogTableRegressor):
    """Gradient-boosted trees on the surrogate features, fitted to log10(encounter_frequency_per_pair)."""

    def __init__(self, max_iter: int = 200, learning_rate: float = 0.1, min_samples_leaf: int = 5,
                 random_state: int = 0, impeller_radius: float = DEFAULT_IMPELLER_RADIUS,
                 zero_policy: str = "drop"):
        self.max_iter = max_iter
        self.learning_rate = learning_rate
        self.min_samples_leaf = min_samples_leaf
        self.random_state = random_state
        self.impeller_radius = impeller_radius
        self.zero_policy = zero_policy

    def fit(self, table: pd.DataFrame, y=None):
        data = prepare_training_table(table, self.zero_policy)
        X = make_features(data, self.impeller_radius).to_numpy(float)
        with single_threaded():
            self.model_ = self._fit_model(X, data[TARGET_NAME].to_numpy(float), len(data))
        return self

    def _fit_model(self, X, y, n_rows):
        return HistGradientBoostingRegressor(
            max_iter=self.max_iter, learning_rate=self.learning_rate,
            min_samples_leaf=min(self.min_samples_leaf, max(1, n_rows // 2)),
            random_state=self.random_state,
        ).fit(X, y)

    def predict_log10(self, table: pd.DataFrame) -> np.ndarray:
        check_is_fitted(self, "model_")
        X = make_features(table, self.impeller_radius).to_numpy(float)
        with single_threaded():
            return self.model_.predict(X)


class PhysicalScaling(_LogTableRegressor):
    """c_ij = K (d_i + d_j)^2 v_tip / V_bed with one constant K fitted in log space."""

    def __init__(self, impeller_radius: float = DEFAULT_IMPELLER_RADIUS, zero_policy: str = "drop"):
        self.impeller_radius = impeller_radius
        self.zero_policy = zero_policy

    def _log10_shape(self, table: pd.DataFrame) -> np.ndarray:
        """log10 of (d_i + d_j)^2 v_tip / V_bed for every row (V_bed = solid volume of the run)."""
        desc = run_descriptors(table)
        volume = desc["solid_volume"].reindex(table["point_id"]).to_numpy(float)
        dsum = table["d_i"].to_numpy(float) + table["d_j"].to_numpy(float)
        v_tip = tip_speed(table["rpm"].to_numpy(float), self.impeller_radius)
        return np.log10(dsum ** 2 * v_tip / volume)

    def fit(self, table: pd.DataFrame, y=None):
        data = prepare_training_table(table, self.zero_policy)
        self.log10_K_ = float(np.mean(data[TARGET_NAME].to_numpy(float) - self._log10_shape(data)))
        self.K_ = 10.0 ** self.log10_K_
        vmask = velocity_rows(data)
        if vmask.any():
            mu, sigma = fit_lognormal(bin_counts(data.loc[vmask]))
            v_tip = tip_speed(data.loc[vmask, "rpm"].to_numpy(float), self.impeller_radius)
            self.log10_speed_ratio_ = float(np.mean(mu - np.log10(v_tip)))
            self.log10_sigma_ = float(np.mean(np.log10(sigma)))
        else:
            self.log10_speed_ratio_ = self.log10_sigma_ = None
        return self

    def predict_velocity(self, table: pd.DataFrame):
        """``(mu, sigma)`` per row: log10 median = log10 v_tip + constant, sigma constant."""
        check_is_fitted(self, "log10_K_")
        if self.log10_speed_ratio_ is None:
            raise ValueError("PhysicalScaling was fitted without impact-velocity bins")
        v_tip = tip_speed(table["rpm"].to_numpy(float), self.impeller_radius)
        mu = self.log10_speed_ratio_ + np.log10(v_tip)
        return mu, np.full(len(mu), 10.0 ** self.log10_sigma_)

    def velocity_fractions(self, table: pd.DataFrame) -> np.ndarray:
        return lognormal_fractions(*self.predict_velocity(table))

    def predict_log10(self, table: pd.DataFrame) -> np.ndarray:
        check_is_fitted(self, "log10_K_")
        make_features(table, self.impeller_radius)  # validates the table
        return self.log10_K_ + self._log10_shape(table)

    def frequency_matrix(self, diameters, numbers, rpm: float) -> np.ndarray:
        """(K, K) symmetric per-pair frequencies (1/s), same interface as the surrogate."""
        frame, iu, ju = pair_table(diameters, numbers, rpm)
        k = len(np.atleast_1d(diameters))
        c = np.empty((k, k))
        values = 10.0 ** self.predict_log10(frame)
        c[iu, ju] = values
        c[ju, iu] = values
        return c
