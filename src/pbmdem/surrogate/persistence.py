"""Save and load a fitted :class:`CollisionSurrogate`: the object in a skops file, a JSON sidecar for users.

* ``model.skops`` - the fitted surrogate itself (frequency and impact-velocity models, the wall
  models under ``wall_models_``), written by :func:`skops.io.dump` (deflate-compressed).
* ``model.json`` - the sidecar a user (and the report) reads: format and version, the SHA-256 of
  ``model.skops``, library versions, family and parameters, features and their training ranges
  (the domain), training points, what was fitted, held-out scores and what training adds. Loading
  reads only the format version, the hash, the scikit-learn version and the velocity bins from it.

:func:`load_surrogate` refuses, before anything is deserialised: a missing or unreadable sidecar
(:class:`SurrogateLoadError`), another format version, scikit-learn major.minor or velocity bins
(:class:`IncompatibleVersionError`: the file, the version found and the one expected), a model file
whose SHA-256 differs from the sidecar's (:class:`TamperedModelError`) and any type outside
:data:`ALLOWED_TYPES` (:class:`UntrustedTypesError`). Every type named in the file's schema is
checked, because skops' own trust is wider (since skops 0.10 every scikit-learn estimator: a
``LinearRegression`` would load); they are then all passed as ``trusted`` (skops audits the file
again while loading: a type it finds that the schema did not name is refused too).
:func:`save_surrogate` checks its file before moving it into place: the schema's types and those
``skops.io.get_untrusted_types`` reports (the project's classes, the Gaussian-process kernels).
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
import os
import platform
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import scipy
import sklearn
import skops
import skops.io as sio
from skops.io.exceptions import UntrustedTypesFoundException

from pbmdem.atomic import atomic_path, write_json
from pbmdem.impact import VELOCITY_EDGES

from .ensemble import EnsembleMLPRegressorCV
from .families import KrigingRegressor, ResponseSurface
from .features import FEATURE_NAMES, TARGET_NAME
from .model import CollisionSurrogate

#: The model families a saved surrogate may use, by their name in the sidecar (``surrogate.model``).
FAMILY_CLASSES = {"mlp": EnsembleMLPRegressorCV, "kriging": KrigingRegressor, "rsm": ResponseSurface}

FORMAT = "pbmdem-surrogate"
#: 8: the pooled fast tail of the impact speeds (``speed_tail``); 7: the features rel_small, rel_large;
#: 6: the impact-speed law may be of another family than the frequency (``velocity_family``;
#: 5: one family for both); 5: the fitted CollisionSurrogate itself in the skops file, the sidecar
#: for users (4: fitted pipelines, the rest rebuilt from the metadata; 3: MLP only; 2: one class;
#: 1: raw target).
FORMAT_VERSION = 8

#: Every type that may appear in a surrogate model file (module.qualname).
ALLOWED_TYPES = frozenset(
    {f"{cls.__module__}.{cls.__qualname__}" for cls in (CollisionSurrogate, *FAMILY_CLASSES.values())}
    | {f"builtins.{t}" for t in ("dict", "list", "tuple", "str", "int", "float", "bool", "NoneType")}
    | {f"numpy.{t}" for t in ("ndarray", "dtype", "float64", "float32", "int64", "int32", "bool_", "bool")}
    | {"numpy.random.mtrand.RandomState", "numpy.random._mt19937.MT19937"}
    | {
        "sklearn.pipeline.Pipeline",
        "sklearn.preprocessing._data.StandardScaler",
        "sklearn.neural_network._multilayer_perceptron.MLPRegressor",
        "sklearn.neural_network._stochastic_optimizers.AdamOptimizer",  # surrogate.solver: adam
        "sklearn.gaussian_process._gpr.GaussianProcessRegressor",
        "sklearn.preprocessing._polynomial.PolynomialFeatures",
        "sklearn.linear_model._bayes.BayesianRidge",
    }
    | {f"sklearn.gaussian_process.kernels.{k}" for k in ("ConstantKernel", "Product", "Sum", "RBF", "DotProduct")}
    | {"sklearn.gaussian_process.kernels.WhiteKernel"}
)

RETRAIN = "; retrain the surrogate (pbmdem surrogate train, or the workflow's rule train_surrogate)"


class SurrogateLoadError(RuntimeError):
    """A saved surrogate cannot be loaded safely."""


class TamperedModelError(SurrogateLoadError):
    """The model file does not match the SHA-256 recorded in its sidecar."""


class IncompatibleVersionError(SurrogateLoadError):
    """The model was written by an incompatible library or format version."""


class UntrustedTypesError(SurrogateLoadError):
    """The model file contains types outside the allow-list."""


def sha256_file(path: str | os.PathLike) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def library_versions() -> dict[str, str]:
    return {
        "python": platform.python_version(),
        "sklearn": sklearn.__version__,
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "skops": skops.__version__,
        "pandas": pd.__version__,
    }


def _jsonable(obj):
    """Plain-JSON copy: numpy scalars/arrays to Python, tuples to lists, NaN/inf to None."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    return obj


