"""Save and load a fitted :class:`CollisionSurrogate` without pickle execution risk.

Two files:

* ``model.skops`` - the fitted ensembles, ``{"frequency": [...], "velocity": [...]}`` (lists of
  ``Pipeline(StandardScaler, MLPRegressor)``; ``velocity`` is empty for a surrogate trained
  without impact-velocity bins) written with :func:`skops.io.dump`. Only scikit-learn/numpy objects are stored; the wrapper
  class itself is rebuilt from the metadata, so no project class has to be trusted.
* ``model.json`` - metadata: estimator parameters, feature names and training ranges, training
  runs, CV scores, library versions and the SHA-256 of ``model.skops``.

:func:`load_surrogate` checks, before deserialising anything, that the metadata format is known,
the SHA-256 matches (else :class:`TamperedModelError`) and the scikit-learn major.minor equals the
installed one (else :class:`IncompatibleVersionError`). It then lists every type in the skops
schema and refuses any type outside :data:`ALLOWED_TYPES` (:class:`UntrustedTypesError`); only
the allow-listed types that skops itself does not trust by default (``skops.io.get_untrusted_types``)
are passed as ``trusted``.
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
import skops
import skops.io as sio
import sklearn

from pbmdem.impact import VELOCITY_EDGES

from ._io import atomic_write
from .features import FEATURE_NAMES, TARGET_NAME
from .model import CollisionSurrogate

FORMAT = "pbmdem-surrogate"
#: 2: encounter target, velocity ensemble, features without rpm (version 1: raw collision target).
FORMAT_VERSION = 2

#: Every type that may appear in a surrogate model file (module.qualname).
ALLOWED_TYPES = frozenset({
    "builtins.dict", "builtins.list", "builtins.tuple", "builtins.str", "builtins.int",
    "builtins.float", "builtins.bool", "builtins.NoneType",
    "numpy.ndarray", "numpy.dtype", "numpy.float64", "numpy.float32", "numpy.int64", "numpy.int32",
    "numpy.bool_", "numpy.bool",
    "numpy.random.mtrand.RandomState", "numpy.random._mt19937.MT19937",
    "sklearn.pipeline.Pipeline",
    "sklearn.preprocessing._data.StandardScaler",
    "sklearn.neural_network._multilayer_perceptron.MLPRegressor",
})


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
    return {"python": platform.python_version(), "sklearn": sklearn.__version__, "numpy": np.__version__,
            "scipy": scipy.__version__, "skops": skops.__version__, "pandas": pd.__version__}


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


def save_surrogate(surrogate: CollisionSurrogate, model_path: str | os.PathLike,
                   metadata_path: str | os.PathLike | None = None, cv_scores: dict | None = None,
                   extra: dict | None = None) -> dict:
    """Write ``model.skops`` and its JSON metadata (atomically); return the metadata dict."""
    if not hasattr(surrogate, "estimators_"):
        raise ValueError("only a fitted CollisionSurrogate can be saved")
    model_path = Path(model_path)
    metadata_path = metadata_path_for(model_path) if metadata_path is None else Path(metadata_path)
    velocity = list(getattr(surrogate, "velocity_estimators_", None) or [])
    atomic_write(model_path, lambda tmp: sio.dump({"frequency": list(surrogate.estimators_), "velocity": velocity},
                                                  tmp))
    params = surrogate.get_params()
    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "model_file": model_path.name,
        "model_sha256": sha256_file(model_path),
        "estimator": "pbmdem.surrogate.CollisionSurrogate",
        "params": params,
        "target": f"{TARGET_NAME} (fitted in log10 space; predict returns 1/s per particle pair)",
        "velocity_target": ("log-normal impact-speed law per pair: [log10 median speed (m/s) minus the "
                            "physics offset, log10 sigma (decades)], fitted by ML to the bins of "
                            "pbmdem.impact.VELOCITY_EDGES" if velocity else None),
        "velocity_edges": [float(e) for e in VELOCITY_EDGES],
        "velocity_best_params": getattr(surrogate, "velocity_best_params_", None),
        "velocity_search": {"best_rmse_log10": getattr(surrogate, "velocity_best_score_", None),
                            "results": (surrogate.velocity_search_results_.to_dict(orient="records")
                                        if getattr(surrogate, "velocity_search_results_", None) is not None else [])},
        "n_velocity_rows": getattr(surrogate, "n_velocity_rows_", 0),
        "duplicated_features": [list(p) for p in getattr(surrogate, "duplicated_features_", [])],
        "feature_names": list(surrogate.feature_names_),
        "feature_ranges": {k: list(v) for k, v in surrogate.feature_ranges().items()},
        "best_params": surrogate.best_params_,
        "seeds": surrogate.seeds_,
        "training_point_ids": list(surrogate.training_point_ids_),
        "n_training_rows": surrogate.n_training_rows_,
        "n_dropped_rows": surrogate.n_dropped_rows_,
        "n_floored_rows": surrogate.n_floored_rows_,
        "search_cv_folds": surrogate.cv_folds_,
        "search": {"best_rmse_log10": surrogate.best_score_,
                   "results": surrogate.search_results_.to_dict(orient="records")},
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
    if meta.get("format") != FORMAT:
        raise SurrogateLoadError(f"{metadata_path} is not {FORMAT} metadata")
    if meta.get("format_version") != FORMAT_VERSION:
        raise IncompatibleVersionError(
            f"{metadata_path}: metadata format version {meta.get('format_version')} "
            f"(this pbmdem reads version {FORMAT_VERSION}); retrain the surrogate")
    return meta


def load_surrogate(model_path: str | os.PathLike, metadata_path: str | os.PathLike | None = None) -> CollisionSurrogate:
    """Load a surrogate saved by :func:`save_surrogate`, after integrity, version and type checks."""
    model_path = Path(model_path)
    metadata_path = metadata_path_for(model_path) if metadata_path is None else Path(metadata_path)
    meta = read_metadata(metadata_path)

    digest = sha256_file(model_path)
    if digest != meta.get("model_sha256"):
        raise TamperedModelError(
            f"{model_path}: SHA-256 {digest} does not match {meta.get('model_sha256')} recorded in "
            f"{metadata_path}; the model file was modified or belongs to another training run")

    saved = meta.get("versions", {}).get("sklearn", "?")
    if _major_minor(saved) != _major_minor(sklearn.__version__):
        raise IncompatibleVersionError(
            f"{model_path} was written with scikit-learn {saved}, installed is {sklearn.__version__} "
            f"(major.minor must match); retrain the surrogate with the installed version")

    types = schema_types(model_path)
    bad = sorted(types - ALLOWED_TYPES)
    if bad:
        raise UntrustedTypesError(f"{model_path} contains types outside the allow-list: {bad}")
    untrusted = sio.get_untrusted_types(file=model_path)
    bad = sorted(set(untrusted) - ALLOWED_TYPES)
    if bad:
        raise UntrustedTypesError(f"{model_path} contains types outside the allow-list: {bad}")
    stored = sio.load(model_path, trusted=list(untrusted))
    if (not isinstance(stored, dict) or not isinstance(stored.get("frequency"), list) or not stored["frequency"]
            or not isinstance(stored.get("velocity"), list)):
        raise SurrogateLoadError(f"{model_path} does not hold the fitted frequency and velocity pipelines")
    edges = meta.get("velocity_edges")
    if edges is None or len(edges) != len(VELOCITY_EDGES) or not np.allclose(edges, VELOCITY_EDGES, rtol=1e-9):
        raise IncompatibleVersionError(
            f"{metadata_path}: velocity bins {edges} differ from this version's pbmdem.impact.VELOCITY_EDGES; "
            f"retrain the surrogate")

    try:
        return _from_metadata(stored, meta, metadata_path)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        what = f"missing field {exc}" if isinstance(exc, KeyError) else str(exc)
        raise IncompatibleVersionError(
            f"{metadata_path}: metadata does not fit this pbmdem version ({type(exc).__name__}: {what}); "
            "it was written by another version or edited; retrain the surrogate") from None


def _from_metadata(stored: dict, meta: dict, metadata_path) -> CollisionSurrogate:
    """The surrogate object from its fitted estimators (`stored`: the skops file's frequency and
    velocity lists) and metadata (KeyError/TypeError when the metadata has missing or unknown
    fields)."""
    estimators = stored["frequency"]
    if list(meta["feature_names"]) != list(FEATURE_NAMES):
        raise IncompatibleVersionError(
            f"{metadata_path}: features {meta['feature_names']} differ from this version's {list(FEATURE_NAMES)}")
    params = dict(meta["params"])
    params["hidden_layer_sizes"] = tuple(tuple(h) for h in params["hidden_layer_sizes"])
    params["alpha"] = tuple(params["alpha"])
    if params.get("seeds") is not None:
        params["seeds"] = tuple(params["seeds"])
    surrogate = CollisionSurrogate(**params)
    ranges = meta["feature_ranges"]
    surrogate.estimators_ = estimators
    surrogate.seeds_ = list(meta["seeds"])
    surrogate.feature_names_ = tuple(meta["feature_names"])
    surrogate.n_features_in_ = len(surrogate.feature_names_)
    surrogate.feature_min_ = np.array([ranges[n][0] for n in surrogate.feature_names_], dtype=float)
    surrogate.feature_max_ = np.array([ranges[n][1] for n in surrogate.feature_names_], dtype=float)
    surrogate.best_params_ = {"hidden_layer_sizes": tuple(meta["best_params"]["hidden_layer_sizes"]),
                              "alpha": float(meta["best_params"]["alpha"])}
    surrogate.best_score_ = meta["search"]["best_rmse_log10"]
    surrogate.search_results_ = pd.DataFrame(meta["search"]["results"])
    surrogate.training_point_ids_ = list(meta["training_point_ids"])
    surrogate.cv_folds_ = meta["search_cv_folds"]
    surrogate.n_training_rows_ = meta["n_training_rows"]
    surrogate.n_dropped_rows_ = meta["n_dropped_rows"]
    surrogate.n_floored_rows_ = meta["n_floored_rows"]
    surrogate.velocity_estimators_ = stored["velocity"]
    vbest = meta.get("velocity_best_params")
    surrogate.velocity_best_params_ = (None if vbest is None else
                                       {"hidden_layer_sizes": tuple(vbest["hidden_layer_sizes"]),
                                        "alpha": float(vbest["alpha"])})
    surrogate.velocity_best_score_ = meta["velocity_search"]["best_rmse_log10"]
    vres = meta["velocity_search"]["results"]
    surrogate.velocity_search_results_ = pd.DataFrame(vres) if vres else None
    surrogate.n_velocity_rows_ = meta["n_velocity_rows"]
    surrogate.duplicated_features_ = [tuple(p) for p in meta.get("duplicated_features", [])]
    surrogate.metadata_ = meta
    return surrogate
