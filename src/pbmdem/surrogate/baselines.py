"""Baselines for the encounter surrogate, evaluated on the same grouped folds.

Both are scikit-learn regressors on the surrogate's feature matrix with ``y`` = log10 of the
encounter frequency per pair (:func:`pbmdem.surrogate.features.training_data`):
``fit(X, y, groups=None)``, ``predict(X)`` in the units of ``y``.

* :class:`HGBBaseline`: ``HistGradientBoostingRegressor`` on the features.
* :class:`PhysicalScaling`: a one-constant kinetic-theory scaling

  .. math:: c_{ij} = K' \\, (d_i + d_j)^2 \\, v_{tip},   K' = K / V_{bed},

  collision cross-section ~ (d_i + d_j)^2, relative velocity ~ impeller tip speed, and the
  probability that a given pair meets ~ 1 / bed volume. Every DEM bed of the grid has the same
  solid volume (``dem.bed_height``, ``dem.packing_fraction``: the counts are chosen for it, the
  default grid's beds agree within 1e-4 decades), so ``1 / V_bed`` is a constant absorbed in
  ``K'`` (it cannot come from the features: a row sees two of a run's classes, not all).
  ``log10 K'`` is fitted by least squares in log space (the mean residual). Its impact-speed law
  (``fit(..., velocity=...)``) is one log-normal for all pairs with the median proportional to
  the tip speed: ``log10(median / v_tip)`` and ``log10 sigma`` are the means over the rows.
"""

from __future__ import annotations

import numpy as np
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.ensemble import HistGradientBoostingRegressor
from sklearn.utils.validation import check_is_fitted, validate_data

from ._threads import single_threaded
from .features import FEATURE_NAMES
from .velocity import n_law_parameters, speed_fractions

#: Features the physical scaling is a law of.
LAW_FEATURES = ("d_small", "d_large", "tip_speed")


class HGBBaseline(RegressorMixin, BaseEstimator):
    """Gradient-boosted trees on the surrogate features (``y``: log10 encounter frequency per pair).

    ``min_samples_leaf`` is capped at half the training rows, so tiny tables still split.
    """

    def __init__(
        self, max_iter: int = 200, learning_rate: float = 0.1, min_samples_leaf: int = 5, random_state: int | None = 0
    ):
        self.max_iter = max_iter
        self.learning_rate = learning_rate
        self.min_samples_leaf = min_samples_leaf
        self.random_state = random_state

    def fit(self, X, y, groups=None):
        """Fit on the feature matrix; ``groups`` is accepted for a uniform interface and not used."""
        X, y = validate_data(self, X, y, y_numeric=True, dtype=np.float64)
        with single_threaded():
            self.model_ = HistGradientBoostingRegressor(
                max_iter=self.max_iter,
                learning_rate=self.learning_rate,
                min_samples_leaf=min(self.min_samples_leaf, max(1, len(y) // 2)),
                random_state=self.random_state,
            ).fit(X, y)
        self.n_iter_ = self.model_.n_iter_
        return self

    def predict(self, X):
        check_is_fitted(self)
        X = validate_data(self, X, reset=False, dtype=np.float64)
        with single_threaded():
            return self.model_.predict(X)


class PhysicalScaling(RegressorMixin, BaseEstimator):
    """log10 c_ij = log10 K' + log10((d_small + d_large)^2 tip_speed), one constant K' fitted in log space.

    ``X`` must carry the named features ``d_small``, ``d_large`` (m) and ``tip_speed`` (m/s): a
    feature frame with those columns, or an array whose columns are :data:`FEATURE_NAMES` in
    that order. ``speed_law``: the impact-speed law of :meth:`velocity_fractions`
    (:data:`pbmdem.surrogate.velocity.SPEED_LAWS`; that of the ``velocity`` targets of ``fit``).
    """

    def __init__(self, speed_law: str = "lognormal"):
        self.speed_law = speed_law

    def _columns(self) -> list[int]:
        names = getattr(self, "feature_names_in_", None)
        if names is not None:
            names = [str(n) for n in names]
            missing = [n for n in LAW_FEATURES if n not in names]
            if missing:
                raise ValueError(
                    f"PhysicalScaling needs the features {list(LAW_FEATURES)}; X lacks {missing} (columns {names})"
                )
            return [names.index(n) for n in LAW_FEATURES]
        if self.n_features_in_ != len(FEATURE_NAMES):
            raise ValueError(
                f"PhysicalScaling needs the features {list(LAW_FEATURES)}: pass a feature frame with "
                f"these columns or an array with the {len(FEATURE_NAMES)} columns {list(FEATURE_NAMES)}; "
                f"got an array with {self.n_features_in_} column(s) and no feature names"
            )
        return [list(FEATURE_NAMES).index(n) for n in LAW_FEATURES]

    def _law_inputs(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(d_small + d_large, tip_speed) of every row, both checked > 0."""
        i, j, k = self._columns()
        dsum, v_tip = X[:, i] + X[:, j], X[:, k]
        if not ((dsum > 0).all() and (v_tip > 0).all()):
            raise ValueError("PhysicalScaling: d_small + d_large and tip_speed must be > 0 in every row")
        return dsum, v_tip

    def _log10_shape(self, X: np.ndarray) -> np.ndarray:
        dsum, v_tip = self._law_inputs(X)
        return np.log10(dsum**2 * v_tip)

    def fit(self, X, y, groups=None, velocity=None):
        """Fit ``log10 K'`` to ``y`` (log10 frequency); with ``velocity`` ((n, 2): mu = log10
        median speed, sigma; NaN rows skipped) also the speed ratio and spread. ``groups`` is not used."""
        p = n_law_parameters(self.speed_law)
        X, y = validate_data(self, X, y, y_numeric=True, dtype=np.float64)
        self.log10_K_ = float(np.mean(y - self._log10_shape(X)))
        self.log10_speed_ratio_ = self.log10_sigma_ = self.shape_ = None
        if velocity is not None:
            V = np.asarray(velocity, dtype=float)
            if V.shape != (len(y), p):
                raise ValueError(f"velocity must have shape (n_samples, {p}) = ({len(y)}, {p}), got {V.shape}")
            vmask = np.isfinite(V).all(axis=1)
            if vmask.any():
                _, v_tip = self._law_inputs(X[vmask])
                self.log10_speed_ratio_ = float(np.mean(V[vmask, 0] - np.log10(v_tip)))
                self.log10_sigma_ = float(np.mean(np.log10(V[vmask, 1])))
                self.shape_ = float(np.mean(V[vmask, 2])) if p == 3 else None
        return self

    def predict(self, X):
        """log10 c_ij per row (the units of ``y``)."""
        check_is_fitted(self)
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self.log10_K_ + self._log10_shape(X)

    def predict_velocity(self, X):
        """``(mu, sigma)`` per row: log10 median = log10 v_tip + constant, sigma constant."""
        check_is_fitted(self)
        if self.log10_speed_ratio_ is None:
            raise ValueError("PhysicalScaling was fitted without impact-velocity targets (fit(..., velocity=...))")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        _, v_tip = self._law_inputs(X)
        mu = self.log10_speed_ratio_ + np.log10(v_tip)
        return mu, np.full(len(mu), 10.0**self.log10_sigma_)

    def velocity_fractions(self, X) -> np.ndarray:
        mu, sigma = self.predict_velocity(X)
        shape = None if self.shape_ is None else np.full(len(mu), self.shape_)
        return speed_fractions(mu, sigma, self.speed_law, shape)
