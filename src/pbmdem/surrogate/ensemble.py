"""Self-tuning MLP ensemble regressor with grouped hyperparameter search (a scikit-learn estimator).

:class:`EnsembleMLPRegressorCV` knows nothing about collisions: it regresses any numeric ``y``
(1-D or 2-D) on any numeric ``X``. When ``groups`` are given, the hyperparameters are chosen by a
grid search whose folds hold out whole groups (for the surrogate: whole DEM runs, ``point_id``),
then one ``Pipeline(StandardScaler, MLPRegressor)`` is fitted per seed with the chosen values;
the members' mean is the prediction, their spread the uncertainty estimate.
"""

from __future__ import annotations

import logging
import numbers
import re
import warnings
import weakref

import numpy as np
from scipy.special import expit
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.exceptions import ConvergenceWarning
from sklearn.model_selection import GridSearchCV, GroupKFold, LeaveOneGroupOut
from sklearn.neural_network import MLPRegressor
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils.validation import check_is_fitted, validate_data

from ._threads import single_threaded
from .errors import array_input, checked_groups

log = logging.getLogger(__name__)

CV_STRATEGIES = ("leave_one_group_out", "group_kfold")


def grouped_splits(
    groups, strategy: str = "leave_one_group_out", n_splits: int = 5
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(train, test) index arrays of a grouped split: whole groups (DEM runs) are held out together."""
    groups = np.asarray(groups)
    n_groups = len(np.unique(groups))
    if n_groups < 2:
        raise ValueError(f"grouped cross-validation needs at least 2 DEM runs, got {n_groups}")
    if strategy == "leave_one_group_out":
        cv = LeaveOneGroupOut()
    elif strategy == "group_kfold":
        cv = GroupKFold(n_splits=min(int(n_splits), n_groups))
    else:
        raise ValueError(f"cv strategy must be one of {CV_STRATEGIES}, got {strategy!r}")
    return list(cv.split(np.zeros((len(groups), 1)), groups=groups))


def n_weights(hidden_layer_sizes, n_features: int, n_outputs: int = 1) -> int:
    """Weights and biases of an MLP with these hidden layers."""
    widths = [int(n_features), *map(int, hidden_layer_sizes), int(n_outputs)]
    return sum((a + 1) * b for a, b in zip(widths[:-1], widths[1:]))


class OneStandardErrorRule:
    """``GridSearchCV(refit=...)`` callable: the index of the candidate chosen by the
    one-standard-error rule (Breiman et al. 1984).

    Among the candidates whose mean grouped-CV score lies within one standard error (fold spread
    / sqrt(folds)) of the best, the simplest: fewest weights, then the largest L2 penalty, then the
    first. With a few DEM runs the candidates' scores often differ by less than their fold-to-fold
    noise; taking the top score then lets a rounding difference (another BLAS kernel, a 1e-9 change
    of the targets) flip the choice and with it the whole model. ``cv_results`` is a
    ``GridSearchCV.cv_results_`` of a ``Pipeline(..., ("mlp", MLPRegressor))``.
    """

    def __init__(self, n_features: int):
        self.n_features = int(n_features)

    def __call__(self, cv_results: dict) -> int:
        mean = np.asarray(cv_results["mean_test_score"], float)
        std = np.asarray(cv_results["std_test_score"], float)
        n_splits = sum(1 for key in cv_results if re.fullmatch(r"split\d+_test_score", key))
        best = int(np.argmax(mean))
        se = std[best] / np.sqrt(max(1, n_splits)) if np.isfinite(std[best]) else 0.0
        near = [k for k in range(len(mean)) if mean[k] >= mean[best] - se]
        params = cv_results["params"]
        return min(
            near,
            key=lambda k: (
                n_weights(params[k]["mlp__hidden_layer_sizes"], self.n_features),
                -params[k]["mlp__alpha"],
                k,
            ),
        )


def _object_array(values) -> np.ndarray:
    """1-d object array of the given values (tuples stay tuples, not a 2-d array)."""
    out = np.empty(len(values), dtype=object)
    for k, v in enumerate(values):
        out[k] = v
    return out


class EnsembleMLPRegressorCV(RegressorMixin, BaseEstimator):
    """Ensemble of ``Pipeline(StandardScaler, MLPRegressor)`` with a grouped grid search.

    ``hidden_layer_sizes`` and ``alpha`` are the search's candidates (an int ``h`` stands for
    ``(h,)``); one member per seed in ``seeds`` (the search fits with the first); ``max_iter``,
    ``activation`` and ``solver`` go to every ``MLPRegressor``; ``cv`` and ``n_splits`` choose the
    grouped splitter (:func:`grouped_splits`), ``n_jobs`` the search's parallel jobs. The defaults
    are scikit-learn's with one member; the workflow passes every value from the config
    (:func:`pbmdem.surrogate.settings.build_surrogate`). The fitted attributes (``estimators_``,
    ``best_params_``, ``best_score_``, ``cv_results_``, ``cv_folds_``, ``n_iter_``, ``n_outputs_``)
    are described in docs/surrogate.md.
    """

    def __init__(
        self,
        hidden_layer_sizes=((100,),),
        alpha=(1e-4,),
        seeds=(0,),
        max_iter=200,
        activation="relu",
        solver="adam",
        cv="leave_one_group_out",
        n_splits=5,
        n_jobs=None,
    ):
        self.hidden_layer_sizes = hidden_layer_sizes
        self.alpha = alpha
        self.seeds = seeds
        self.max_iter = max_iter
        self.activation = activation
        self.solver = solver
        self.cv = cv
        self.n_splits = n_splits
        self.n_jobs = n_jobs

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.target_tags.multi_output = True
        return tags

    # ------------------------------------------------------------------ parameters
    def _candidates(self) -> tuple[list[tuple[int, ...]], list[float]]:
        sizes = self.hidden_layer_sizes
        if isinstance(sizes, numbers.Integral):
            sizes = [sizes]
        sizes = [tuple(int(u) for u in np.atleast_1d(h)) for h in sizes]
        alphas = [float(a) for a in np.atleast_1d(self.alpha)]
        if not sizes or not alphas:
            raise ValueError(
                "hidden_layer_sizes and alpha need at least one candidate each, "
                f"got hidden_layer_sizes={self.hidden_layer_sizes!r}, alpha={self.alpha!r}"
            )
        if any(not h or min(h) < 1 for h in sizes):
            raise ValueError(f"hidden_layer_sizes: every layer needs >= 1 unit, got {self.hidden_layer_sizes!r}")
        if any(not (np.isfinite(a) and a >= 0) for a in alphas):
            raise ValueError(f"alpha: every candidate must be finite and >= 0, got {self.alpha!r}")
        return sizes, alphas

    def _seed_list(self) -> list[int]:
        seeds = [int(s) for s in np.atleast_1d(self.seeds)]
        if not seeds:
            raise ValueError(f"seeds needs at least one seed (one ensemble member each), got {self.seeds!r}")
        return seeds

    def _pipeline(self) -> Pipeline:
        return Pipeline(
            [
                ("scale", StandardScaler()),
                ("mlp", MLPRegressor(activation=self.activation, solver=self.solver, max_iter=int(self.max_iter))),
            ]
        )

    # ------------------------------------------------------------------ fit
    def fit(self, X, y, groups=None):
        """Grouped grid search (with ``groups`` of >= 2 distinct values and more than one
        candidate; otherwise the first candidate), then one member per seed. Returns ``self``."""
        if self.cv not in CV_STRATEGIES:
            raise ValueError(f"cv must be one of {CV_STRATEGIES}, got {self.cv!r}")
        sizes, alphas = self._candidates()
        seeds = self._seed_list()
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=[np.float64, np.float32])
        groups = checked_groups(groups, X.shape[0])
        search = len(sizes) * len(alphas) > 1
        n_groups = 0 if groups is None else len(np.unique(groups))
        if search and n_groups < 2:
            why = "no groups given" if groups is None else "only one group (DEM run)"
            warnings.warn(
                f"{why}: no grouped hyperparameter search possible, using the first candidate of "
                f"hidden_layer_sizes and alpha",
                UserWarning,
                stacklevel=2,
            )
        with single_threaded(), warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            self._fit(X, y, groups if search and n_groups >= 2 else None, sizes, alphas, seeds)
        n_conv = sum(issubclass(w.category, ConvergenceWarning) for w in caught)
        if n_conv:
            warnings.warn(
                f"{n_conv} MLP fit(s) stopped at max_iter={self.max_iter} before converging",
                ConvergenceWarning,
                stacklevel=2,
            )
        return self

    def _fit(self, X, y, groups, sizes, alphas, seeds) -> None:
        """The search (when ``groups`` is given) and the members, without warnings handling."""
        self.cv_results_ = None
        self.cv_folds_ = []
        self.best_score_ = float("nan")
        best = {"mlp__hidden_layer_sizes": sizes[0], "mlp__alpha": alphas[0]}
        members = []
        if groups is not None:
            splits = grouped_splits(groups, self.cv, self.n_splits)
            # the refit is the first member: the chosen candidate fitted on all rows with seeds[0]
            search = GridSearchCV(
                self._pipeline().set_params(mlp__random_state=seeds[0]),
                {"mlp__hidden_layer_sizes": sizes, "mlp__alpha": alphas},
                cv=splits,
                scoring="neg_mean_squared_error",
                refit=OneStandardErrorRule(X.shape[1]),
                n_jobs=self.n_jobs,
                error_score="raise",
            ).fit(X, y)
            self.cv_results_ = self._results(search.cv_results_, len(splits))
            best = search.best_params_
            members.append(search.best_estimator_)
            self.best_score_ = float(self.cv_results_["mean_test_score"][search.best_index_])
            self.cv_folds_ = [sorted({str(g) for g in groups[test]}) for _, test in splits]
            rmse = np.sqrt(-self.cv_results_["mean_test_score"])
            for k, params in enumerate(self.cv_results_["params"]):
                log.info(
                    "hyperparameter candidate hidden_layer_sizes=%s alpha=%g: RMSE %.4f (log10) over %d grouped "
                    "folds, rank %d",
                    str(params["hidden_layer_sizes"]),
                    params["alpha"],
                    rmse[k],
                    len(splits),
                    self.cv_results_["rank_test_score"][k],
                )
        self.best_params_ = {
            "hidden_layer_sizes": tuple(best["mlp__hidden_layer_sizes"]),
            "alpha": float(best["mlp__alpha"]),
        }
        for seed in seeds[len(members) :]:
            members.append(
                self._pipeline()
                .set_params(
                    mlp__hidden_layer_sizes=self.best_params_["hidden_layer_sizes"],
                    mlp__alpha=self.best_params_["alpha"],
                    mlp__random_state=seed,
                )
                .fit(X, y)
            )
        self.estimators_ = members
        self.n_outputs_ = 1 if y.ndim == 1 else int(y.shape[1])
        self.n_iter_ = np.array([m[-1].n_iter_ for m in members], dtype=int)

    @staticmethod
    def _results(res: dict, n_splits: int) -> dict:
        """GridSearchCV results with the pipeline prefix dropped from the parameter names."""
        params = [
            {"hidden_layer_sizes": tuple(p["mlp__hidden_layer_sizes"]), "alpha": float(p["mlp__alpha"])}
            for p in res["params"]
        ]
        return {
            "params": params,
            "param_hidden_layer_sizes": _object_array([p["hidden_layer_sizes"] for p in params]),
            "param_alpha": np.array([p["alpha"] for p in params], dtype=float),
            "mean_test_score": np.asarray(res["mean_test_score"], dtype=float),
            "std_test_score": np.asarray(res["std_test_score"], dtype=float),
            "rank_test_score": np.asarray(res["rank_test_score"], dtype=int),
            **{f"split{k}_test_score": np.asarray(res[f"split{k}_test_score"], dtype=float) for k in range(n_splits)},
        }

    # ------------------------------------------------------------------ predict
    def predict_array(self, X: np.ndarray, return_std: bool = False):
        """:meth:`predict` on a float64 array with the training features in their order, without
        scikit-learn's per-call validation (the caller's array is trusted: finite, 2-d, the
        fitted number of features): the same members' predictions, mean and spread, for the
        PBM's frequent calls with a few rows (``CollisionSurrogate.frequency_matrix``)."""
        X = array_input(self, X)
        return _mean_std(_members_forward(self, X), return_std)

    def predict(self, X, return_std: bool = False):
        """Members' mean prediction (units of ``y``); with ``return_std`` also their standard
        deviation (ddof 1; zeros for a single member)."""
        check_is_fitted(self)
        X = validate_data(self, X, reset=False, dtype=[np.float64, np.float32])
        with single_threaded():
            return _mean_std(np.stack([m.predict(X) for m in self.estimators_]), return_std)

    @property
    def n_members_(self) -> int:
        return len(self.estimators_)

    def fitted_state(self) -> dict:
        """JSON-able description of the fit (for the model's sidecar): the search and its choice,
        one row per candidate (rmse_log10: RMSE of the grouped search in the units of y,
        fold_mse_log10_std: std of the fold MSEs; without a search the candidate used, NaN scores)."""
        check_is_fitted(self)
        res = self.cv_results_
        if res is None:
            res = {"params": [self.best_params_], "mean_test_score": [np.nan], "std_test_score": [np.nan],
                   "rank_test_score": [1]}  # fmt: skip
        columns = ("hidden_layer_sizes", "alpha", "rmse_log10", "fold_mse_log10_std", "rank")
        rows = [
            dict(
                zip(columns, (tuple(p["hidden_layer_sizes"]), float(p["alpha"]), float(np.sqrt(-m)), float(sd), int(r)))
            )
            for p, m, sd, r in zip(res["params"], res["mean_test_score"], res["std_test_score"], res["rank_test_score"])
        ]
        rmse = None if not np.isfinite(self.best_score_) else float(np.sqrt(-self.best_score_))
        return {
            "n_outputs": self.n_outputs_,
            "best_params": self.best_params_,
            "search": {"best_rmse_log10": rmse, "results": rows},
            "search_cv_folds": self.cv_folds_,
        }


