"""skops persistence of the surrogate: round trip, tampering, versions, type allow-list."""

import json
import warnings

import numpy as np
import pytest
import skops.io as sio
from sklearn.linear_model import LinearRegression
from synthetic_tables import make_synthetic_table, make_synthetic_tables

from pbmdem.surrogate import (
    CollisionSurrogate,
    EnsembleMLPRegressorCV,
    IncompatibleVersionError,
    TamperedModelError,
    UntrustedTypesError,
    load_surrogate,
    save_surrogate,
    training_data,
)
from pbmdem.surrogate.persistence import ALLOWED_TYPES, FORMAT_VERSION, schema_types, sha256_file
from pbmdem.surrogate.velocity import attach_velocity_bins

R = 0.0265  # impeller radius (m) of the synthetic tables and models


def tiny_surrogate(**kwargs) -> CollisionSurrogate:
    ensemble = EnsembleMLPRegressorCV(
        hidden_layer_sizes=((4,), (5,)),
        alpha=(0.1,),
        seeds=(0, 1),
        max_iter=300,
        activation="tanh",
        solver="lbfgs",
        cv="group_kfold",
        n_splits=3,
    )
    return CollisionSurrogate(frequency_model=ensemble, impeller_radius=R, physics_offset="cross_section", **kwargs)


def fit(model, table):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = training_data(table, R)
        return model.fit(d.X, d.y, groups=d.groups, velocity=d.velocity)


@pytest.fixture(scope="module")
def table():
    return attach_velocity_bins(*make_synthetic_tables(R, rpms=(300, 600, 900), seed=4))


@pytest.fixture(scope="module")
def fitted(table):
    return fit(tiny_surrogate(), table)


@pytest.fixture()
def saved(fitted, tmp_path):
    model = tmp_path / "model.skops"
    save_surrogate(fitted, model, cv_scores={"mlp": {"pooled_r2_log10": 0.9, "nan_value": float("nan")}})
    return model, tmp_path / "model.json"


def test_round_trip_identical_predictions(fitted, saved, table):
    model, meta_path = saved
    loaded = load_surrogate(model)
    a, sa = fitted.predict_log10(table, return_std=True)
    b, sb = loaded.predict_log10(table, return_std=True)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(sa, sb)
    d, n = [0.002, 0.003, 0.004], [1200, 700, 300]
    np.testing.assert_array_equal(
        fitted.frequency_matrix(d, n, 600, check_domain=False), loaded.frequency_matrix(d, n, 600, check_domain=False)
    )

    def plain(m):
        return {k: v for k, v in m.get_params().items() if k not in ("frequency_model", "velocity_model")}

    assert plain(loaded) == plain(fitted) and loaded.velocity_model is None
    assert loaded.feature_ranges() == fitted.feature_ranges()
    assert list(loaded.feature_names_in_) == list(fitted.feature_names_in_) and loaded.n_features_in_ == 6
    for attr in ("training_point_ids_", "n_training_rows_", "n_velocity_rows_", "duplicated_features_"):
        assert getattr(loaded, attr) == getattr(fitted, attr), attr
    for attr in ("best_params_", "cv_folds_", "n_outputs_"):
        assert getattr(loaded.frequency_model_, attr) == getattr(fitted.frequency_model_, attr), attr
    assert loaded.frequency_model_.best_score_ == pytest.approx(fitted.frequency_model_.best_score_, rel=1e-12)
    np.testing.assert_allclose(
        loaded.frequency_model_.cv_results_["mean_test_score"],
        fitted.frequency_model_.cv_results_["mean_test_score"],
        rtol=1e-12,
    )
    assert loaded.frequency_model_.cv_results_["params"] == fitted.frequency_model_.cv_results_["params"]
    np.testing.assert_array_equal(loaded.frequency_model_.n_iter_, fitted.frequency_model_.n_iter_)
    # the impact-velocity model round-trips too
    assert loaded.has_velocity_model()
    assert len(loaded.velocity_model_.estimators_) == len(fitted.velocity_model_.estimators_)
    for x, y in zip(fitted.predict_velocity(table, return_std=True), loaded.predict_velocity(table, return_std=True)):
        np.testing.assert_array_equal(x, y)
    ea = fitted.encounters(d, n, 600, check_domain=False)
    eb = loaded.encounters(d, n, 600, check_domain=False)
    np.testing.assert_array_equal(ea.frequency, eb.frequency)
    np.testing.assert_array_equal(ea.velocity_fractions, eb.velocity_fractions)
    assert loaded.velocity_model_.best_params_ == fitted.velocity_model_.best_params_

    meta = json.loads(meta_path.read_text())
    assert meta["model_sha256"] == sha256_file(model)
    assert meta["feature_names"] == list(fitted.feature_names_in_)
    assert set(meta["feature_ranges"]) == set(fitted.feature_names_in_)
    assert meta["training_point_ids"] == sorted(table["point_id"].unique())
    assert {"sklearn", "numpy", "skops"} <= set(meta["versions"])
    assert meta["cv_scores"]["mlp"]["pooled_r2_log10"] == 0.9
    assert meta["cv_scores"]["mlp"]["nan_value"] is None  # strict JSON, no NaN
    assert meta["format_version"] == FORMAT_VERSION == 4
    assert meta["family"] == "mlp"
    assert meta["params"]["frequency_model"]["family"] == "mlp"
    # the impeller radius the model was trained with, and every estimator parameter
    assert meta["params"]["impeller_radius"] == R
    assert meta["params"]["frequency_model"]["params"] == json.loads(json.dumps(fitted.frequency_model.get_params()))
    assert meta["target"].startswith("log10_encounter_frequency_per_pair")
    assert meta["n_velocity_rows"] == len(table) and len(meta["velocity_edges"]) == 18


