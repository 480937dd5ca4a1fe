"""Save and load a fitted :class:`CollisionSurrogate` without pickle execution risk.

Two files:

* ``model.skops`` - the fitted ensembles, ``{"frequency": [...], "velocity": [...]}`` (lists of
  ``Pipeline(StandardScaler, MLPRegressor)``; ``velocity`` is empty for a surrogate trained
  without impact-velocity bins) written with :func:`skops.io.dump`. Only scikit-learn/numpy
  objects are stored; the wrapper class itself is rebuilt from the metadata, so no project class has to be trusted.
* ``model.json`` - metadata: estimator parameters (the impeller radius among them), feature names
  and training ranges, training runs, CV scores, library versions and the SHA-256 of ``model.skops``.

:func:`load_surrogate` checks, before deserialising anything, that the metadata format is known
and the metadata fulfils its contract (:mod:`.metadata`), the SHA-256 matches (else
:class:`TamperedModelError`) and the scikit-learn major.minor equals the installed one (else
:class:`IncompatibleVersionError`). It then refuses any type outside :data:`ALLOWED_TYPES`
(:class:`UntrustedTypesError`), of those in the skops schema and of those skops itself does not
trust (``skops.io.get_untrusted_types``), and passes the latter as ``trusted``. The allow-list is
written out because skops' own is wider: since skops 0.10 it trusts every scikit-learn estimator
by default (a ``LinearRegression`` would load), and a surrogate file holds only a few of them.
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
from sklearn.base import clone

from pbmdem.impact import VELOCITY_EDGES

from ._io import atomic_write
from .ensemble import EnsembleMLPRegressorCV
from .families import KrigingRegressor, ResponseSurface
from .features import FEATURE_NAMES, TARGET_NAME
from .metadata import check_metadata
from .model import CollisionSurrogate

#: The model families a saved surrogate may use, by their name in the metadata (``surrogate.model``).
FAMILY_CLASSES = {"mlp": EnsembleMLPRegressorCV, "kriging": KrigingRegressor, "rsm": ResponseSurface}

FORMAT = "pbmdem-surrogate"
#: 4: the model family of each inner model ({"family", "params"}) and its fitted state
#: (``frequency_state``, ``velocity_state``); the skops file holds each model's fitted pipelines.
#: (3: MLP ensembles only; 2: the former single-class parameters; 1: raw collision target.)
FORMAT_VERSION = 4

#: Every type that may appear in a surrogate model file (module.qualname).
ALLOWED_TYPES = frozenset(
    {
        "builtins.dict",
        "builtins.list",
        "builtins.tuple",
        "builtins.str",
        "builtins.int",
        "builtins.float",
        "builtins.bool",
        "builtins.NoneType",
        "numpy.ndarray",
        "numpy.dtype",
        "numpy.float64",
        "numpy.float32",
        "numpy.int64",
        "numpy.int32",
        "numpy.bool_",
        "numpy.bool",
        "numpy.random.mtrand.RandomState",
        "numpy.random._mt19937.MT19937",
        "sklearn.pipeline.Pipeline",
        "sklearn.preprocessing._data.StandardScaler",
        "sklearn.neural_network._multilayer_perceptron.MLPRegressor",
        "sklearn.gaussian_process._gpr.GaussianProcessRegressor",
        "sklearn.gaussian_process.kernels.ConstantKernel",
        "sklearn.gaussian_process.kernels.Product",
        "sklearn.gaussian_process.kernels.Sum",
        "sklearn.gaussian_process.kernels.RBF",
        "sklearn.gaussian_process.kernels.DotProduct",
        "sklearn.gaussian_process.kernels.WhiteKernel",
        "sklearn.preprocessing._polynomial.PolynomialFeatures",
        "sklearn.linear_model._bayes.BayesianRidge",
    }
)


class SurrogateLoadError(RuntimeError):
    """A saved surrogate cannot be loaded safely."""


class TamperedModelError(SurrogateLoadError):
    """The model file does not match the SHA-256 recorded in its metadata."""


class IncompatibleVersionError(SurrogateLoadError):
    """The model was written by an incompatible library or format version."""


class UntrustedTypesError(SurrogateLoadError):
    """The model file contains types outside the allow-list."""


def sha256_file(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def library_versions() -> dict[str, str]:
    return {
        "python": platform.python_version(),
        "sklearn": sklearn.__version__,
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "skops": skops.__version__,
        "pandas": pd.__version__,
    }


def _major_minor(version: str) -> tuple[str, ...]:
    return tuple(str(version).split(".")[:2])


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


def _surrogate_params(surrogate: CollisionSurrogate) -> dict:
    """JSON form of the surrogate's parameters: each inner model as its family and parameters."""
    params = surrogate.get_params(deep=False)
    for key in ("frequency_model", "velocity_model"):
        if params[key] is not None:
            params[key] = {"family": family_name(params[key]), "params": params[key].get_params(deep=False)}
    return params