def metadata_path_for(model_path: str | os.PathLike) -> Path:
    return Path(model_path).with_suffix(".json")


def family_name(model) -> str:
    """The family name (``mlp``, ``kriging``, ``rsm``) of an inner model."""
    for name, cls in FAMILY_CLASSES.items():
        if type(model) is cls:
            return name
    raise ValueError(f"{type(model).__name__} is not a surrogate model family {sorted(FAMILY_CLASSES)}")


def _tail_metadata(tail) -> dict | None:
    """The pooled fast tail (:func:`~.tail.fit_speed_tail`) as a user reads it, or None."""
    if tail is None:
        return None
    first, a, beta, spread = tail
    return {
        "from_m_s": float(VELOCITY_EDGES[first]),
        "a": a,
        "beta": beta,
        "sd_ln_a_between_runs": spread,  # the members' a: a exp(-z sd)
        "law": "P(V>v|V>v_s) = exp(-a((v/v_tip)^beta - (v_s/v_tip)^beta))",
    }


def _model_metadata(surrogate: CollisionSurrogate) -> dict:
    """What a user reads of one fitted surrogate (the pair model, or a wall model under ``walls``)."""
    freq, vel = surrogate.frequency_model_, surrogate.velocity_model_
    params = surrogate.get_params(deep=False)
    for key in ("frequency_model", "velocity_model"):
        if params[key] is not None:
            params[key] = {"family": family_name(params[key]), "params": params[key].get_params(deep=False)}
    return {
        "params": params,
        "family": family_name(freq),
        "velocity_family": None if vel is None else family_name(vel),
        "frequency_state": freq.fitted_state(),
        "velocity_state": None if vel is None else vel.fitted_state(),
        "n_velocity_rows": surrogate.n_velocity_rows_,
        "speed_tail": _tail_metadata(surrogate.speed_tail_),
        "duplicated_features": [list(p) for p in surrogate.duplicated_features_],
        "feature_names": [str(n) for n in surrogate.feature_names_in_],
        "feature_ranges": {k: list(v) for k, v in surrogate.feature_ranges().items()},
        "training_point_ids": list(surrogate.training_point_ids_),
        "n_training_rows": surrogate.n_training_rows_,
    }


def save_surrogate(
    surrogate: CollisionSurrogate,
    model_path: str | os.PathLike,
    metadata_path: str | os.PathLike | None = None,
    cv_scores: dict | None = None,
    extra: dict | None = None,
) -> dict:
    """Write ``model.skops`` and its JSON sidecar (atomically); return the sidecar's dict."""
    if not hasattr(surrogate, "frequency_model_"):
        raise ValueError("only a fitted CollisionSurrogate can be saved")
    names = [str(n) for n in getattr(surrogate, "feature_names_in_", [])]
    if names != list(FEATURE_NAMES):
        raise ValueError(
            f"only a surrogate fitted on the feature frame {list(FEATURE_NAMES)} can be saved, "
            f"this one was fitted on {names or 'an array without feature names'}"
        )
    model_path = Path(model_path)
    metadata_path = metadata_path_for(model_path) if metadata_path is None else Path(metadata_path)
    with atomic_path(model_path) as tmp:
        sio.dump(surrogate, tmp, compression=zipfile.ZIP_DEFLATED)
        # never write a file that load_surrogate refuses
        refuse_unknown(schema_types(tmp) | set(sio.get_untrusted_types(file=tmp)), model_path)
    walls = getattr(surrogate, "wall_models_", None) or {}
    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "created_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "model_file": model_path.name,
        "model_sha256": sha256_file(model_path),
        "estimator": "pbmdem.surrogate.CollisionSurrogate",
        "target": f"{TARGET_NAME} (fitted in log10 space; frequency_matrix returns 1/s per particle pair)",
        "velocity_target": (
            f"{surrogate.speed_law} impact-speed law per pair (pbmdem.surrogate.velocity): [log10 median speed (m/s) "
            f"minus the physics offset, log10 sigma (decades){', q' if surrogate.speed_law == 'gengamma' else ''}], "
            "fitted by ML to the bins of pbmdem.impact.VELOCITY_EDGES"
            if surrogate.velocity_model_ is not None
            else None
        ),
        "velocity_edges": [float(e) for e in VELOCITY_EDGES],
        **_model_metadata(surrogate),
        # per wall: the same fields of its CollisionSurrogate (pbmdem.surrogate.walls)
        "walls": {wall: _model_metadata(model) for wall, model in walls.items()},
        "cv_scores": cv_scores or {},
        "versions": library_versions(),
        **(extra or {}),
    }
    meta = _jsonable(meta)
    write_json(metadata_path, meta, sort_keys=False)
    return meta