def test_frequency_only_model_round_trips(tmp_path):
    t = make_synthetic_table(R, rpms=(300, 600, 900), seed=4)
    m = fit(tiny_surrogate(velocity_model=EnsembleMLPRegressorCV(seeds=(3,))), t)
    save_surrogate(m, tmp_path / "model.skops")
    loaded = load_surrogate(tmp_path / "model.skops")
    assert not loaded.has_velocity_model()
    assert loaded.get_params()["velocity_model__seeds"] == (3,)
    np.testing.assert_array_equal(m.predict_log10(t), loaded.predict_log10(t))


def test_other_velocity_bins_rejected(saved):
    model, meta_path = saved
    meta = json.loads(meta_path.read_text())
    meta["velocity_edges"] = meta["velocity_edges"][:-1]
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(IncompatibleVersionError, match="VELOCITY_EDGES"):
        load_surrogate(model)


def test_model_file_holds_only_allowed_types(saved):
    model, _ = saved
    assert schema_types(model) <= ALLOWED_TYPES
    assert all(t.split(".")[0] in {"builtins", "numpy", "sklearn"} for t in ALLOWED_TYPES)


def test_tampered_file_rejected(saved):
    model, _ = saved
    data = bytearray(model.read_bytes())
    data[len(data) // 2] ^= 0xFF
    model.write_bytes(bytes(data))
    with pytest.raises(TamperedModelError, match="SHA-256"):
        load_surrogate(model)


def test_swapped_model_file_rejected(fitted, saved, tmp_path):
    model, _ = saved
    other = tmp_path / "other.skops"
    sio.dump([fitted.frequency_model_.estimators_[0]], other)
    model.write_bytes(other.read_bytes())
    with pytest.raises(TamperedModelError):
        load_surrogate(model)


def test_version_mismatch_rejected(saved):
    model, meta_path = saved
    meta = json.loads(meta_path.read_text())
    meta["versions"]["sklearn"] = "0.99.0"
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(IncompatibleVersionError, match=r"scikit-learn 0\.99\.0"):
        load_surrogate(model)


def test_patch_version_difference_accepted(saved, monkeypatch):
    import sklearn

    model, meta_path = saved
    major, minor = sklearn.__version__.split(".")[:2]
    meta = json.loads(meta_path.read_text())
    meta["versions"]["sklearn"] = f"{major}.{minor}.999"
    meta_path.write_text(json.dumps(meta))
    assert load_surrogate(model).frequency_model_.estimators_


def test_format_version_mismatch_rejected(saved):
    model, meta_path = saved
    meta = json.loads(meta_path.read_text())
    meta["format_version"] = 99
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(IncompatibleVersionError, match="format version"):
        load_surrogate(model)


def test_types_outside_allow_list_rejected(saved):
    # a well-formed skops file with the right hash but an sklearn type the surrogate never uses
    model, meta_path = saved
    sio.dump([LinearRegression().fit([[0.0], [1.0]], [0.0, 1.0])], model)
    meta = json.loads(meta_path.read_text())
    meta["model_sha256"] = sha256_file(model)
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(UntrustedTypesError, match="LinearRegression"):
        load_surrogate(model)


def test_unfitted_cannot_be_saved(tmp_path):
    with pytest.raises(ValueError, match="fitted"):
        save_surrogate(CollisionSurrogate(), tmp_path / "m.skops")
    # nor one fitted on other features than FEATURE_NAMES (the loader rebuilds the feature frame)
    rng = np.random.default_rng(0)
    generic = CollisionSurrogate(
        EnsembleMLPRegressorCV(hidden_layer_sizes=((3,),), max_iter=50, solver="lbfgs"), impeller_radius=R
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        generic.fit(rng.normal(size=(20, 3)), rng.normal(size=20))
    with pytest.raises(ValueError, match="fitted on the feature frame"):
        save_surrogate(generic, tmp_path / "m.skops")


def test_format_2_files_are_refused_with_retrain(saved):
    model, meta_path = saved
    meta = json.loads(meta_path.read_text())
    meta["format_version"] = 3
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(IncompatibleVersionError, match="format version 3 .*reads version 4.*retrain"):
        load_surrogate(model)


def test_version_1_layout_rejected(fitted, saved):
    # a format-1 file (a bare list of frequency pipelines) with a matching hash is refused clearly
    from pbmdem.surrogate import SurrogateLoadError

    model, meta_path = saved
    sio.dump(list(fitted.frequency_model_.estimators_), model)
    meta = json.loads(meta_path.read_text())
    meta["model_sha256"] = sha256_file(model)
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(SurrogateLoadError, match="frequency and velocity pipelines"):
        load_surrogate(model)


# --- the metadata contract (issue 25, item 3): every violation names model.json and the key
def _edit_metadata(meta_path, edit):
    meta = json.loads(meta_path.read_text())
    meta = edit(meta)
    meta_path.write_text(json.dumps(meta))


@pytest.mark.parametrize(
    "edit, key",
    [
        (lambda m: None, "a JSON object is required, found NoneType"),
        (lambda m: m | {"versions": None}, "key versions = None"),
        (
            lambda m: m | {"feature_ranges": m["feature_ranges"] | {"d_large": [0.002, None]}},
            "feature_ranges.d_large[1]",
        ),
        (lambda m: m | {"feature_ranges": m["feature_ranges"] | {"d_large": [0.004, 0.002]}}, "feature_ranges.d_large"),
        (
            lambda m: m | {"feature_ranges": {k: v for k, v in m["feature_ranges"].items() if k != "tip_speed"}},
            "lacks the training range of ['tip_speed']",
        ),
        (lambda m: m | {"params": m["params"] | {"domain_margin": 1e300}}, "key params.domain_margin = 1e+300"),
        (lambda m: m | {"params": m["params"] | {"impeller_radius": "wide"}}, "key params.impeller_radius = 'wide'"),
        (lambda m: m | {"feature_names": None}, "key feature_names = None"),
    ],
)
def test_metadata_violations_name_the_file_and_the_key(saved, edit, key):
    model, meta_path = saved
    _edit_metadata(meta_path, edit)
    with pytest.raises(IncompatibleVersionError) as err:
        load_surrogate(model)
    assert f"surrogate metadata {meta_path}" in str(err.value)
    assert key in str(err.value)


def test_a_nan_range_in_the_metadata_is_refused(saved):
    model, meta_path = saved
    meta = json.loads(meta_path.read_text())
    meta["feature_ranges"]["d_large"][1] = float("nan")
    meta_path.write_text(json.dumps(meta))  # Python writes NaN, and its JSON reader accepts it
    with pytest.raises(
        IncompatibleVersionError, match=r"key feature_ranges\.d_large\[1\] = nan: every number must be finite"
    ):
        load_surrogate(model)


def test_predict_with_null_versions_is_an_error_not_a_traceback(saved, capsys):
    model, meta_path = saved
    _edit_metadata(meta_path, lambda m: m | {"versions": None})
    from pbmdem.cli import main

    code = main(
        ["surrogate", "predict", "--model", str(model), "--diameters", "0.002", "0.003"]
        + ["--numbers", "100", "100", "--rpm", "600"]
    )
    err = capsys.readouterr().err
    assert code == 2
    assert "model.json" in err and "key versions = None" in err and "Traceback" not in err
