"""MLP encounter surrogate (scikit-learn estimator conventions).

:class:`CollisionSurrogate` is fitted on a collision table (with the impact-velocity bins attached,
:func:`pbmdem.surrogate.velocity.attach_velocity_bins`) and predicts, per particle pair, the
encounter frequency (1/s) and the distribution of impact speeds over
:data:`pbmdem.impact.VELOCITY_EDGES`. Internally it is an ensemble of
``Pipeline(StandardScaler, MLPRegressor)`` members fitted to ``log10(encounter_frequency_per_pair)``
and a second ensemble of two-output members fitted to the log-normal summary (log10 median,
log10 spread) of each pair's impact speeds; the members differ only in their random seed, their
spread is the uncertainty estimate.
Hyperparameters (``hidden_layer_sizes``, ``alpha``) are chosen by a grid search whose folds hold
out whole DEM runs (``point_id`` groups), so no run is on both sides of a split.
"""

from __future__ import annotations

import logging

import warnings
from collections.abc import Sequence

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, RegressorMixin, clone
from sklearn.exceptions import ConvergenceWarning
from sklearn.metrics import r2_score
from sklearn.model_selection import GridSearchCV, GroupKFold, LeaveOneGroupOut
from sklearn.neural_network import MLPRegressor
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils.validation import check_is_fitted

from pbmdem.impact import EncounterRates

from ._threads import single_threaded
from .features import (
    DEFAULT_IMPELLER_RADIUS,
    FEATURE_NAMES,
    TARGET_NAME,
    duplicated_features,
    make_features,
    pair_table,
    prepare_training_table,
)
from .velocity import bin_counts, fit_lognormal, lognormal_fractions, velocity_rows

CV_STRATEGIES = ("leave_one_group_out", "group_kfold")


PHYSICS_OFFSETS = ("cross_section", "none")


class OutOfDomainWarning(UserWarning):
    """A prediction was requested outside the training domain of the surrogate."""


def make_group_cv(strategy: str = "leave_one_group_out", n_splits: int = 5, n_groups: int | None = None):
    """Grouped cross-validation splitter: whole DEM runs (groups) are held out together."""
    if strategy == "leave_one_group_out":
        return LeaveOneGroupOut()
    if strategy == "group_kfold":
        k = int(n_splits) if n_groups is None else min(int(n_splits), int(n_groups))
        if k < 2:
            raise ValueError(f"group_kfold needs at least 2 groups, got {n_groups}")
        return GroupKFold(n_splits=k)
    raise ValueError(f"cv strategy must be one of {CV_STRATEGIES}, got {strategy!r}")


def grouped_splits(groups, strategy: str = "leave_one_group_out", n_splits: int = 5) -> list[tuple[np.ndarray, np.ndarray]]:
    """Explicit (train, test) index arrays of a grouped split; checked to be run-disjoint."""
    groups = np.asarray(groups)
    n_groups = len(np.unique(groups))
    if n_groups < 2:
        raise ValueError(f"grouped cross-validation needs at least 2 DEM runs, got {n_groups}")
    cv = make_group_cv(strategy, n_splits, n_groups)
    splits = []
    for train, test in cv.split(np.zeros((len(groups), 1)), groups=groups):
        leaked = set(groups[train]) & set(groups[test])
        if leaked:  # cannot happen with the splitters above; kept as a hard guarantee
            raise RuntimeError(f"run(s) {sorted(leaked)} in both train and test")
        splits.append((train, test))
    return splits