def _mean_std(preds: np.ndarray, return_std: bool):
    """The members' mean over axis 0 and, with ``return_std``, their std (ddof 1; zeros for one member)."""
    mean = preds.mean(axis=0)
    if not return_std:
        return mean
    return mean, (preds.std(axis=0, ddof=1) if len(preds) > 1 else np.zeros_like(mean))


#: the members' weights stacked (:func:`_stack`) per fitted ensemble, with the list they belong to
_STACKS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _members_forward(ensemble, X: np.ndarray) -> np.ndarray:
    """(n_members, n[, outputs]): ``np.stack([m.predict(X) for m in ensemble.estimators_])`` in one
    pass over the members' stacked weights, by the operations of scikit-learn's
    ``StandardScaler.transform`` and ``MLPRegressor._forward_pass_fast`` without their per-call
    input validation (about 0.7 ms per member and call, against 20 us for the arithmetic).
    ``np.matmul`` of the stack multiplies each member's slice as ``a @ W`` does, so the numbers are
    the members' own to the bit (tests/test_surrogate_array_path.py)."""
    members = ensemble.estimators_
    entry = _STACKS.get(ensemble)
    if entry is None or entry[0] is not members:
        entry = (members, _stack(members))
        _STACKS[ensemble] = entry
    mean, scale, coefs, intercepts, hidden, out = entry[1]
    a = np.repeat(X[None], len(members), axis=0)
    if mean is not None:
        a -= mean
    if scale is not None:
        a /= scale
    last = len(coefs) - 1
    for i, (w, b) in enumerate(zip(coefs, intercepts, strict=True)):
        a = np.matmul(a, w)
        a += b
        if i != last:
            hidden(a)
    out(a)
    return a[:, :, 0] if a.shape[2] == 1 else a


