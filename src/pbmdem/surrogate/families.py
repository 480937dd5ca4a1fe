"""Model families of the encounter surrogate besides the MLP ensemble: Kriging
(:class:`KrigingRegressor`) and a response surface (:class:`ResponseSurface`); docs/surrogate.md
("Model families and the kernel source") describes the families, how each is tuned and why HDMR is
not fitted separately.

Both classes here are scikit-learn regressors on any numeric ``X`` (1-D or 2-D ``y``; every output
gets a model of its own) whose ``predict(X, return_std=True)`` returns the predictive standard
deviation of the model (Kriging: posterior incl. the fitted noise; RSM: Bayesian ridge
posterior), and share the interface the surrogate uses with the MLP ensemble:

* :meth:`predict_array` (the PBM's frequent calls, without scikit-learn's per-call validation),
* ``n_members``: the surrogate's members are the quantiles ``mean + z_k std`` of the predictive
  normal, ``z_k = Phi^-1((k + 1/2) / n)`` (``CollisionSurrogate.member``), so that PBM-ANN can run
  once per member as with the ensemble,
* :meth:`fitted_state`, what the model's sidecar (``model.json``) says of the fit.

Fits are single-threaded (:func:`~pbmdem.surrogate._threads.single_threaded`): the matrices are
tiny, and one thread makes the optimiser's path independent of the thread count.
"""

from __future__ import annotations

import logging
import warnings

import numpy as np
from scipy.linalg import solve_triangular
from scipy.optimize import minimize
from scipy.spatial.distance import cdist
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, DotProduct, Product, Sum, WhiteKernel
from sklearn.gaussian_process.kernels import ConstantKernel as Constant
from sklearn.linear_model import BayesianRidge
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import PolynomialFeatures, StandardScaler
from sklearn.utils.validation import check_is_fitted, validate_data

from ._terms import SHARED, polynomial_terms
from ._threads import single_threaded
from .ensemble import grouped_splits
from .errors import array_input

log = logging.getLogger(__name__)


#: Bounds of the Kriging length scales, in standard deviations of each (log) feature. A DEM grid
#: samples a feature at a handful of levels (3-5 speeds, a few distributions), about one standard
#: deviation apart: a length scale far below 0.1 could only fit the noise between levels, and one
#: that wanders down there makes the likelihood multi-modal, so that the optimiser's choice
#: depended on the BLAS kernel (5 % different predictions under OpenBLAS' Haswell and SkylakeX
#: kernels with (0.01, 1000); 1e-12 with these bounds; benchmarks/bench_surrogate_reproducibility.py).
#: 1000 means "irrelevant feature".
LENGTH_SCALE_BOUNDS = (0.1, 1e3)


def converged_lbfgs(obj_func, initial_theta, bounds):
    """L-BFGS-B run to a tight convergence (projected gradient 1e-9, relative decrease 1e-15):
    scikit-learn's default stops where another BLAS kernel's rounding moves the hyperparameters by
    ~1e-5 relative (measured on the default grid's tables); converged, they agree to ~1e-9."""
    result = minimize(
        obj_func,
        initial_theta,
        method="L-BFGS-B",
        jac=True,
        bounds=bounds,
        options={"gtol": 1e-9, "ftol": 1e-15, "maxiter": 15000},
    )
    return result.x, result.fun