def _fitted_parts(surrogate: CollisionSurrogate) -> dict:
    """What the skops file holds of one fitted surrogate: its inner models' fitted pipelines."""
    vel = surrogate.velocity_model_
    return {
        "frequency": surrogate.frequency_model_.fitted_parts(),
        "velocity": [] if vel is None else vel.fitted_parts(),
    }


def _model_metadata(surrogate: CollisionSurrogate) -> dict:
    """The metadata that rebuilds one fitted surrogate around its stored parts (_from_metadata)."""
    freq, vel = surrogate.frequency_model_, surrogate.velocity_model_
    return {
        "params": _surrogate_params(surrogate),
        "family": family_name(freq),
        "frequency_state": freq.fitted_state(),
        "velocity_state": None if vel is None else vel.fitted_state(),
        "n_velocity_rows": surrogate.n_velocity_rows_,
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
    """Write ``model.skops`` and its JSON metadata (atomically); return the metadata dict."""
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
    walls = getattr(surrogate, "wall_models_", None) or {}
    parts = {"walls": {wall: _fitted_parts(model) for wall, model in walls.items()}, **_fitted_parts(surrogate)}
    atomic_write(model_path, lambda tmp: sio.dump(parts, tmp))
    vel = surrogate.velocity_model_
    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "created_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "model_file": model_path.name,
        "model_sha256": sha256_file(model_path),
        "estimator": "pbmdem.surrogate.CollisionSurrogate",
        "target": f"{TARGET_NAME} (fitted in log10 space; frequency_matrix returns 1/s per particle pair)",
        "velocity_target": (
            "log-normal impact-speed law per pair: [log10 median speed (m/s) minus the "
            "physics offset, log10 sigma (decades)], fitted by ML to the bins of "
            "pbmdem.impact.VELOCITY_EDGES"
            if vel is not None
            else None
        ),
        "velocity_edges": [float(e) for e in VELOCITY_EDGES],
        **_model_metadata(surrogate),
        # per wall: the same fields of its CollisionSurrogate (pbmdem.surrogate.walls)
        "walls": {wall: _model_metadata(model) for wall, model in walls.items()},
        "cv_scores": cv_scores or {},
        "versions": library_versions(),
    }
    if extra:
        meta.update(extra)
    meta = _jsonable(meta)
    text = json.dumps(meta, indent=2, sort_keys=False) + "\n"
    atomic_write(metadata_path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
    return meta


def schema_types(model_path: str | os.PathLike) -> set[str]:
    """All ``module.class`` names referenced by the schema of a skops file (nothing is loaded)."""
    try:
        with zipfile.ZipFile(model_path) as zf:
            schema = json.loads(zf.read("schema.json"))
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError) as exc:
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


