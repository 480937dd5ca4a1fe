"""scikit-learn's estimator checks on the surrogate's estimators (small instances, quick fits).

``EnsembleMLPRegressorCV``, ``KrigingRegressor``, ``ResponseSurface``,
``CollisionSurrogate(physics_offset="none")`` and ``HGBBaseline`` must pass every check.
``PhysicalScaling`` and ``CollisionSurrogate(physics_offset="cross_section")`` are laws of the named
features ``d_small``, ``d_large`` and ``tip_speed``; the checks below fit them on generic arrays
(2-10 unnamed columns, negative values), which such a law cannot take, so exactly these checks are
expected to fail for them (strict: a listed check that passes fails the test). Their API checks
(clone, parameters, tags, repr, unfitted errors) run and must pass; ``test_surrogate_model.py``
exercises them on feature frames. ``check_array_api_input`` is skipped by scikit-learn itself unless
``SCIPY_ARRAY_API=1`` is set.
"""

import pickle
import warnings

import joblib
import numpy as np
import pytest
from sklearn.base import clone
from sklearn.exceptions import DataConversionWarning, NotFittedError
from sklearn.metrics import r2_score
from sklearn.utils.estimator_checks import parametrize_with_checks
from sklearn.utils.validation import check_is_fitted
from synthetic_tables import make_synthetic_table

from pbmdem.surrogate import (
    CollisionSurrogate,
    EnsembleMLPRegressorCV,
    HGBBaseline,
    KrigingRegressor,
    PhysicalScaling,
    ResponseSurface,
    training_data,
)

#: A small ensemble: two members, one tiny architecture, quick lbfgs fits.
SMALL = dict(hidden_layer_sizes=((5,),), alpha=(0.01,), seeds=(0, 1), max_iter=200, activation="tanh", solver="lbfgs")
R = 0.0265  # impeller radius (m); not used by fit/predict on a feature matrix, but required

_GENERIC = (
    "fits on generic unnamed arrays; the law needs the named features d_small, d_large and tip_speed "
    "(a feature frame, or an array with the columns FEATURE_NAMES)"
)

#: Checks that fit a law of named features on generic data, each with its reason.
NAMED_FEATURE_LAW_FAILURES = {
    "check_fit_score_takes_y": _GENERIC,
    "check_estimators_overwrite_params": _GENERIC,
    "check_dont_overwrite_parameters": _GENERIC,
    "check_estimators_fit_returns_self": _GENERIC,
    "check_readonly_memmap_input": _GENERIC,
    "check_n_features_in_after_fitting": _GENERIC,
    "check_positive_only_tag_during_fit": _GENERIC + " (iris, 4 columns)",
    "check_estimators_dtypes": _GENERIC,
    "check_dtype_object": _GENERIC + " (before it tests the object dtype)",
    "check_pipeline_consistency": _GENERIC,
    "check_estimators_nan_inf": _GENERIC + " (before it tests NaN/inf at predict)",
    "check_estimators_pickle": _GENERIC,
    "check_f_contiguous_array_estimator": _GENERIC,
    "check_regressors_train": _GENERIC,
    "check_regressor_data_not_an_array": _GENERIC,
    "check_regressors_no_decision_function": _GENERIC,
    "check_supervised_y_2d": _GENERIC,
    "check_regressors_int": _GENERIC,
    "check_methods_sample_order_invariance": _GENERIC,
    "check_methods_subset_invariance": _GENERIC,
    "check_fit2d_1sample": _GENERIC + " (the error names the features, not the sample count)",
    "check_fit2d_1feature": _GENERIC + " (the error names the features, not the feature count)",
    "check_dict_unchanged": _GENERIC,
    "check_fit_idempotent": _GENERIC,
    "check_fit_check_is_fitted": _GENERIC,
    "check_n_features_in": _GENERIC,
    "check_fit2d_predict1d": _GENERIC,
}


def is_named_feature_law(estimator) -> bool:
    return isinstance(estimator, PhysicalScaling) or (
        isinstance(estimator, CollisionSurrogate) and estimator.physics_offset == "cross_section"
    )