class _PerOutputRegressor(RegressorMixin, BaseEstimator):
    """Shared machinery: one scikit-learn pipeline per output, predictive mean and std, members."""

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.target_tags.multi_output = True
        return tags

    def _pipeline(self, n_features: int) -> Pipeline:  # pragma: no cover - abstract
        raise NotImplementedError

    def _check_params(self) -> None:
        if int(self.n_members) < 1:
            raise ValueError(f"n_members must be >= 1, got {self.n_members!r}")

    def fit(self, X, y, groups=None):
        """Fit one pipeline per column of ``y``; ``groups`` is accepted for the common interface
        (these families have no hyperparameter search over groups) and not used."""
        self._check_params()
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        Y = y.reshape(len(y), -1)
        with single_threaded(), warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            self.estimators_ = [self._pipeline(X.shape[1]).fit(X, Y[:, j]) for j in range(Y.shape[1])]
        for w in caught:
            self._report_warning(w)
        self.n_outputs_ = 1 if y.ndim == 1 else int(Y.shape[1])
        return self

    def _report_warning(self, w) -> None:
        """Warnings of the inner fits are passed on (never dropped)."""
        warnings.warn(w.message, w.category, stacklevel=4)

    @property
    def n_members_(self) -> int:
        return int(self.n_members)

    def _output(self, est: Pipeline, X: np.ndarray, return_std: bool, shared: dict):  # pragma: no cover - abstract
        """(mean, std or None) of one output's fitted pipeline at X; ``shared``: work that the
        outputs of one prediction (or of the predictions inside :func:`~._terms.shared_terms`) may share."""
        raise NotImplementedError

    def _predict(self, X: np.ndarray, return_std: bool):
        """Mean (and with ``return_std`` the standard deviation) of every output; the standard
        deviation costs the most, so it is computed only when asked for."""
        # no thread limit here: a prediction is a few small products that OpenBLAS runs on one
        # thread anyway, and setting up the limit cost tens of ms on the PBM's first call
        means, stds = [], []
        shared = SHARED.get()
        shared = {} if shared is None else shared
        for est in self.estimators_:  # a loop, not a comprehension: the Kriging warning's stacklevel
            mean, std = self._output(est, X, return_std, shared)
            means.append(mean)
            stds.append(std)
        mean = np.column_stack(means)
        if not return_std:
            return mean[:, 0] if self.n_outputs_ == 1 else mean
        std = np.column_stack(stds)
        return (mean[:, 0], std[:, 0]) if self.n_outputs_ == 1 else (mean, std)

    def predict(self, X, return_std: bool = False):
        """Predictive mean (units of ``y``); with ``return_std`` also the predictive standard deviation."""
        check_is_fitted(self)
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self._predict(X, return_std)

    def predict_array(self, X: np.ndarray, return_std: bool = False):
        """:meth:`predict` on a trusted float64 array in the training feature order, without
        scikit-learn's per-call validation (both families predict by their fitted attributes)."""
        X = array_input(self, X)
        return self._predict(X, return_std)

    def fitted_state(self) -> dict:
        """JSON-able description of the fit (for the model's sidecar)."""
        return {"n_outputs": self.n_outputs_, "fitted": self.describe()}