def read_metadata(metadata_path: str | os.PathLike) -> dict:
    try:
        meta = json.loads(Path(metadata_path).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise SurrogateLoadError(f"cannot read surrogate metadata {metadata_path}: {exc}") from exc
    meta = check_metadata(meta, metadata_path, FORMAT, FORMAT_VERSION, IncompatibleVersionError)  # metadata.py
    if meta.get("format") != FORMAT:
        raise SurrogateLoadError(f"{metadata_path} is not {FORMAT} metadata")
    if meta.get("format_version") != FORMAT_VERSION:
        raise IncompatibleVersionError(
            f"{metadata_path}: metadata format version {meta.get('format_version')} "
            f"(this pbmdem reads version {FORMAT_VERSION}); retrain the surrogate"
        )
    return meta


def load_surrogate(model_path: str | os.PathLike, metadata_path: str | os.PathLike | None = None) -> CollisionSurrogate:
    """Load a surrogate saved by :func:`save_surrogate`, after integrity, version and type checks."""
    model_path = Path(model_path)
    metadata_path = metadata_path_for(model_path) if metadata_path is None else Path(metadata_path)
    meta = read_metadata(metadata_path)

    # read_metadata checked the contract: the keys below are there, with values of their type
    digest = sha256_file(model_path)
    if digest != meta["model_sha256"]:
        raise TamperedModelError(
            f"{model_path}: SHA-256 {digest} does not match {meta['model_sha256']} recorded in "
            f"{metadata_path}; the model file was modified or belongs to another training run"
        )

    saved = meta["versions"]["sklearn"]
    if _major_minor(saved) != _major_minor(sklearn.__version__):
        raise IncompatibleVersionError(
            f"{model_path} was written with scikit-learn {saved}, installed is {sklearn.__version__} "
            f"(major.minor must match); retrain the surrogate with the installed version"
        )

    types = schema_types(model_path)
    untrusted = sio.get_untrusted_types(file=model_path) if types <= ALLOWED_TYPES else []
    bad = sorted((types | set(untrusted)) - ALLOWED_TYPES)
    if bad:
        raise UntrustedTypesError(f"{model_path} contains types outside the allow-list: {bad}")
    stored = sio.load(model_path, trusted=list(untrusted))
    if (
        not isinstance(stored, dict)
        or not isinstance(stored.get("frequency"), list)
        or not stored["frequency"]
        or not isinstance(stored.get("velocity"), list)
    ):
        raise SurrogateLoadError(f"{model_path} does not hold the fitted frequency and velocity pipelines")
    edges = meta["velocity_edges"]
    if len(edges) != len(VELOCITY_EDGES) or not np.allclose(edges, VELOCITY_EDGES, rtol=1e-9):
        raise IncompatibleVersionError(
            f"{metadata_path}: velocity bins {edges} differ from this version's pbmdem.impact.VELOCITY_EDGES; "
            f"retrain the surrogate"
        )

    try:
        surrogate = _from_metadata(stored, meta, metadata_path)
        surrogate.wall_models_ = {
            wall: _from_metadata(stored["walls"][wall], wall_meta, metadata_path)
            for wall, wall_meta in meta.get("walls", {}).items()
        }
        return surrogate
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        what = f"missing field {exc}" if isinstance(exc, KeyError) else str(exc)
        raise IncompatibleVersionError(
            f"{metadata_path}: metadata does not fit this pbmdem version ({type(exc).__name__}: {what}); "
            "it was written by another version or edited; retrain the surrogate"
        ) from None


def _build(cls, params: dict, what: str):
    """``cls(**params)`` with exactly the parameters ``cls`` has (a missing one would silently
    take its default: refused like an unknown one)."""
    expected = set(cls().get_params(deep=False))
    if set(params) != expected:
        raise ValueError(
            f"{what} parameters differ from this version's: missing {sorted(expected - set(params))}, "
            f"unknown {sorted(set(params) - expected)}"
        )
    return cls(**params)


def _inner_model(spec: dict, what: str):
    """An unfitted inner model from its metadata ``{"family": name, "params": {...}}``."""
    family = spec["family"]
    if family not in FAMILY_CLASSES:
        raise ValueError(f"{what}.family = {family!r}; allowed: {sorted(FAMILY_CLASSES)}")
    params = dict(spec["params"])
    if family == "mlp":
        params["hidden_layer_sizes"] = tuple(tuple(h) for h in params["hidden_layer_sizes"])
        params["alpha"] = tuple(params["alpha"])
        params["seeds"] = tuple(params["seeds"])
    return _build(FAMILY_CLASSES[family], params, what)


def _from_metadata(stored: dict, meta: dict, metadata_path) -> CollisionSurrogate:
    """The surrogate object from its fitted estimators (`stored`: the skops file's frequency and
    velocity lists) and metadata (KeyError/TypeError/ValueError when the metadata has missing or
    unknown fields)."""
    names = list(meta["feature_names"])
    if names != list(FEATURE_NAMES):
        raise IncompatibleVersionError(
            f"{metadata_path}: features {meta['feature_names']} differ from this version's {list(FEATURE_NAMES)}"
        )
    params = dict(meta["params"])
    # a surrogate saved before the speed law was a setting learned the log-normal law
    params.setdefault("speed_law", "lognormal")
    params["frequency_model"] = _inner_model(params["frequency_model"], "params.frequency_model")
    if params["velocity_model"] is not None:
        params["velocity_model"] = _inner_model(params["velocity_model"], "params.velocity_model")
    surrogate = _build(CollisionSurrogate, params, "surrogate")
    freq_template = surrogate.frequency_model
    vel_template = freq_template if surrogate.velocity_model is None else surrogate.velocity_model
    surrogate.frequency_model_ = clone(freq_template).restore(stored["frequency"], meta["frequency_state"], names)
    surrogate.velocity_model_ = None
    if stored["velocity"]:
        surrogate.velocity_model_ = clone(vel_template).restore(stored["velocity"], meta["velocity_state"], names)
    ranges = meta["feature_ranges"]
    surrogate.n_features_in_ = len(names)
    surrogate.feature_names_in_ = np.asarray(names, dtype=object)
    surrogate.feature_min_ = np.array([ranges[n][0] for n in names], dtype=float)
    surrogate.feature_max_ = np.array([ranges[n][1] for n in names], dtype=float)
    surrogate.duplicated_features_ = [tuple(p) for p in meta["duplicated_features"]]
    surrogate.training_point_ids_ = list(meta["training_point_ids"])
    surrogate.n_training_rows_ = int(meta["n_training_rows"])
    surrogate.n_velocity_rows_ = int(meta["n_velocity_rows"])
    surrogate.metadata_ = meta
    return surrogate