def _as_features(X, impeller_radius: float) -> pd.DataFrame:
    """Accept a collision table, a feature frame or an (n, len(FEATURE_NAMES)) array; return the feature frame."""
    if isinstance(X, pd.DataFrame):
        if all(c in X.columns for c in FEATURE_NAMES):
            return X.loc[:, list(FEATURE_NAMES)].astype(float)
        return make_features(X, impeller_radius)
    arr = np.asarray(X, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != len(FEATURE_NAMES):
        raise ValueError(f"expected a collision table, a feature frame or an array with "
                         f"{len(FEATURE_NAMES)} columns {FEATURE_NAMES}, got shape {arr.shape}")
    return pd.DataFrame(arr, columns=list(FEATURE_NAMES))


class VelocityModelMissingError(RuntimeError):
    """The surrogate was trained without impact-velocity bins, so it cannot predict them."""


class CollisionSurrogate(RegressorMixin, BaseEstimator):
    """Ensemble-MLP surrogate of DEM encounter frequencies and impact speeds per particle pair.

    Parameters
    ----------
    hidden_layer_sizes : sequence of tuples
        Candidate hidden-layer sizes for the grid search.
    alpha : sequence of float
        Candidate L2 penalties for the grid search.
    ensemble_size : int
        Number of MLPs (seeds) fitted with the selected hyperparameters.
    seeds : sequence of int or None
        Seeds of the ensemble members (length ``ensemble_size``); ``None`` uses
        ``random_state, random_state + 1, ...``. The grid search uses the first seed.
    random_state : int
        Base seed when ``seeds`` is None.
    max_iter : int
        Iteration limit of each MLP.
    activation, solver : str
        Passed to :class:`~sklearn.neural_network.MLPRegressor` (``lbfgs`` suits small data).
    cv : {"leave_one_group_out", "group_kfold"}
        Grouped splitter of the hyperparameter search; groups are DEM runs (``point_id``).
    n_splits : int
        Folds of ``group_kfold`` (capped at the number of runs).
    impeller_radius : float
        Impeller radius (m) for the tip-speed feature; default ``granulator.impeller.blade_length``.
    zero_policy : {"drop", "floor"}
        Handling of rows with zero collisions (see :func:`~pbmdem.surrogate.features.prepare_training_table`).
    domain_margin : float
        Relative slack of the per-feature training ranges before :class:`OutOfDomainWarning`
        (fraction of each feature's training range).
    n_jobs : int or None
        Parallel jobs of the grid search.
    physics_offset : {"cross_section", "none"}
        ``"cross_section"`` (default): the MLP learns the residual of log10 c_ij after the
        collision cross-section 2 log10(d_i + d_j) (d in mm), which is added back at prediction.
        Kinetic theory gives c_ij proportional to (d_i + d_j)^2 at a fixed bed volume, so the
        learned part varies less and predictions for granules larger than the training sizes
        follow the cross-section instead of a saturated tanh network. The velocity networks
        likewise learn log10(median impact speed / impeller tip speed), impacts being driven by
        the impeller. ``"none"``: plain log10 c and log10 median speed.
    """

    def __init__(
        self,
        hidden_layer_sizes: Sequence[tuple[int, ...]] = ((4,), (8,), (8, 8)),
        alpha: Sequence[float] = (1e-3, 1e-2, 1e-1, 1.0),
        ensemble_size: int = 5,
        seeds: Sequence[int] | None = None,
        random_state: int = 0,
        max_iter: int = 2000,
        activation: str = "tanh",
        solver: str = "lbfgs",
        cv: str = "leave_one_group_out",
        n_splits: int = 5,
        impeller_radius: float = DEFAULT_IMPELLER_RADIUS,
        zero_policy: str = "drop",
        domain_margin: float = 0.0,
        n_jobs: int | None = None,
        physics_offset: str = "cross_section",
    ):
        self.hidden_layer_sizes = hidden_layer_sizes
        self.alpha = alpha
        self.ensemble_size = ensemble_size
        self.seeds = seeds
        self.random_state = random_state
        self.max_iter = max_iter
        self.activation = activation
        self.solver = solver
        self.cv = cv
        self.n_splits = n_splits
        self.impeller_radius = impeller_radius
        self.zero_policy = zero_policy
        self.domain_margin = domain_margin
        self.n_jobs = n_jobs
        self.physics_offset = physics_offset

    # ------------------------------------------------------------------ helpers
    def _seed_list(self) -> list[int]:
        if self.ensemble_size < 1:
            raise ValueError(f"ensemble_size must be >= 1, got {self.ensemble_size}")
        if self.seeds is None:
            return [int(self.random_state) + k for k in range(int(self.ensemble_size))]
        seeds = [int(s) for s in self.seeds]
        if len(seeds) != self.ensemble_size:
            raise ValueError(f"seeds has {len(seeds)} entries but ensemble_size is {self.ensemble_size}")
        return seeds

    def _pipeline(self) -> Pipeline:
        return Pipeline([
            ("scale", StandardScaler()),
            ("mlp", MLPRegressor(activation=self.activation, solver=self.solver, max_iter=int(self.max_iter))),
        ])

    def _param_grid(self) -> dict:
        sizes = [tuple(int(u) for u in np.atleast_1d(h)) for h in self.hidden_layer_sizes]
        alphas = [float(a) for a in np.atleast_1d(self.alpha)]
        if not sizes or not alphas:
            raise ValueError("hidden_layer_sizes and alpha need at least one candidate each")
        return {"mlp__hidden_layer_sizes": sizes, "mlp__alpha": alphas}

    def _offset(self, features: pd.DataFrame) -> np.ndarray:
        """log10 of the physical part of c_ij that the MLP does not have to learn."""
        if self.physics_offset == "none":
            return np.zeros(len(features))
        if self.physics_offset == "cross_section":
            return 2.0 * np.log10(1e3 * (features["d_small"].to_numpy(float) + features["d_large"].to_numpy(float)))
        raise ValueError(f"physics_offset = {self.physics_offset!r}; allowed: {PHYSICS_OFFSETS}")

    def _velocity_offset(self, features: pd.DataFrame) -> np.ndarray:
        """log10 of the speed scale the velocity networks do not have to learn (the tip speed)."""
        if self.physics_offset == "none":
            return np.zeros(len(features))
        if self.physics_offset == "cross_section":
            return np.log10(features["tip_speed"].to_numpy(float))
        raise ValueError(f"physics_offset = {self.physics_offset!r}; allowed: {PHYSICS_OFFSETS}")

    def _search_and_ensemble(self, X, target, groups, seeds):
        """Grouped grid search (if possible) then one member per seed; returns a dict of results."""
        grid = self._param_grid()
        n_candidates = len(grid["mlp__hidden_layer_sizes"]) * len(grid["mlp__alpha"])
        n_runs = len(np.unique(groups))
        splits = grouped_splits(groups, self.cv, self.n_splits) if n_runs >= 2 else []
        n_conv = 0
        if n_candidates > 1 and splits:
            search = GridSearchCV(
                self._pipeline().set_params(mlp__random_state=seeds[0]), grid, cv=splits,
                scoring="neg_mean_squared_error", refit=False, n_jobs=self.n_jobs, error_score="raise",
            )
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", ConvergenceWarning)
                search.fit(X, target)
            n_conv += sum(issubclass(w.category, ConvergenceWarning) for w in caught)
            best = dict(search.best_params_)
            res = search.cv_results_
            results = pd.DataFrame({
                "hidden_layer_sizes": [str(tuple(p)) for p in res["param_mlp__hidden_layer_sizes"]],
                "alpha": np.asarray(res["param_mlp__alpha"], dtype=float),
                "rmse_log10": np.sqrt(-np.asarray(res["mean_test_score"], dtype=float)),
                "fold_mse_log10_std": np.asarray(res["std_test_score"], dtype=float),
                "rank": np.asarray(res["rank_test_score"], dtype=int),
            })
            best_score = float(np.sqrt(-search.best_score_))
            for row in results.itertuples():
                logging.getLogger(__name__).info(
                    "hyperparameter candidate hidden_layer_sizes=%s alpha=%g: RMSE %.4f (log10) over %d grouped "
                    "folds, rank %d", row.hidden_layer_sizes, row.alpha, row.rmse_log10, len(splits), row.rank)
        else:
            best = {k: v[0] for k, v in grid.items()}
            results = pd.DataFrame({
                "hidden_layer_sizes": [str(best["mlp__hidden_layer_sizes"])],
                "alpha": [best["mlp__alpha"]], "rmse_log10": [np.nan], "fold_mse_log10_std": [np.nan], "rank": [1],
            })
            best_score = float("nan")
        best_params = {"hidden_layer_sizes": tuple(best["mlp__hidden_layer_sizes"]), "alpha": float(best["mlp__alpha"])}
        members = []
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            for seed in seeds:
                est = clone(self._pipeline()).set_params(
                    mlp__hidden_layer_sizes=best_params["hidden_layer_sizes"],
                    mlp__alpha=best_params["alpha"], mlp__random_state=seed)
                members.append(est.fit(X, target))
        n_conv += sum(issubclass(w.category, ConvergenceWarning) for w in caught)
        return {"members": members, "best_params": best_params, "best_score": best_score,
                "search_results": results, "splits": splits, "n_conv": n_conv}

    # ------------------------------------------------------------------ fit
    def fit(self, table: pd.DataFrame, y=None):
        """Fit on a collision table (``y`` is ignored: the target is read from the table)."""
        with single_threaded():
            return self._fit(table)

    def _fit(self, table: pd.DataFrame):
        if self.cv not in CV_STRATEGIES:
            raise ValueError(f"cv must be one of {CV_STRATEGIES}, got {self.cv!r}")
        seeds = self._seed_list()
        data = prepare_training_table(table, self.zero_policy)
        features = make_features(data, self.impeller_radius)
        X = features.to_numpy(float)
        target = data[TARGET_NAME].to_numpy(float) - self._offset(features)
        groups = data["point_id"].astype(str).to_numpy()
        self.duplicated_features_ = duplicated_features(features)
        for a, b, r in self.duplicated_features_:
            warnings.warn(f"features {a} and {b} are duplicates on this training table (Pearson r = {r:.4f}): "
                          f"predictions where they disagree are extrapolations", UserWarning, stacklevel=3)
        grid = self._param_grid()
        n_candidates = len(grid["mlp__hidden_layer_sizes"]) * len(grid["mlp__alpha"])
        if n_candidates > 1 and len(np.unique(groups)) < 2:
            warnings.warn("only one DEM run: no grouped hyperparameter search possible, "
                          "using the first candidate of hidden_layer_sizes and alpha", UserWarning, stacklevel=3)
        freq = self._search_and_ensemble(X, target, groups, seeds)
        n_conv = freq["n_conv"]

        # impact-velocity distribution: log-normal (mu, log10 sigma) per pair, second ensemble
        vmask = velocity_rows(data)
        self.velocity_estimators_ = []
        self.velocity_best_params_ = None
        self.velocity_best_score_ = float("nan")
        self.velocity_search_results_ = None
        self.n_velocity_rows_ = int(vmask.sum())
        if vmask.any():
            mu, sigma = fit_lognormal(bin_counts(data.loc[vmask]))
            Fv = features.loc[vmask]
            Y = np.column_stack([mu - self._velocity_offset(Fv), np.log10(sigma)])
            vel = self._search_and_ensemble(Fv.to_numpy(float), Y, groups[vmask], seeds)
            n_conv += vel["n_conv"]
            self.velocity_estimators_ = vel["members"]
            self.velocity_best_params_ = vel["best_params"]
            self.velocity_best_score_ = vel["best_score"]
            self.velocity_search_results_ = vel["search_results"]
        elif len(data):
            warnings.warn("the collision table carries no impact-velocity bins (results/dem/impact_velocity.csv "
                          "not attached): the surrogate predicts encounter frequencies only", UserWarning,
                          stacklevel=3)
        if n_conv:
            warnings.warn(f"{n_conv} MLP fit(s) stopped at max_iter={self.max_iter} before converging",
                          ConvergenceWarning, stacklevel=2)

        self.estimators_ = freq["members"]
        self.search_results_ = freq["search_results"]
        self.best_score_ = freq["best_score"]
        self.best_params_ = freq["best_params"]
        self.seeds_ = seeds
        self.feature_names_ = tuple(FEATURE_NAMES)
        self.n_features_in_ = len(FEATURE_NAMES)
        self.feature_min_ = features.min().to_numpy(float)
        self.feature_max_ = features.max().to_numpy(float)
        self.training_point_ids_ = sorted(set(groups))
        self.cv_folds_ = [sorted(set(groups[test])) for _, test in freq["splits"]]
        self.n_training_rows_ = int(len(data))
        self.n_dropped_rows_ = int(len(table) - len(data))
        self.n_floored_rows_ = int(data["floored"].sum())
        return self

    # ------------------------------------------------------------------ domain
    def feature_ranges(self) -> dict[str, tuple[float, float]]:
        """Training range (min, max) of every feature."""
        check_is_fitted(self, "estimators_")
        return {n: (float(lo), float(hi)) for n, lo, hi in zip(self.feature_names_, self.feature_min_, self.feature_max_)}

    def out_of_domain(self, X) -> pd.DataFrame:
        """Boolean frame: True where a feature lies outside its (slackened) training range."""
        check_is_fitted(self, "estimators_")
        F = _as_features(X, self.impeller_radius)
        span = self.feature_max_ - self.feature_min_
        slack = self.domain_margin * span + 1e-9 * np.maximum(np.abs(self.feature_max_), np.abs(self.feature_min_))
        lo = self.feature_min_ - slack
        hi = self.feature_max_ + slack
        vals = F.to_numpy(float)
        return pd.DataFrame((vals < lo) | (vals > hi), columns=F.columns, index=F.index)

    def _warn_domain(self, F: pd.DataFrame, stacklevel: int = 3) -> None:
        mask = self.out_of_domain(F)
        for j, name in enumerate(self.feature_names_):
            col = mask.iloc[:, j].to_numpy()
            if col.any():
                vals = F.iloc[:, j].to_numpy(float)[col]
                worst = vals[np.argmax(np.maximum(self.feature_min_[j] - vals, vals - self.feature_max_[j]))]
                warnings.warn(
                    f"{name} = {worst:.6g} outside the training range "
                    f"[{self.feature_min_[j]:.6g}, {self.feature_max_[j]:.6g}] "
                    f"({int(col.sum())} of {len(col)} prediction(s) out of domain for {name})",
                    OutOfDomainWarning, stacklevel=stacklevel)

    # ------------------------------------------------------------------ predict
    def predict_log10(self, X, return_std: bool = False, check_domain: bool = True):
        """Ensemble mean of log10(encounter frequency per pair); with ``return_std`` also the members' std."""
        check_is_fitted(self, "estimators_")
        F = _as_features(X, self.impeller_radius)
        if check_domain:
            self._warn_domain(F, stacklevel=3)
        arr = F.to_numpy(float)
        with single_threaded():
            preds = np.stack([m.predict(arr) for m in self.estimators_])
        mean = preds.mean(axis=0) + self._offset(F)
        if return_std:
            std = preds.std(axis=0, ddof=1) if len(self.estimators_) > 1 else np.zeros_like(mean)
            return mean, std
        return mean

    def predict(self, X, return_std: bool = False, check_domain: bool = True):
        """Encounter frequency per particle pair (1/s): 10 ** ensemble-mean log10 (geometric mean).

        ``X`` is a collision table (contract columns), a feature frame or an (n, len(FEATURE_NAMES)) array. With
        ``return_std`` the spread (std of the members' log10 predictions, in decades) is returned too.
        """
        mean, std = self.predict_log10(X, return_std=True, check_domain=check_domain)
        return (10.0 ** mean, std) if return_std else 10.0 ** mean

    def has_velocity_model(self) -> bool:
        """True if the surrogate was trained with impact-velocity bins."""
        check_is_fitted(self, "estimators_")
        return bool(getattr(self, "velocity_estimators_", None))

    def predict_velocity(self, X, return_std: bool = False, check_domain: bool = True):
        """Log-normal impact-speed law per row: ``(mu, sigma)``.

        ``mu`` is log10 of the median impact speed (m/s), ``sigma`` the standard deviation of
        log10 v (decades); both the ensemble mean (sigma through its log10). With ``return_std``
        also the members' spread of ``mu`` and of ``log10 sigma`` (decades).
        """
        check_is_fitted(self, "estimators_")
        if not self.has_velocity_model():
            raise VelocityModelMissingError(
                "this surrogate was trained without impact-velocity bins (results/dem/impact_velocity.csv); "
                "retrain it with the impact-velocity table to predict impact speeds")
        F = _as_features(X, self.impeller_radius)
        if check_domain:
            self._warn_domain(F, stacklevel=3)
        arr = F.to_numpy(float)
        with single_threaded():
            preds = np.stack([m.predict(arr).reshape(len(arr), 2) for m in self.velocity_estimators_])
        mean = preds.mean(axis=0)
        mu = mean[:, 0] + self._velocity_offset(F)
        sigma = 10.0 ** mean[:, 1]
        if return_std:
            std = preds.std(axis=0, ddof=1) if len(preds) > 1 else np.zeros_like(mean)
            return mu, sigma, std[:, 0], std[:, 1]
        return mu, sigma

    def velocity_fractions(self, X, check_domain: bool = True) -> np.ndarray:
        """(n, N_VELOCITY_BINS) predicted fraction of each row's encounters per velocity bin (rows sum to 1)."""
        mu, sigma = self.predict_velocity(X, check_domain=check_domain)
        return lognormal_fractions(mu, sigma)

    def score(self, X, y=None, sample_weight=None):
        """R2 of log10(encounter_frequency_per_pair) on a collision table (``y`` is ignored)."""
        data = prepare_training_table(X, self.zero_policy)
        return float(r2_score(data[TARGET_NAME].to_numpy(float), self.predict_log10(data),
                              sample_weight=sample_weight))

    # ------------------------------------------------------------------ PBM kernel
    def frequency_matrix(self, diameters, numbers, rpm: float, return_std: bool = False,
                         check_domain: bool = True):
        """(K,) diameters (m) and (K,) particle numbers -> (K, K) symmetric encounter frequency c_ij (1/s per pair).

        One vectorised predict over the K (K + 1) / 2 unordered class pairs. ``numbers`` are
        particle numbers on the DEM scale (the run's ``n_total`` is their sum). With
        ``return_std`` also the (K, K) ensemble spread in decades.
        """
        check_is_fitted(self, "estimators_")
        frame, iu, ju = pair_table(diameters, numbers, rpm)
        F = make_features(frame, self.impeller_radius)
        if check_domain:
            self._warn_domain(F, stacklevel=3)
        mean, std = self.predict_log10(F, return_std=True, check_domain=False)
        k = len(np.atleast_1d(diameters))
        c = np.empty((k, k))
        c[iu, ju] = 10.0 ** mean
        c[ju, iu] = 10.0 ** mean
        if not return_std:
            return c
        s = np.empty((k, k))
        s[iu, ju] = std
        s[ju, iu] = std
        return c, s

    def encounters(self, diameters, numbers, rpm: float, check_domain: bool = True) -> EncounterRates:
        """(K,) diameters (m), (K,) particle numbers, impeller speed (1/min) -> EncounterRates.

        One vectorised prediction over the K (K + 1) / 2 unordered class pairs gives the (K, K)
        symmetric encounter frequency per pair (1/s) and the (K, K, V) fractions of each pair's
        encounters per bin of :data:`pbmdem.impact.VELOCITY_EDGES` (summing to 1 over bins).
        """
        check_is_fitted(self, "estimators_")
        if not self.has_velocity_model():
            self.predict_velocity(np.zeros((0, len(FEATURE_NAMES))))  # raises VelocityModelMissingError
        frame, iu, ju = pair_table(diameters, numbers, rpm)
        F = make_features(frame, self.impeller_radius)
        if check_domain:
            self._warn_domain(F, stacklevel=3)
        log_c = self.predict_log10(F, check_domain=False)
        fractions = self.velocity_fractions(F, check_domain=False)
        k = len(np.atleast_1d(diameters))
        c = np.empty((k, k))
        c[iu, ju] = 10.0 ** log_c
        c[ju, iu] = 10.0 ** log_c
        v = np.empty((k, k, fractions.shape[1]))
        v[iu, ju] = fractions
        v[ju, iu] = fractions
        return EncounterRates(frequency=c, velocity_fractions=v)

    def __call__(self, diameters, numbers, rpm: float):
        """Collision-frequency source interface of ``pbmdem.pbm`` (docs/architecture.md)."""
        return self.frequency_matrix(diameters, numbers, rpm)