def _stack(members) -> tuple:
    """(scaler means (M, 1, d) or None, scales or None, coefs [(M, n_in, n_out)], intercepts
    [(M, 1, n_out)], hidden and output activation) of one ensemble's members: fitted
    ``Pipeline(StandardScaler, MLPRegressor)`` of the same layers, differing in their seeds."""
    scalers, mlps = [m.steps[0][1] for m in members], [m.steps[1][1] for m in members]
    first = mlps[0]
    mean = np.stack([s.mean_ for s in scalers])[:, None, :] if scalers[0].with_mean else None
    scale = np.stack([s.scale_ for s in scalers])[:, None, :] if scalers[0].with_std else None
    coefs = [np.stack([p.coefs_[i] for p in mlps]) for i in range(len(first.coefs_))]
    intercepts = [np.stack([p.intercepts_[i] for p in mlps])[:, None, :] for i in range(len(first.intercepts_))]
    return mean, scale, coefs, intercepts, _ACTIVATIONS[first.activation], _ACTIVATIONS[first.out_activation_]


#: in-place activations, as scikit-learn's ``neural_network._base.ACTIVATIONS``
_ACTIVATIONS = {
    "identity": lambda a: None,
    "tanh": lambda a: np.tanh(a, out=a),
    "relu": lambda a: np.maximum(a, 0, out=a),
    "logistic": lambda a: expit(a, out=a),
}
