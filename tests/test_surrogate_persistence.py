"""skops persistence of the surrogate: the fitted object round-trips bit-identically for every family
(pair, impact-velocity and wall models); tampering, versions, the type allow-list, the sidecar."""

import json
import warnings
import zipfile

import numpy as np
import pandas as pd
import pytest
import sklearn
import skops.io as sio
from sklearn.linear_model import LinearRegression
from synthetic_tables import make_synthetic_table, make_synthetic_tables, make_synthetic_wall_tables

from pbmdem.impact import WALLS
from pbmdem.surrogate import (
    FEATURE_NAMES,
    CollisionSurrogate,
    EnsembleMLPRegressorCV,
    IncompatibleVersionError,
    KrigingRegressor,
    ResponseSurface,
    SurrogateLoadError,
    TamperedModelError,
    UntrustedTypesError,
    load_surrogate,
    save_surrogate,
    training_data,
)
from pbmdem.surrogate.persistence import ALLOWED_TYPES, FORMAT_VERSION, schema_types, sha256_file
from pbmdem.surrogate.velocity import attach_velocity_bins
from pbmdem.surrogate.walls import wall_training_data

R = 0.0265  # impeller radius (m) of the synthetic tables and models


def tiny_ensemble(**kwargs) -> EnsembleMLPRegressorCV:
    kwargs = {"hidden_layer_sizes": ((4,), (5,)), "alpha": (0.1,), "seeds": (0, 1), "max_iter": 300} | kwargs
    return EnsembleMLPRegressorCV(
        **{"activation": "tanh", "solver": "lbfgs", "cv": "group_kfold", "n_splits": 3} | kwargs
    )


#: the model families (pbmdem.surrogate.settings.FAMILIES), small
FAMILIES = {
    "mlp": tiny_ensemble,
    "kriging": lambda: KrigingRegressor(n_restarts_optimizer=1, n_members=3),
    "rsm": lambda: ResponseSurface(degree=(1, 2), cv="group_kfold", n_splits=3, n_members=3),
}


def tiny_surrogate(**kwargs) -> CollisionSurrogate:
    return CollisionSurrogate(
        frequency_model=tiny_ensemble(), impeller_radius=R, physics_offset="cross_section", **kwargs
    )


