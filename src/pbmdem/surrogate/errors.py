"""Errors of the surrogate's input tables and of a missing velocity model, the check of the
``groups`` of a fit, and the checks of its hot paths (fitted, the array's shape)."""

from __future__ import annotations

import numpy as np
from sklearn.exceptions import NotFittedError


class CollisionTableError(ValueError):
    """The collision table violates the contract of docs/architecture.md."""


class VelocityModelMissingError(RuntimeError):
    """The surrogate was trained without impact-velocity bins, so it cannot predict them."""


def require_fitted(estimator, attribute: str) -> None:
    """NotFittedError unless ``estimator`` has the fitted ``attribute``: scikit-learn's
    ``check_is_fitted`` for the PBM's per-interval calls, without its scan of every attribute
    (about 30 us a call, 22 calls per PBM-ANN batch)."""
    if attribute not in vars(estimator):
        raise NotFittedError(
            f"This {type(estimator).__name__} instance is not fitted yet. Call 'fit' with appropriate "
            "arguments before using this estimator."
        )


def checked_groups(groups, n_samples: int):
    """``groups`` (the DEM run of every row) as an array, None if None; ValueError unless it has
    one entry per sample."""
    if groups is None:
        return None
    groups = np.asarray(groups)
    if groups.shape != (n_samples,):
        raise ValueError(f"groups must be 1-d with one entry per sample ({n_samples}), got shape {groups.shape}")
    return groups


def array_input(estimator, X) -> np.ndarray:
    """``X`` as the float64 (n, ``n_features_in_``) array of a fitted model's ``predict_array``
    (fitted with ``estimators_``), or ValueError; nothing else of scikit-learn's validation."""
    require_fitted(estimator, "estimators_")
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != estimator.n_features_in_:
        raise ValueError(f"predict_array: X must be (n, {estimator.n_features_in_}), got shape {X.shape}")
    return X