def expected_failures(estimator) -> dict:
    return NAMED_FEATURE_LAW_FAILURES if is_named_feature_law(estimator) else {}


ESTIMATORS = [
    EnsembleMLPRegressorCV(**SMALL),
    CollisionSurrogate(frequency_model=EnsembleMLPRegressorCV(**SMALL), impeller_radius=R, physics_offset="none"),
    CollisionSurrogate(
        frequency_model=EnsembleMLPRegressorCV(**SMALL), impeller_radius=R, physics_offset="cross_section"
    ),
    HGBBaseline(max_iter=20),
    PhysicalScaling(),
    KrigingRegressor(n_restarts_optimizer=0),
    ResponseSurface(),
]


@parametrize_with_checks(ESTIMATORS, expected_failed_checks=expected_failures, xfail_strict=True)
def test_sklearn_estimator_checks(estimator, check):
    check(estimator)


def test_only_the_named_feature_laws_have_expected_failures():
    laws = [type(e).__name__ + getattr(e, "physics_offset", "") for e in ESTIMATORS if is_named_feature_law(e)]
    assert laws == ["CollisionSurrogatecross_section", "PhysicalScaling"]


@pytest.mark.parametrize("law", [e for e in ESTIMATORS if is_named_feature_law(e)], ids=repr)
def test_named_feature_laws_follow_the_conventions_on_feature_frames(law):
    """What the listed checks would test, on the data such a law is made for."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # a frequency-only table
        data = training_data(make_synthetic_table(R, rpms=(300, 600, 900), seed=2), R)
    X, y = data.X, data.y
    est = clone(law)
    with pytest.raises(NotFittedError):
        check_is_fitted(est)
    with pytest.raises(NotFittedError):
        est.predict(X)
    params = joblib.hash(est.get_params())
    public = set(vars(est))
    assert est.fit(X, y) is est
    assert joblib.hash(est.get_params()) == params  # parameters untouched
    assert {k for k in vars(est) if not k.endswith("_")} == public  # only fitted attributes added
    assert est.n_features_in_ == X.shape[1] and list(est.feature_names_in_) == list(X.columns)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # out-of-domain checks of the surrogate
        p = est.predict(X)
        state = dict(vars(est))
        assert p.shape == y.shape and est.score(X, y) == pytest.approx(r2_score(y, p))
        assert vars(est).keys() == state.keys()  # predict does not change the estimator
        np.testing.assert_allclose(est.predict(X.iloc[7:19]), p[7:19])  # subset and order invariance
        np.testing.assert_allclose(est.predict(X.iloc[::-1]), p[::-1])
        np.testing.assert_array_equal(clone(law).fit(X, y).predict(X), p)  # idempotent
        np.testing.assert_array_equal(pickle.loads(pickle.dumps(est)).predict(X), p)
    with pytest.warns(DataConversionWarning, match="column-vector y"):
        np.testing.assert_array_equal(clone(law).fit(X, y[:, None]).predict(X), p)
    with pytest.raises(ValueError, match="feature names"):
        est.predict(X.iloc[:, ::-1])
    with pytest.raises(ValueError, match="has 5 features"):
        est.predict(X.iloc[:, :5].to_numpy())
    with pytest.raises(ValueError, match="Input y contains NaN"):
        clone(law).fit(X, np.where(np.arange(len(y)) == 3, np.nan, y))
    with pytest.raises(ValueError, match="Input X contains infinity"):
        est.predict(X.assign(n_total=np.inf))


@pytest.mark.parametrize("bad", [None, 0.0, -0.02, float("nan"), "26 mm"])
def test_surrogate_refuses_to_fit_without_an_impeller_radius(bad):
    X = np.random.default_rng(0).uniform(1.0, 2.0, size=(12, 3))
    with pytest.raises(ValueError, match=r"impeller_radius \(granulator.impeller.blade_length\)"):
        CollisionSurrogate(frequency_model=EnsembleMLPRegressorCV(**SMALL), impeller_radius=bad).fit(X, X[:, 0])