def fit(model, data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return model.fit(data.X, data.y, groups=data.groups, velocity=data.velocity)


@pytest.fixture(scope="module")
def tables():
    pairs, velocities = make_synthetic_tables(R, rpms=(300, 600, 900), seed=4)
    return pairs, velocities, *make_synthetic_wall_tables(pairs, R, seed=5)


@pytest.fixture(scope="module")
def table(tables):
    return attach_velocity_bins(*tables[:2])


@pytest.fixture(scope="module")
def fitted(table):
    return fit(tiny_surrogate(), training_data(table, R))


@pytest.fixture(scope="module")
def with_walls(tables):
    """Per family: a fitted surrogate with a frequency, an impact-velocity and a model per wall."""
    pairs, velocities, walls, wall_velocities = tables
    data = training_data(pairs, R, velocity_table=velocities)

    def surrogate(family):
        inner = FAMILIES[family]
        return CollisionSurrogate(inner(), inner(), impeller_radius=R, physics_offset="cross_section")

    out = {}
    for family in FAMILIES:
        model = fit(surrogate(family).set_params(uncertainty_scale=1.3, velocity_uncertainty_scale=0.8), data)
        model.wall_models_ = {
            wall: fit(surrogate(family), wall_training_data(walls, wall_velocities, wall, R, "drop")) for wall in WALLS
        }
        out[family] = model
    return out


@pytest.fixture()
def saved(fitted, tmp_path):
    model = tmp_path / "model.skops"
    save_surrogate(fitted, model, cv_scores={"mlp": {"pooled_r2_log10": 0.9, "nan_value": float("nan")}})
    return model, tmp_path / "model.json"


def predictions(m: CollisionSurrogate, X) -> list[np.ndarray]:
    """Every prediction a consumer makes of `m` (the PBM's kernel, its members, walls, tables)."""
    d, n = np.array([0.0015, 0.002, 0.003, 0.004, 0.006]), np.array([900.0, 600.0, 400.0, 200.0, 50.0])
    out = [*m.predict_log10(X, return_std=True), *m.predict_velocity(X, return_std=True), m.velocity_fractions(X)]
    for wall in getattr(m, "wall_models_", {}).values():
        out += [*wall.predict_log10(X, return_std=True, check_domain=False), *wall.predict_velocity(X, True, False)]
    for rpm in (300.0, 600.0, 900.0):
        out += [*m.frequency_matrix(d, n, rpm, return_std=True, check_domain=False)]
        for k in range(-1, m.n_members):  # the surrogate (-1), then each of its members
            one = m if k < 0 else m.member(k)
            pairs = one.encounters(d, n, rpm, check_domain=False)
            out += [pairs.frequency, pairs.velocity_fractions]
            if getattr(m, "wall_models_", None):
                walls = one.impacts(d, n, rpm, check_domain=False).walls
                out += [walls.frequency, walls.velocity_fractions]
    return out


@pytest.mark.parametrize("family", list(FAMILIES))
def test_every_family_loads_to_bit_identical_predictions(with_walls, family, table, tmp_path):
    fitted = with_walls[family]
    meta = save_surrogate(fitted, tmp_path / "model.skops")
    loaded = load_surrogate(tmp_path / "model.skops")
    assert type(loaded.frequency_model_) is type(fitted.frequency_model_) is type(loaded.velocity_model_)
    assert sorted(loaded.wall_models_) == sorted(WALLS) and loaded.n_members == fitted.n_members
    a, b = predictions(fitted, table), predictions(loaded, table)
    assert len(a) == len(b) > 40
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    assert loaded.get_params(deep=False).keys() == fitted.get_params(deep=False).keys()
    assert loaded.uncertainty_scale == 1.3 and loaded.velocity_uncertainty_scale == 0.8
    # the sidecar says what a user reads of every model: family, features, domain, training points
    assert meta == json.loads((tmp_path / "model.json").read_text())
    assert meta["family"] == family and meta["params"]["frequency_model"]["family"] == family
    assert meta["model_sha256"] == sha256_file(tmp_path / "model.skops")
    for wall, m in [(None, fitted), *fitted.wall_models_.items()]:
        part = meta if wall is None else meta["walls"][wall]
        assert part["feature_names"] == list(m.feature_names_in_)
        assert part["feature_ranges"] == {k: list(v) for k, v in m.feature_ranges().items()}
        assert part["training_point_ids"] == m.training_point_ids_ and part["n_velocity_rows"] > 0


def test_round_trip_keeps_the_fitted_state(fitted, saved, table):
    model, meta_path = saved
    loaded = load_surrogate(model)
    for x, y in zip(predictions(fitted, table), predictions(loaded, table), strict=True):
        np.testing.assert_array_equal(x, y)
    assert loaded.velocity_model is None and loaded.has_velocity_model()
    assert loaded.feature_ranges() == fitted.feature_ranges() and loaded.n_features_in_ == len(FEATURE_NAMES) == 8
    for attr in ("training_point_ids_", "n_training_rows_", "n_velocity_rows_", "duplicated_features_"):
        assert getattr(loaded, attr) == getattr(fitted, attr), attr
    for attr in ("best_params_", "best_score_", "cv_folds_", "n_outputs_"):
        assert getattr(loaded.frequency_model_, attr) == getattr(fitted.frequency_model_, attr), attr
    for key, value in fitted.frequency_model_.cv_results_.items():
        np.testing.assert_array_equal(loaded.frequency_model_.cv_results_[key], value)
    np.testing.assert_array_equal(loaded.frequency_model_.n_iter_, fitted.frequency_model_.n_iter_)

    meta = json.loads(meta_path.read_text())
    assert meta["training_point_ids"] == sorted(table["point_id"].unique())
    assert {"sklearn", "numpy", "skops"} <= set(meta["versions"])
    assert meta["cv_scores"]["mlp"]["pooled_r2_log10"] == 0.9
    assert meta["cv_scores"]["mlp"]["nan_value"] is None  # strict JSON, no NaN
    assert meta["format_version"] == FORMAT_VERSION == 8
    assert meta["family"] == meta["velocity_family"] == "mlp"
    # the impeller radius the model was trained with, and every estimator parameter
    assert meta["params"]["impeller_radius"] == R
    assert meta["params"]["frequency_model"]["params"] == json.loads(json.dumps(fitted.frequency_model.get_params()))
    assert meta["frequency_state"]["best_params"] == json.loads(json.dumps(fitted.frequency_model_.best_params_))
    assert meta["target"].startswith("log10_encounter_frequency_per_pair")
    assert meta["n_velocity_rows"] == len(table) and len(meta["velocity_edges"]) == 18


def test_frequency_only_model_round_trips(tmp_path):
    t = make_synthetic_table(R, rpms=(300, 600, 900), seed=4)
    m = fit(tiny_surrogate(velocity_model=EnsembleMLPRegressorCV(seeds=(3,))), training_data(t, R))
    save_surrogate(m, tmp_path / "model.skops")
    loaded = load_surrogate(tmp_path / "model.skops")
    assert not loaded.has_velocity_model()
    assert loaded.get_params()["velocity_model__seeds"] == (3,)
    np.testing.assert_array_equal(m.predict_log10(t), loaded.predict_log10(t))


def test_an_adam_trained_ensemble_round_trips(table, tmp_path):
    # surrogate.solver: adam leaves scikit-learn's AdamOptimizer in every member
    m = fit(
        tiny_surrogate().set_params(frequency_model=tiny_ensemble(solver="adam", max_iter=20)), training_data(table, R)
    )
    save_surrogate(m, tmp_path / "model.skops")
    assert "sklearn.neural_network._stochastic_optimizers.AdamOptimizer" in schema_types(tmp_path / "model.skops")
    np.testing.assert_array_equal(m.predict_log10(table), load_surrogate(tmp_path / "model.skops").predict_log10(table))


def test_other_velocity_bins_rejected(saved):
    model, meta_path = saved
    meta = json.loads(meta_path.read_text())
    meta["velocity_edges"] = meta["velocity_edges"][:-1]
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(IncompatibleVersionError, match="VELOCITY_EDGES"):
        load_surrogate(model)


def test_model_file_holds_only_allowed_types(saved):
    model, _ = saved
    assert "pbmdem.surrogate.model.CollisionSurrogate" in schema_types(model) <= ALLOWED_TYPES
    assert all(t.split(".")[0] in {"builtins", "numpy", "sklearn", "pbmdem"} for t in ALLOWED_TYPES)


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


def _rehash(model, meta_path):
    """The sidecar of `model` with the hash of its current bytes (a file past the tamper check)."""
    meta = json.loads(meta_path.read_text())
    meta["model_sha256"] = sha256_file(model)
    meta_path.write_text(json.dumps(meta))


def test_a_corrupt_file_is_named_not_deserialised(saved):
    model, meta_path = saved
    model.write_bytes(b"not a zip archive")
    _rehash(model, meta_path)
    with pytest.raises(SurrogateLoadError, match=f"{model} is not a readable skops file"):
        load_surrogate(model)


def test_version_mismatch_rejected(saved):
    model, meta_path = saved
    meta = json.loads(meta_path.read_text())
    meta["versions"]["sklearn"] = "0.99.0"
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(IncompatibleVersionError, match=rf"{model} .*scikit-learn 0\.99\.0, installed is"):
        load_surrogate(model)


def test_patch_version_difference_accepted(saved):
    model, meta_path = saved
    major, minor = sklearn.__version__.split(".")[:2]
    meta = json.loads(meta_path.read_text())
    meta["versions"]["sklearn"] = f"{major}.{minor}.999"
    meta_path.write_text(json.dumps(meta))
    assert load_surrogate(model).frequency_model_.estimators_


@pytest.mark.parametrize("found", [5, 99, None])
def test_another_format_version_is_refused_with_retrain(saved, found):
    model, meta_path = saved
    meta = json.loads(meta_path.read_text())
    meta["format_version"] = found
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(
        IncompatibleVersionError,
        match=rf"{meta_path}: format version {found} .*reads version {FORMAT_VERSION}.*retrain",
    ):
        load_surrogate(model)


def test_types_outside_allow_list_rejected(saved):
    # a well-formed skops file with the right hash but an sklearn type the surrogate never uses
    model, meta_path = saved
    sio.dump([LinearRegression().fit([[0.0], [1.0]], [0.0, 1.0])], model)
    _rehash(model, meta_path)
    with pytest.raises(UntrustedTypesError, match=rf"{model} .*allow-list.*refused.*LinearRegression"):
        load_surrogate(model)


def test_a_file_not_holding_a_surrogate_is_refused(fitted, saved):
    model, meta_path = saved
    sio.dump(list(fitted.frequency_model_.estimators_), model, compression=zipfile.ZIP_DEFLATED)
    _rehash(model, meta_path)
    with pytest.raises(IncompatibleVersionError, match=rf"{model} holds a list .*expected a fitted CollisionSurrogate"):
        load_surrogate(model)


def test_saving_refuses_a_type_outside_the_allow_list(table, tmp_path):
    m = fit(tiny_surrogate(), training_data(table, R))
    m.wall_models_ = {"bowl": LinearRegression()}
    with pytest.raises(UntrustedTypesError, match="LinearRegression"):
        save_surrogate(m, tmp_path / "model.skops")
    assert not list(tmp_path.iterdir())  # nothing written, no temporary file left


def test_unfitted_cannot_be_saved(tmp_path):
    with pytest.raises(ValueError, match="fitted"):
        save_surrogate(CollisionSurrogate(), tmp_path / "m.skops")
    # nor one fitted on other features than FEATURE_NAMES (the PBM's calls build that frame)
    rng = np.random.default_rng(0)
    generic = CollisionSurrogate(
        EnsembleMLPRegressorCV(hidden_layer_sizes=((3,),), max_iter=50, solver="lbfgs"), impeller_radius=R
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        generic.fit(rng.normal(size=(20, 3)), rng.normal(size=20))
    with pytest.raises(ValueError, match="fitted on the feature frame"):
        save_surrogate(generic, tmp_path / "m.skops")


# --- the sidecar (model.json): what the loader reads of it must be there; the rest is for users
def test_a_missing_sidecar_is_named(saved):
    model, meta_path = saved
    meta_path.unlink()
    with pytest.raises(SurrogateLoadError, match=rf"surrogate metadata {meta_path} is missing.*beside the model"):
        load_surrogate(model)


@pytest.mark.parametrize(
    "edit, key",
    [
        (lambda m: None, "a JSON object is required, found NoneType"),
        (lambda m: m | {"format": "other"}, "key format = 'other', expected 'pbmdem-surrogate'"),
        (lambda m: m | {"versions": None}, "key versions = None: dict required"),
        (lambda m: m | {"versions": {}}, "versions: key sklearn = None: str required"),
        (lambda m: {k: v for k, v in m.items() if k != "model_sha256"}, "key model_sha256 = None"),
        (lambda m: m | {"training_point_ids": "rpm300"}, "key training_point_ids = 'rpm300': list required"),
        (lambda m: m | {"velocity_edges": [0.0, "fast"]}, "key velocity_edges holds 'fast': numbers required"),
    ],
)
def test_sidecar_violations_name_the_file_and_the_key(saved, edit, key):
    model, meta_path = saved
    meta_path.write_text(json.dumps(edit(json.loads(meta_path.read_text()))))
    with pytest.raises(SurrogateLoadError) as err:
        load_surrogate(model)
    assert f"surrogate metadata {meta_path}" in str(err.value)
    assert key in str(err.value)


def test_the_model_file_not_the_sidecar_holds_the_domain(fitted, saved, table):
    # a sidecar edited by hand cannot widen the domain or change a parameter: it is only read
    model, meta_path = saved
    meta = json.loads(meta_path.read_text())
    meta["feature_ranges"] = {k: [-1e300, 1e300] for k in meta["feature_ranges"]}
    meta["params"] |= {"domain_margin": 1e300, "impeller_radius": "wide"}
    meta_path.write_text(json.dumps(meta))
    loaded = load_surrogate(model)
    assert loaded.feature_ranges() == fitted.feature_ranges()
    assert loaded.domain_margin == fitted.domain_margin and loaded.impeller_radius == R
    faster = table.assign(rpm=10 * table["rpm"])  # tip speeds beyond the training range
    assert loaded.out_of_domain(faster)["tip_speed"].all()
    pd.testing.assert_frame_equal(loaded.out_of_domain(faster), fitted.out_of_domain(faster))


def test_predict_with_null_versions_is_an_error_not_a_traceback(saved, capsys):
    model, meta_path = saved
    meta_path.write_text(json.dumps(json.loads(meta_path.read_text()) | {"versions": None}))
    from pbmdem.cli import main

    code = main(
        ["surrogate", "predict", "--model", str(model), "--diameters", "0.002", "0.003"]
        + ["--numbers", "100", "100", "--rpm", "600"]
    )
    err = capsys.readouterr().err
    assert code == 2
    assert "model.json" in err and "key versions = None" in err and "Traceback" not in err
