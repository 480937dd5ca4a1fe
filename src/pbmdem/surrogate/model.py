"""The encounter surrogate used by the PBM: :class:`CollisionSurrogate`, a scikit-learn regressor on the
features of :mod:`pbmdem.surrogate.features` holding the frequency and impact-speed models, the physics
offsets, the pooled tail and the training domain; the PBM calls ``frequency_matrix``, ``encounters``, ``impacts``.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, RegressorMixin, clone
from sklearn.utils.validation import check_is_fitted, validate_data

from pbmdem.frequency import matrix_from_pairs, upper_pairs
from pbmdem.impact import EncounterRates, ImpactRates, WallRates

from ._terms import shared_terms
from .calibration import member_at, member_quantiles
from .domain import TrainingDomain
from .ensemble import EnsembleMLPRegressorCV
from .errors import VelocityModelMissingError, checked_groups, require_fitted
from .features import (
    FEATURE_NAMES,
    check_impeller_radius,
    duplicated_features,
    make_features,
    pair_features,
    pair_table,
)
from .tail import fit_speed_tail, law_fractions
from .velocity import check_speed_law, n_law_parameters
from .walls import diagonal_features, wall_laws

PHYSICS_OFFSETS = ("cross_section", "none")
FEATURE_TRANSFORMS = ("log", "none")

#: Features the physics offsets are computed from (``physics_offset="cross_section"``).
OFFSET_FEATURES = ("d_small", "d_large", "tip_speed")


class CollisionSurrogate(TrainingDomain, RegressorMixin, BaseEstimator):
    """Encounter frequency and impact-speed law per particle pair: the surrogate the PBM uses.

    Parameters
    ----------
    frequency_model : EnsembleMLPRegressorCV or None
        Unfitted estimator of the encounter frequency (cloned at fit); None: ``EnsembleMLPRegressorCV()``.
    velocity_model : EnsembleMLPRegressorCV or None
        Unfitted estimator of the impact-speed law (two outputs); None: a clone of ``frequency_model``.
        It is fitted only when ``fit`` gets ``velocity`` targets.
    impeller_radius : float
        Impeller radius (m), ``granulator.impeller.blade_length``: the tip-speed feature of
        :meth:`frequency_matrix`, :meth:`encounters` and of collision tables passed to
        :meth:`predict_log10`/:meth:`predict_velocity` is built with it. Required (``fit``
        raises without it); there is no default radius.
    physics_offset : {"none", "cross_section"}
        ``"cross_section"``: the frequency model learns the residual of log10 c_ij after the
        collision cross-section 2 log10(d_small + d_large) (d in mm), which is added back at
        prediction (why: docs/surrogate.md, "Physics offset"). The velocity model likewise
        learns log10(median impact speed / tip speed). Needs X with the named features
        ``d_small``, ``d_large``, ``tip_speed``. ``"none"``: plain targets, any numeric X.
    speed_law : {"lognormal", "weibull", "gengamma"}
        The impact-speed law whose (mu, sigma[, q]) the velocity model learns and whose bin fractions
        it predicts (:mod:`pbmdem.surrogate.velocity`); the ``velocity`` targets of ``fit`` must
        be fitted with the same law (:func:`~pbmdem.surrogate.features.training_data`).
    speed_tail_from : float or None
        m/s: above this bin edge fractions follow :func:`~pbmdem.surrogate.tail.fit_speed_tail`; None: the
        law's own tail.
    domain_margin : float
        Relative slack of the per-feature training ranges before :class:`OutOfDomainWarning`
        (fraction of each feature's training range).

    Attributes
    ----------
    frequency_model_ : EnsembleMLPRegressorCV
        The fitted frequency model (``best_params_``, ``cv_results_``, ``estimators_``, ...).
    velocity_model_ : EnsembleMLPRegressorCV or None
        The fitted impact-velocity model, None without velocity targets.
    speed_tail_ : (int, float, float, float) or None
        The pooled tail (bin, a, beta, spread) of :func:`~pbmdem.surrogate.tail.fit_speed_tail`, or None.
    feature_min_, feature_max_ : ndarray
        Training range of every feature.
    duplicated_features_ : list of (str, str, float)
        Feature pairs that are duplicates on the training data (|Pearson r| > 0.999).
    training_point_ids_ : list of str
        The distinct ``groups`` (DEM runs) of the training data.
    n_training_rows_, n_velocity_rows_ : int
        Rows fitted by the frequency and the velocity model.
    n_features_in_, feature_names_in_
        As in scikit-learn.
    """

    def __init__(
        self,
        frequency_model=None,
        velocity_model=None,
        impeller_radius=None,
        physics_offset="none",
        domain_margin=0.0,
        feature_transform="none",
        uncertainty_scale=1.0,
        velocity_uncertainty_scale=1.0,
        speed_law="lognormal",
        speed_tail_from=None,
    ):
        self.frequency_model = frequency_model
        self.velocity_model = velocity_model
        self.impeller_radius = impeller_radius
        self.physics_offset = physics_offset
        self.domain_margin = domain_margin
        self.feature_transform = feature_transform
        self.uncertainty_scale = uncertainty_scale
        self.velocity_uncertainty_scale = velocity_uncertainty_scale
        self.speed_law = speed_law
        self.speed_tail_from = speed_tail_from

    # ------------------------------------------------------------------ helpers
    def _inner(self, F: pd.DataFrame):
        """What the inner models see: the (log) features, as a frame when fitted with feature
        names, else as an array."""
        F = self._transform(F)
        return F if hasattr(self, "feature_names_in_") else F.to_numpy()

    def _transform(self, F):
        """The features as the inner models see them: ``log10`` of every feature with
        ``feature_transform="log"`` (all features are positive sizes, fractions, counts and
        speeds that enter power laws), else unchanged. Domain checks use the untransformed values."""
        return F if self.feature_transform == "none" else np.log10(F)

    def _column(self, F, name: str) -> np.ndarray:
        """Feature ``name`` of a feature frame, or of a feature array in :data:`FEATURE_NAMES` order."""
        return F[:, FEATURE_NAMES.index(name)] if isinstance(F, np.ndarray) else F[name].to_numpy(float)

    def _offset(self, F) -> np.ndarray:
        """log10 of the physical part of c_ij that the frequency model does not have to learn."""
        if self.physics_offset == "none":
            return np.zeros(len(F))
        return 2.0 * np.log10(1e3 * (self._column(F, "d_small") + self._column(F, "d_large")))

    def _velocity_offset(self, F) -> np.ndarray:
        """log10 of the speed scale the velocity model does not have to learn (the tip speed)."""
        return np.zeros(len(F)) if self.physics_offset == "none" else np.log10(self._column(F, "tip_speed"))

    def _features(self, X):
        """A collision table becomes its feature frame; a feature frame or an array is passed on."""
        if isinstance(X, pd.DataFrame):
            names = self._feature_names()
            if all(n in X.columns for n in names):
                return X.loc[:, names]
            return make_features(X, self.impeller_radius)
        return X

    # ------------------------------------------------------------------ fit
    def fit(self, X, y, groups=None, velocity=None, velocity_counts=None):
        """Fit on the features ``X`` (n, n_features), ``y`` = log10 encounter frequency per pair (n,),
        ``groups`` = DEM run of every row (for the grouped search), optionally ``velocity`` = (n, 2 or 3)
        impact-speed law per row (``speed_law``: log10 median speed in m/s, sigma in decades[, q]; NaN rows
        unused) and ``velocity_counts`` = (n, bins) impacts per bin (``speed_tail_from``). Returns ``self``."""
        check_impeller_radius(self.impeller_radius)
        check_speed_law(self.speed_law)
        if self.physics_offset not in PHYSICS_OFFSETS:
            raise ValueError(f"physics_offset = {self.physics_offset!r}; allowed: {PHYSICS_OFFSETS}")
        if self.feature_transform not in FEATURE_TRANSFORMS:
            raise ValueError(f"feature_transform = {self.feature_transform!r}; allowed: {FEATURE_TRANSFORMS}")
        for name in ("uncertainty_scale", "velocity_uncertainty_scale"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} = {value!r}; a finite number > 0 is required")
        X, y = validate_data(self, X, y, y_numeric=True, dtype=np.float64)
        if self.feature_transform == "log" and not (X > 0).all():
            raise ValueError("feature_transform = 'log' needs features > 0 in every row")
        F = self._frame(X)
        if self.physics_offset != "none":
            missing = [n for n in OFFSET_FEATURES if n not in F.columns]
            if missing:
                raise ValueError(
                    f"physics_offset = {self.physics_offset!r} needs X with the named features "
                    f"{list(OFFSET_FEATURES)} (a feature frame from make_features/training_data); "
                    f"missing {missing}"
                )
        groups = checked_groups(groups, len(y))
        if velocity is not None:
            V = np.asarray(velocity, dtype=float)
            p = n_law_parameters(self.speed_law)
            if V.shape != (len(y), p):
                raise ValueError(
                    f"velocity must have shape (n_samples, {p}) = ({len(y)}, {p}) (the {self.speed_law} law's "
                    f"mu, sigma{', q' if p == 3 else ''} per row), got {V.shape}"
                )
            vmask = np.isfinite(V).all(axis=1)
            if (V[vmask, 1] <= 0).any():
                raise ValueError("velocity: sigma (second column) must be > 0 where given")
        self.duplicated_features_ = duplicated_features(F)
        for a, b, r in self.duplicated_features_:
            warnings.warn(
                f"features {a} and {b} are duplicates on this training table (Pearson r = {r:.4f}): "
                f"predictions where they disagree are extrapolations",
                UserWarning,
                stacklevel=2,
            )
        template = EnsembleMLPRegressorCV() if self.frequency_model is None else self.frequency_model
        self.frequency_model_ = clone(template).fit(self._inner(F), y - self._offset(F), groups=groups)

        self.velocity_model_, self.n_velocity_rows_ = None, 0
        if velocity is not None and vmask.any():
            Fv = F.loc[vmask].reset_index(drop=True)
            Yv = np.column_stack([V[vmask, 0] - self._velocity_offset(Fv), np.log10(V[vmask, 1]), V[vmask, 2:]])
            vtemplate = template if self.velocity_model is None else self.velocity_model
            self.velocity_model_ = clone(vtemplate).fit(
                self._inner(Fv), Yv, groups=None if groups is None else groups[vmask]
            )
            self.n_velocity_rows_ = int(vmask.sum())
        self.speed_tail_ = None
        if self.velocity_model_ is not None and self.speed_tail_from is not None and velocity_counts is not None:
            tip = self._column(F, "tip_speed")[vmask]
            counts, runs = np.asarray(velocity_counts, float)[vmask], None if groups is None else groups[vmask]
            self.speed_tail_ = fit_speed_tail(counts, tip, self.speed_tail_from, runs)

        self.feature_min_ = X.min(axis=0)
        self.feature_max_ = X.max(axis=0)
        self.training_point_ids_ = [] if groups is None else sorted({str(g) for g in groups})
        self.n_training_rows_ = int(len(y))
        return self

    # ------------------------------------------------------------------ predict
    def predict(self, X, return_std: bool = False, check_domain: bool = True):
        """Ensemble mean of log10(encounter frequency per pair) on the feature matrix ``X`` (the
        units of ``y``); with ``return_std`` also the members' standard deviation (decades).
        Features outside the training range raise :class:`OutOfDomainWarning` unless
        ``check_domain`` is False."""
        check_is_fitted(self)
        F = self._validated_frame(X, check_domain)
        return self._log10(F, self.frequency_model_.predict(self._inner(F), return_std=return_std), return_std)

    def _log10(self, F, out, return_std: bool):
        """:meth:`predict` from the frequency model's prediction ``out`` (mean, or mean and std
        with ``return_std``) on the features ``F``: the offset added, the std calibrated."""
        mean, std = out if return_std else (out, None)
        mean = mean + self._offset(F)
        return (mean, self.uncertainty_scale * std) if return_std else mean

    def predict_log10(self, X, return_std: bool = False, check_domain: bool = True):
        """:meth:`predict` for a collision table (contract columns), a feature frame or an array."""
        return self.predict(self._features(X), return_std=return_std, check_domain=check_domain)

    def has_velocity_model(self) -> bool:
        """True if the surrogate was trained with impact-velocity targets."""
        require_fitted(self, "velocity_model_")
        return self.velocity_model_ is not None

    def _require_velocity_model(self) -> None:
        if not self.has_velocity_model():
            raise VelocityModelMissingError(
                "this surrogate was trained without impact-velocity bins (results/dem/impact_velocity.csv); "
                "retrain it with the impact-velocity table to predict impact speeds"
            )

    def predict_velocity(self, X, return_std: bool = False, check_domain: bool = True):
        """Impact-speed law (``speed_law``) per row: ``(mu, sigma)``.

        ``X``: a collision table, a feature frame or an array. ``mu`` is log10 of the median
        impact speed (m/s), ``sigma`` the standard deviation of log10 v (decades); both the
        ensemble mean (sigma through its log10). With ``return_std`` also the members' spread of
        ``mu`` and of ``log10 sigma`` (decades).
        """
        self._require_velocity_model()
        F = self._validated_frame(self._features(X), check_domain)
        mu, sigma, _, std = self._velocity_law(F)
        return (mu, sigma, std[:, 0], std[:, 1]) if return_std else (mu, sigma)

    def _velocity_law(self, F):
        """(mu, sigma, shape or None, (n, outputs) std) of the velocity model on the feature frame."""
        mean, std = self.velocity_model_.predict(self._inner(F), return_std=True)
        return self._law(F, mean, self.velocity_uncertainty_scale * std.reshape(len(F), -1))

    def _law(self, F, mean, std=None):
        """(mu, sigma, shape or None, std) from the velocity model's outputs ``mean`` on the features ``F``."""
        mean = mean.reshape(len(F), -1)
        shape = mean[:, 2] if mean.shape[1] > 2 else None
        return mean[:, 0] + self._velocity_offset(F), 10.0 ** mean[:, 1], shape, std

    def velocity_fractions(self, X, check_domain: bool = True) -> np.ndarray:
        """(n, N_VELOCITY_BINS) predicted fraction of each row's encounters per velocity bin (rows sum to 1)."""
        self._require_velocity_model()
        F = self._validated_frame(self._features(X), check_domain)
        mu, sigma, shape, _ = self._velocity_law(F)
        return law_fractions([(self.speed_law, self._column(F, "tip_speed"), mu, sigma, shape, self.speed_tail_)])[0]

    # ------------------------------------------------------------------ PBM kernel
    def _array_path(self) -> bool:
        """True if the PBM-facing calls can skip DataFrames: fitted on the feature frame
        (feature names :data:`FEATURE_NAMES`, in that order)."""
        names = getattr(self, "feature_names_in_", None)
        return names is not None and [str(n) for n in names] == list(FEATURE_NAMES)

    def _pairs(self, diameters, numbers, rpm: float, check_domain: bool):
        """Features of the K (K + 1) / 2 class pairs (:func:`pbmdem.frequency.upper_pairs`; an
        array with :meth:`_array_path`, else the feature frame) and K."""
        if self._array_path():
            # the values of make_features(pair_table(...)), without DataFrames (pair_features)
            X = pair_features(diameters, numbers, rpm, self.impeller_radius)[0]
            if check_domain:
                self._warn_domain(X, stacklevel=4)
            return X, len(np.atleast_1d(diameters))
        F = make_features(pair_table(diameters, numbers, rpm)[0], self.impeller_radius)
        if check_domain:
            self._warn_domain(validate_data(self, F, reset=False, dtype=np.float64), stacklevel=4)
        return F, len(np.atleast_1d(diameters))

    def _pair_log10(self, F, return_std: bool = False):
        """:meth:`predict` of the pairs' features from :meth:`_pairs` (unchecked domain)."""
        if not isinstance(F, np.ndarray):
            return self.predict(F, return_std=return_std, check_domain=False)
        return self._log10(
            F, self.frequency_model_.predict_array(self._transform(F), return_std=return_std), return_std
        )

    def _pair_law(self, F):
        """The speed law of the pairs' features from :meth:`_pairs` (unchecked domain) as an entry
        of :func:`~.tail.law_fractions`: (speed law, tip speeds, mu, sigma, shape, pooled tail)."""
        if not isinstance(F, np.ndarray):
            F = self._validated_frame(self._features(F), False)
            mu, sigma, shape = self._velocity_law(F)[:3]
        else:
            mu, sigma, shape = self._law(F, self.velocity_model_.predict_array(self._transform(F)))[:3]
        return self.speed_law, self._column(F, "tip_speed"), mu, sigma, shape, self.speed_tail_

    def frequency_matrix(self, diameters, numbers, rpm: float, return_std: bool = False, check_domain: bool = True):
        """(K,) diameters (m) and (K,) particle numbers -> (K, K) symmetric encounter frequency c_ij (1/s per pair).

        One vectorised predict over the K (K + 1) / 2 unordered class pairs. ``numbers`` are
        particle numbers on the DEM scale (the run's ``n_total`` is their sum). With
        ``return_std`` also the (K, K) calibrated predictive standard deviation in decades. A surrogate fitted on the
        feature frame predicts from a feature array (:func:`~.features.pair_features`,
        :meth:`EnsembleMLPRegressorCV.predict_array`): the same numbers as :meth:`predict_log10`
        on the pairs' collision table, without its DataFrames.
        """
        require_fitted(self, "frequency_model_")
        F, k = self._pairs(diameters, numbers, rpm, check_domain)
        out = self._pair_log10(F, return_std=return_std)
        mean, std = out if return_std else (out, None)
        c = matrix_from_pairs(10.0**mean, k)
        return (c, matrix_from_pairs(std, k)) if return_std else c

    def encounters(self, diameters, numbers, rpm: float, check_domain: bool = True) -> EncounterRates:
        """(K,) diameters (m), (K,) particle numbers, impeller speed (1/min) -> EncounterRates.

        One vectorised prediction over the K (K + 1) / 2 unordered class pairs gives the (K, K)
        symmetric encounter frequency per pair (1/s) and the (K, K, V) fractions of each pair's
        encounters per bin of :data:`pbmdem.impact.VELOCITY_EDGES` (summing to 1 over bins).
        """
        self._require_velocity_model()
        F, k = self._pairs(diameters, numbers, rpm, check_domain)
        frequency = matrix_from_pairs(10.0 ** self._pair_log10(F), k)
        fractions = law_fractions([self._pair_law(F)])[0]
        return EncounterRates(frequency=frequency, velocity_fractions=matrix_from_pairs(fractions, k))

    def impacts(self, diameters, numbers, rpm: float, check_domain: bool = True):
        """:class:`pbmdem.impact.ImpactRates`: :meth:`encounters` and the wall models' impacts per granule
        (:func:`~pbmdem.surrogate.walls.wall_laws`), the same numbers as those calls: the walls
        predict from the diagonal rows of the pairs' feature array, the pairs' and walls' speed laws
        become fractions in one :func:`~.tail.law_fractions`, and response surfaces share terms at equal
        features (:mod:`._terms`)."""
        self._require_velocity_model()
        with shared_terms():
            F, k = self._pairs(diameters, numbers, rpm, check_domain)
            frequency = matrix_from_pairs(10.0 ** self._pair_log10(F), k)
            if isinstance(F, np.ndarray):
                iu, ju = upper_pairs(k)
                diagonal = F[iu == ju]
            else:
                diagonal = diagonal_features(diameters, numbers, rpm, self.impeller_radius)
            walls, laws = wall_laws(self, diagonal, check_domain)
            fractions = law_fractions([self._pair_law(F), *laws])
            pairs = EncounterRates(frequency=frequency, velocity_fractions=matrix_from_pairs(fractions[0], k))
            return ImpactRates(pairs, WallRates(walls, np.stack(fractions[1:])))

    def __call__(self, diameters, numbers, rpm: float):
        """Collision-frequency source interface of ``pbmdem.pbm`` (docs/architecture.md)."""
        return self.frequency_matrix(diameters, numbers, rpm)

    @property
    def n_members(self) -> int:
        """Members of the frequency model's uncertainty (ensemble networks or predictive quantiles)."""
        require_fitted(self, "frequency_model_")
        return self.frequency_model_.n_members_

    def member(self, k: int) -> CollisionSurrogate:
        """A copy of the fitted surrogate that predicts with member ``k`` of its calibrated uncertainty
        alone: :class:`~pbmdem.surrogate.calibration.CalibratedMember` at the k-th of
        :func:`~pbmdem.surrogate.calibration.member_quantiles` ``z_k`` (``std``: the networks' spread or
        the predictive standard deviation, times ``uncertainty_scale`` or ``velocity_uncertainty_scale``),
        the pooled tail's a times exp(-z_k spread). Frequency, speed law, tail and wall models take the
        same ``z_k``: member 0 has the fewest and slowest impacts, the last the most and the fastest;
        with an odd ``n_members`` the middle member is the mean prediction itself."""
        n = self.n_members
        if not 0 <= int(k) < n:
            raise ValueError(f"surrogate member {k!r}: allowed 0 .. {n - 1}")
        return member_at(self, float(member_quantiles(n)[int(k)]))