def cross_kernel(kernel, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """``kernel(X, Y)`` of a fitted kernel built of sums and products of ``Constant``, ``RBF``,
    ``DotProduct`` and ``WhiteKernel`` (:class:`KrigingRegressor`'s) by scikit-learn's own lines for
    X != Y (a constant times the term, ``exp(-0.5 cdist(X / l, Y / l, "sqeuclidean"))``,
    ``inner(X, Y) + sigma_0^2``, the white noise 0 off the training points), without the kernel
    objects' calls and checks: the same operations on the same numbers (a constant's product with a
    scalar instead of a filled matrix, the white noise's zeros not added: x + 0 is x). Any other
    kernel is called."""
    K = _kernel_terms(kernel, X, Y)
    return K if isinstance(K, np.ndarray) and K.shape == (len(X), len(Y)) else kernel(X, Y)


def _kernel_terms(kernel, X: np.ndarray, Y: np.ndarray):
    """:func:`cross_kernel` of one term: a matrix, a constant's scalar or None (white noise: zeros)."""
    kind = type(kernel)
    if kind is Sum or kind is Product:
        a, b = _kernel_terms(kernel.k1, X, Y), _kernel_terms(kernel.k2, X, Y)
        if kind is Sum:
            return a if b is None else b if a is None else a + b
        if a is not None and b is not None:
            return a * b
    elif kind is Constant:
        return np.float64(kernel.constant_value)
    elif kind is RBF:
        length_scale = np.squeeze(kernel.length_scale).astype(float)
        return np.exp(-0.5 * cdist(X / length_scale, Y / length_scale, metric="sqeuclidean"))
    elif kind is DotProduct:
        return np.inner(X, Y) + kernel.sigma_0**2
    elif kind is WhiteKernel:
        return None
    return kernel(X, Y)


class KrigingRegressor(_PerOutputRegressor):
    """Kriging: Gaussian-process regression with an anisotropic kernel and a noise term.

    Kernel (on standardised features): ``C * RBF(length_scale=[l_1 .. l_d]) + T * DotProduct +
    WhiteKernel`` (length scales within :data:`LENGTH_SCALE_BOUNDS`, the dot product's offset fixed
    at 1 so that the trend adds one hyperparameter, its variance ``T``). One length scale per
    feature (ARD) lets the data say how smooth the response is along each feature and which features
    hardly matter (their length scale runs to the upper bound); the dot-product term is a linear
    trend (universal Kriging), so that outside the data the prediction follows the trend rather than
    reverting to the mean (with log features and a log target a linear trend is a power law); the
    white-noise term absorbs the replicate noise of the DEM means. Hyperparameters maximise the log
    marginal likelihood (L-BFGS-B) from the initial
    values and ``n_restarts_optimizer`` random starts drawn with ``random_state``; ``normalize_y``.

    Parameters
    ----------
    n_restarts_optimizer : int
        Extra optimiser starts (the best likelihood wins).
    linear_trend : bool
        Add the dot-product (linear trend) term.
    random_state : int
        Seed of the optimiser's restarts.
    n_members : int
        Members of the surrogate (quantiles of the predictive normal, ``CollisionSurrogate.member``).
    """

    def __init__(self, n_restarts_optimizer: int = 5, linear_trend: bool = True, random_state: int = 0, n_members=5):
        self.n_restarts_optimizer = n_restarts_optimizer
        self.linear_trend = linear_trend
        self.random_state = random_state
        self.n_members = n_members

    def _pipeline(self, n_features: int) -> Pipeline:
        kernel = Constant(1.0, (1e-3, 1e3)) * RBF(np.ones(n_features), LENGTH_SCALE_BOUNDS)
        if self.linear_trend:
            kernel = kernel + Constant(0.1, (1e-4, 1e2)) * DotProduct(1.0, "fixed")
        kernel = kernel + WhiteKernel(1e-2, (1e-6, 1.0))
        gp = GaussianProcessRegressor(
            kernel,
            optimizer=converged_lbfgs,
            normalize_y=True,
            n_restarts_optimizer=int(self.n_restarts_optimizer),
            random_state=int(self.random_state),
        )
        return Pipeline([("scale", StandardScaler()), ("gp", gp)])

    def fit(self, X, y, groups=None):
        super().fit(X, y, groups)
        for est in self.estimators_:
            # the optimiser is not needed to predict; the stored model names scikit-learn's own
            # (a function of this module would have to be trusted when the model file is loaded)
            est[-1].optimizer = "fmin_l_bfgs_b"
        return self

    def _output(self, est: Pipeline, X: np.ndarray, return_std: bool, shared: dict):
        """:meth:`GaussianProcessRegressor.predict`'s lines on the fitted pipeline's attributes
        (scale; mean ``K(x, X_train) @ alpha``; variance ``k(x, x) - |L^-1 K(x, X_train)^T|^2``,
        negative variances set to 0 with the same warning; undo ``normalize_y``) without
        scikit-learn's validation at each step, which cost most of a prediction; equal to the
        pipelines' ``predict`` (tests/test_surrogate_families.py)."""
        (_, scale), (_, gp) = est.steps  # by position: naming a step costs a lookup
        x = (X - scale.mean_) / scale.scale_
        K_trans = cross_kernel(gp.kernel_, x, gp.X_train_)
        mean = gp._y_train_std * (K_trans @ gp.alpha_) + gp._y_train_mean
        if not return_std:
            return mean, None
        V = solve_triangular(gp.L_, K_trans.T, lower=True, check_finite=False)
        var = gp.kernel_.diag(x).copy()
        var -= np.einsum("ij,ji->i", V.T, V)
        if np.any(var < 0):
            warnings.warn("Predicted variances smaller than 0. Setting those variances to 0.", stacklevel=4)
            var[var < 0] = 0.0
        return mean, np.sqrt(var * gp._y_train_std**2)

    def _report_warning(self, w) -> None:
        # A length scale at its upper bound means the response hardly varies along that feature:
        # expected for an irrelevant feature, so it is logged, not raised; any other warning is raised.
        if issubclass(w.category, ConvergenceWarning) and "close to the specified" in str(w.message):
            log.info("Kriging: %s", w.message)
            return
        super()._report_warning(w)

    def describe(self) -> list[str]:
        """The fitted kernel of every output."""
        check_is_fitted(self)
        return [str(est[-1].kernel_) for est in self.estimators_]


class ResponseSurface(_PerOutputRegressor):
    """Response surface: a polynomial in the standardised features, fitted by Bayesian ridge.

    The polynomial terms (with interactions) are standardised and fitted by
    :class:`~sklearn.linear_model.BayesianRidge`, which chooses the penalty from the data (evidence
    maximisation) and gives the posterior predictive standard deviation. The degree is chosen per
    output among the candidates ``degree`` by grouped cross-validation over ``groups`` (whole DEM
    runs held out; the smallest mean squared error, ties to the lower degree): a full quadratic in
    six features has 27 terms, and held out along a feature that the grid samples at a few levels
    it can extrapolate wildly, where a lower degree does not.

    Parameters
    ----------
    degree : int or sequence of int
        Candidate polynomial degrees (1: a power law in log features; 2: the classical quadratic
        response surface).
    cv, n_splits
        Grouped splitter of the degree choice (as for the MLP ensemble).
    n_members : int
        Members of the surrogate (as for Kriging).

    Attributes
    ----------
    degrees_ : list of int
        The chosen degree of every output.
    cv_mse_ : list of dict
        Grouped-CV mean squared error of every candidate degree, per output (empty without groups).
    """

    def __init__(self, degree=(1, 2), cv: str = "group_kfold", n_splits: int = 5, n_members: int = 5):
        self.degree = degree
        self.cv = cv
        self.n_splits = n_splits
        self.n_members = n_members

    def _degrees(self) -> list[int]:
        degrees = sorted({int(d) for d in np.atleast_1d(self.degree)})
        if not degrees or not all(1 <= d <= 4 for d in degrees):
            raise ValueError(f"degree: candidates from 1 to 4 are allowed, got {self.degree!r}")
        return degrees

    def _check_params(self) -> None:
        super()._check_params()
        self._degrees()

    def _pipeline_of(self, degree: int) -> Pipeline:
        return Pipeline(
            [
                ("scale", StandardScaler()),
                ("poly", PolynomialFeatures(degree, include_bias=False)),
                ("scale_terms", StandardScaler()),
                ("ridge", BayesianRidge()),
            ]
        )

    def fit(self, X, y, groups=None):
        """Choose the degree of every output by grouped CV over ``groups`` (with one candidate or
        fewer than two groups: the lowest candidate), then fit it on all rows."""
        self._check_params()
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        Y = y.reshape(len(y), -1)
        degrees = self._degrees()
        splits = []
        if len(degrees) > 1 and groups is not None and len(np.unique(groups)) >= 2:
            splits = grouped_splits(np.asarray(groups), self.cv, self.n_splits)
        self.degrees_, self.cv_mse_, self.estimators_ = [], [], []
        with single_threaded():
            for j in range(Y.shape[1]):
                mse = {}
                for degree in degrees if splits else []:
                    err = [
                        (self._pipeline_of(degree).fit(X[tr], Y[tr, j]).predict(X[te]) - Y[te, j]) ** 2
                        for tr, te in splits
                    ]
                    mse[degree] = float(np.mean(np.concatenate(err)))
                best = min(mse, key=lambda d: (mse[d], d)) if mse else degrees[0]
                self.degrees_.append(int(best))
                self.cv_mse_.append(mse)
                self.estimators_.append(self._pipeline_of(best).fit(X, Y[:, j]))
        self.n_outputs_ = 1 if y.ndim == 1 else int(Y.shape[1])
        return self

    def _output(self, est: Pipeline, X: np.ndarray, return_std: bool, shared: dict):
        """One output by the pipeline's own arithmetic on its fitted attributes (scalers,
        polynomial powers, the ridge's coefficients and posterior covariance), without
        scikit-learn's validation at each of the four steps, which cost most of a prediction;
        equal to the pipelines' ``predict`` (tests/test_surrogate_families.py). Outputs whose
        scalers and powers are equal (the same degree, fitted on the same rows) share the terms
        (``shared``): the same operations on the same numbers."""
        terms = polynomial_terms(est, X, shared)
        ridge = est.steps[-1][1]
        mean = terms @ ridge.coef_ + ridge.intercept_
        if not return_std:
            return mean, None
        return mean, np.sqrt((terms @ ridge.sigma_ * terms).sum(axis=1) + 1.0 / ridge.alpha_)

    def fitted_state(self) -> dict:
        return {**super().fitted_state(), "cv_mse": [{str(k): v for k, v in m.items()} for m in self.cv_mse_]}

    def describe(self) -> list[str]:
        """Degree, terms and the fitted noise and weight precisions of every output."""
        check_is_fitted(self)
        return [
            f"degree {est['poly'].degree}: {est['poly'].n_output_features_} terms, noise precision "
            f"{est[-1].alpha_:.4g}, weight precision {est[-1].lambda_:.4g}"
            for est in self.estimators_
        ]
