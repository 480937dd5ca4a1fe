"""The surrogate's training domain: the range of every feature it was fitted on, the
:class:`OutOfDomainWarning` of a prediction outside it, and :func:`out_of_domain_recorded`, which
collects those warnings for the PBM's reports."""

from __future__ import annotations

import contextlib
import logging
import warnings

import numpy as np
import pandas as pd
from sklearn.utils.validation import check_is_fitted, validate_data

log = logging.getLogger(__name__)


class OutOfDomainWarning(UserWarning):
    """A prediction was requested outside the training domain of the surrogate."""


@contextlib.contextmanager
def out_of_domain_recorded(where: str, log_each: bool = True):
    """Collect the surrogate's OutOfDomainWarning messages (its own mechanism for inputs outside
    the training range) into the yielded list and log each one; every other warning is passed on
    unchanged. Nothing is silenced: the caller counts and reports what was collected."""
    found: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", OutOfDomainWarning)
        yield found
    for w in caught:
        if issubclass(w.category, OutOfDomainWarning):
            found.append(str(w.message))
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    if log_each:
        for message in found:
            log.warning("%s: surrogate out of its training domain: %s", where, message)


class TrainingDomain:
    """The fitted features and their training domain, for :class:`~pbmdem.surrogate.model.CollisionSurrogate`
    (a scikit-learn estimator with ``feature_min_``, ``feature_max_``, ``domain_margin`` and
    ``_features``, which turns a collision table into its feature frame)."""

    def _feature_names(self) -> list[str]:
        names = getattr(self, "feature_names_in_", None)
        return [str(n) for n in names] if names is not None else [f"x{j}" for j in range(self.n_features_in_)]

    def _frame(self, X: np.ndarray) -> pd.DataFrame:
        return pd.DataFrame(X, columns=self._feature_names())

    def feature_ranges(self) -> dict[str, tuple[float, float]]:
        """Training range (min, max) of every feature."""
        check_is_fitted(self)
        return {
            n: (float(lo), float(hi)) for n, lo, hi in zip(self._feature_names(), self.feature_min_, self.feature_max_)
        }

    def _domain_mask(self, vals: np.ndarray) -> np.ndarray:
        span = self.feature_max_ - self.feature_min_
        slack = self.domain_margin * span + 1e-9 * np.maximum(np.abs(self.feature_max_), np.abs(self.feature_min_))
        return (vals < self.feature_min_ - slack) | (vals > self.feature_max_ + slack)

    def out_of_domain(self, X) -> pd.DataFrame:
        """Boolean frame: True where a feature lies outside its (slackened) training range.
        ``X``: a collision table, a feature frame or an array."""
        check_is_fitted(self)
        F = self._features(X)
        vals = validate_data(self, F, reset=False, dtype=np.float64)
        index = F.index if isinstance(F, pd.DataFrame) else None
        return pd.DataFrame(self._domain_mask(vals), columns=self._feature_names(), index=index)

    def _validated_frame(self, X, check_domain: bool):
        """The feature frame of the feature matrix ``X`` (validated against the fitted features),
        with an OutOfDomainWarning per feature outside the training range if ``check_domain``
        (pointing at the caller of the public method that called this)."""
        X = validate_data(self, X, reset=False, dtype=np.float64)
        if check_domain:
            self._warn_domain(X, stacklevel=4)
        return self._frame(X)

    def _warn_domain(self, vals: np.ndarray, stacklevel: int = 3) -> None:
        """One OutOfDomainWarning per feature with values outside the training range (``vals``:
        validated feature array)."""
        mask = self._domain_mask(vals)
        if not mask.any():
            return
        for j, name in enumerate(self._feature_names()):
            col = mask[:, j]
            if col.any():
                v = vals[col, j]
                worst = v[np.argmax(np.maximum(self.feature_min_[j] - v, v - self.feature_max_[j]))]
                warnings.warn(
                    f"{name} = {worst:.6g} outside the training range "
                    f"[{self.feature_min_[j]:.6g}, {self.feature_max_[j]:.6g}] "
                    f"({int(col.sum())} of {len(col)} prediction(s) out of domain for {name})",
                    OutOfDomainWarning,
                    stacklevel=stacklevel,
                )