def schema_types(model_path: str | os.PathLike) -> set[str]:
    """All ``module.class`` names referenced by the schema of a skops file (nothing is loaded)."""
    try:
        with zipfile.ZipFile(model_path) as zf:
            schema = json.loads(zf.read("schema.json"))
    except (OSError, zipfile.BadZipFile, KeyError, json.JSONDecodeError) as exc:
        raise SurrogateLoadError(f"{model_path} is not a readable skops file: {exc}") from exc
    found: set[str] = set()

    def walk(node):
        if isinstance(node, dict):
            if "__class__" in node:
                found.add(f"{node.get('__module__')}.{node['__class__']}")
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(schema)
    return found


def refuse_unknown(types: set[str], name: str | os.PathLike) -> list[str]:
    """`types` (sorted) if they are all in :data:`ALLOWED_TYPES`, else :class:`UntrustedTypesError` naming `name`."""
    bad = sorted(set(types) - ALLOWED_TYPES)
    if bad:
        raise UntrustedTypesError(f"{name} contains types outside the allow-list (ALLOWED_TYPES), refused: {bad}")
    return sorted(types)


def _require(meta: dict, key: str, kind, where: str):
    value = meta.get(key)
    if not isinstance(value, kind) or isinstance(value, bool):
        raise IncompatibleVersionError(f"{where}: key {key} = {value!r:.60}: {kind.__name__} required{RETRAIN}")
    return value


def read_metadata(metadata_path: str | os.PathLike) -> dict:
    """The sidecar at `metadata_path`, after its format version and the keys the loader and the
    report read (the hash, the library versions, the velocity bins, the training points)."""
    path = Path(metadata_path)
    if not path.is_file():
        raise SurrogateLoadError(
            f"surrogate metadata {path} is missing: save_surrogate writes it beside the model file (copy both){RETRAIN}"
        )
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SurrogateLoadError(f"cannot read surrogate metadata {path}: {exc}") from exc
    where = f"surrogate metadata {path}"
    if not isinstance(meta, dict):
        raise SurrogateLoadError(f"{where}: a JSON object is required, found {type(meta).__name__} {meta!r:.60}")
    if meta.get("format") != FORMAT:
        raise SurrogateLoadError(f"{where}: key format = {meta.get('format')!r:.60}, expected {FORMAT!r}")
    if meta.get("format_version") != FORMAT_VERSION:
        raise IncompatibleVersionError(
            f"{where}: format version {meta.get('format_version')!r:.20} (this pbmdem reads version "
            f"{FORMAT_VERSION}){RETRAIN}"
        )
    _require(meta, "model_sha256", str, where)
    _require(meta, "training_point_ids", list, where)
    _require(_require(meta, "versions", dict, where), "sklearn", str, f"{where}, versions")
    for e in _require(meta, "velocity_edges", list, where):
        if not isinstance(e, (int, float)) or isinstance(e, bool):
            raise IncompatibleVersionError(f"{where}: key velocity_edges holds {e!r:.60}: numbers required{RETRAIN}")
    return meta


def load_surrogate(model_path: str | os.PathLike, metadata_path: str | os.PathLike | None = None) -> CollisionSurrogate:
    """Load a surrogate saved by :func:`save_surrogate`, after integrity, version and type checks."""
    model_path = Path(model_path)
    metadata_path = metadata_path_for(model_path) if metadata_path is None else Path(metadata_path)
    meta = read_metadata(metadata_path)
    try:
        digest = sha256_file(model_path)
    except OSError as exc:
        raise SurrogateLoadError(f"cannot read the surrogate model file {model_path}: {exc}") from exc
    if digest != meta["model_sha256"]:
        raise TamperedModelError(
            f"{model_path}: SHA-256 {digest} does not match {meta['model_sha256']} recorded in "
            f"{metadata_path}; the model file was modified, damaged or belongs to another training run"
        )
    saved, installed = meta["versions"]["sklearn"], sklearn.__version__
    if saved.split(".")[:2] != installed.split(".")[:2]:
        raise IncompatibleVersionError(
            f"{model_path} was written with scikit-learn {saved}, installed is {installed} "
            f"(major.minor must match){RETRAIN}"
        )
    edges = meta["velocity_edges"]
    if len(edges) != len(VELOCITY_EDGES) or not np.allclose(edges, VELOCITY_EDGES, rtol=1e-9):
        raise IncompatibleVersionError(
            f"{metadata_path}: velocity bins {edges} differ from this version's pbmdem.impact.VELOCITY_EDGES{RETRAIN}"
        )
    # every type in the file is allowed, so all are trusted (the loader need not audit it twice)
    trusted = refuse_unknown(schema_types(model_path), model_path)
    try:
        surrogate = sio.load(model_path, trusted=trusted)
    except UntrustedTypesFoundException as exc:  # a type skops sees that the schema does not name
        raise UntrustedTypesError(f"{model_path} contains types outside the allow-list, refused: {exc}") from None
    names = [str(n) for n in getattr(surrogate, "feature_names_in_", [])]
    if not isinstance(surrogate, CollisionSurrogate) or names != list(FEATURE_NAMES):
        raise IncompatibleVersionError(
            f"{model_path} holds a {type(surrogate).__name__} on the features {names}, expected a fitted "
            f"CollisionSurrogate on {list(FEATURE_NAMES)}{RETRAIN}"
        )
    return surrogate
