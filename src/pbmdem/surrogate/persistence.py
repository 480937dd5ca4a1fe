"""Save and load a fitted :class:`CollisionSurrogate` without pickle execution risk.

Two files:

* ``model.skops`` - the fitted ensembles, ``{"frequency": [...], "velocity": [...]}`` (lists of
  ``Pipeline(StandardScaler, MLPRegressor)``; ``velocity`` is empty for a surrogate trained
  without impact-velocity bins) written with :func:`skops.io.dump`. Only scikit-learn/numpy
  objects are stored; the wrapper class itself is rebuilt from the metadata, so no project class has to be trusted.
* ``model.json`` - metadata: estimator parameters (the impeller radius among them), feature names
  and training ranges, training runs, CV scores, library versions and the SHA-256 of ``model.skops``.

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
import sklearn
import skops
import skops.io as sio
from sklearn.base import clone

from pbmdem.impact import VELOCITY_EDGES

from ._io import atomic_write
from .ensemble import EnsembleMLPRegressorCV, _object_array, search_table
from .features import FEATURE_NAMES, TARGET_NAME
from .metadata import check_metadata
from .model import CollisionSurrogate

FORMAT = "pbmdem-surrogate"
#: 3: parameters of CollisionSurrogate(frequency_model=EnsembleMLPRegressorCV, velocity_model=...)
#: (2: the former single-class parameters; 1: raw collision target). The skops layout is unchanged.
FORMAT_VERSION = 3

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


def _surrogate_params(surrogate: CollisionSurrogate) -> dict:
    """JSON form of the surrogate's parameters: the nested estimators as their own parameter dicts."""
    params = surrogate.get_params(deep=False)
    for key in ("frequency_model", "velocity_model"):
        if params[key] is not None:
            params[key] = params[key].get_params(deep=False)
    return params


def _search_meta(est: EnsembleMLPRegressorCV | None) -> dict:
    if est is None:
        return {"best_rmse_log10": None, "results": []}
    return {"best_rmse_log10": float(np.sqrt(-est.best_score_)), "results": search_table(est).to_dict(orient="records")}


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
    freq, vel = surrogate.frequency_model_, surrogate.velocity_model_
    velocity = [] if vel is None else list(vel.estimators_)
    atomic_write(model_path, lambda tmp: sio.dump({"frequency": list(freq.estimators_), "velocity": velocity}, tmp))
    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "created_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "model_file": model_path.name,
        "model_sha256": sha256_file(model_path),
        "estimator": "pbmdem.surrogate.CollisionSurrogate",
        "params": _surrogate_params(surrogate),
        "target": f"{TARGET_NAME} (fitted in log10 space; frequency_matrix returns 1/s per particle pair)",
        "velocity_target": (
            "log-normal impact-speed law per pair: [log10 median speed (m/s) minus the "
            "physics offset, log10 sigma (decades)], fitted by ML to the bins of "
            "pbmdem.impact.VELOCITY_EDGES"
            if vel is not None
            else None
        ),
        "velocity_edges": [float(e) for e in VELOCITY_EDGES],
        "velocity_best_params": None if vel is None else vel.best_params_,
        "velocity_seeds": None if vel is None else [int(s) for s in np.atleast_1d(vel.seeds)],
        "velocity_search": _search_meta(vel),
        "velocity_search_cv_folds": [] if vel is None else vel.cv_folds_,
        "n_velocity_rows": surrogate.n_velocity_rows_,
        "duplicated_features": [list(p) for p in surrogate.duplicated_features_],
        "feature_names": names,
        "feature_ranges": {k: list(v) for k, v in surrogate.feature_ranges().items()},
        "best_params": freq.best_params_,
        "seeds": [int(s) for s in np.atleast_1d(freq.seeds)],
        "training_point_ids": list(surrogate.training_point_ids_),
        "n_training_rows": surrogate.n_training_rows_,
        "search_cv_folds": freq.cv_folds_,
        "search": _search_meta(freq),
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

    digest = sha256_file(model_path)
    if digest != meta.get("model_sha256"):
        raise TamperedModelError(
            f"{model_path}: SHA-256 {digest} does not match {meta.get('model_sha256')} recorded in "
            f"{metadata_path}; the model file was modified or belongs to another training run"
        )

    saved = meta.get("versions", {}).get("sklearn", "?")
    if _major_minor(saved) != _major_minor(sklearn.__version__):
        raise IncompatibleVersionError(
            f"{model_path} was written with scikit-learn {saved}, installed is {sklearn.__version__} "
            f"(major.minor must match); retrain the surrogate with the installed version"
        )

    types = schema_types(model_path)
    bad = sorted(types - ALLOWED_TYPES)
    if bad:
        raise UntrustedTypesError(f"{model_path} contains types outside the allow-list: {bad}")
    untrusted = sio.get_untrusted_types(file=model_path)
    bad = sorted(set(untrusted) - ALLOWED_TYPES)
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
    edges = meta.get("velocity_edges")
    if edges is None or len(edges) != len(VELOCITY_EDGES) or not np.allclose(edges, VELOCITY_EDGES, rtol=1e-9):
        raise IncompatibleVersionError(
            f"{metadata_path}: velocity bins {edges} differ from this version's pbmdem.impact.VELOCITY_EDGES; "
            f"retrain the surrogate"
        )

    try:
        return _from_metadata(stored, meta, metadata_path)
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


def _ensemble(params: dict, what: str) -> EnsembleMLPRegressorCV:
    params = dict(params)
    params["hidden_layer_sizes"] = tuple(tuple(h) for h in params["hidden_layer_sizes"])
    params["alpha"] = tuple(params["alpha"])
    params["seeds"] = tuple(params["seeds"])
    return _build(EnsembleMLPRegressorCV, params, what)


def _restore_ensemble(
    est: EnsembleMLPRegressorCV, members: list, best: dict, search: dict, folds: list, names: list[str], n_outputs: int
) -> EnsembleMLPRegressorCV:
    """The fitted state of an :class:`EnsembleMLPRegressorCV` from its pipelines and metadata."""
    est.estimators_ = members
    est.best_params_ = {"hidden_layer_sizes": tuple(best["hidden_layer_sizes"]), "alpha": float(best["alpha"])}
    rmse = search["best_rmse_log10"]
    est.best_score_ = float("nan") if rmse is None else -(float(rmse) ** 2)
    rows = [r for r in search["results"] if r.get("rmse_log10") is not None]
    est.cv_results_ = None
    if rows:
        params = [
            {"hidden_layer_sizes": tuple(int(u) for u in r["hidden_layer_sizes"]), "alpha": float(r["alpha"])}
            for r in rows
        ]
        est.cv_results_ = {
            "params": params,
            "param_hidden_layer_sizes": _object_array([p["hidden_layer_sizes"] for p in params]),
            "param_alpha": np.array([p["alpha"] for p in params], dtype=float),
            "mean_test_score": -(np.array([r["rmse_log10"] for r in rows], dtype=float) ** 2),
            "std_test_score": np.array(
                [np.nan if r["fold_mse_log10_std"] is None else r["fold_mse_log10_std"] for r in rows], dtype=float
            ),
            "rank_test_score": np.array([r["rank"] for r in rows], dtype=int),
        }
    est.cv_folds_ = [list(f) for f in folds]
    est.n_features_in_ = len(names)
    est.feature_names_in_ = np.asarray(names, dtype=object)
    est.n_outputs_ = n_outputs
    est.n_iter_ = np.array([m[-1].n_iter_ for m in members], dtype=int)
    return est


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
    params["frequency_model"] = _ensemble(params["frequency_model"], "frequency_model")
    if params["velocity_model"] is not None:
        params["velocity_model"] = _ensemble(params["velocity_model"], "velocity_model")
    surrogate = _build(CollisionSurrogate, params, "surrogate")
    freq_template = surrogate.frequency_model
    vel_template = freq_template if surrogate.velocity_model is None else surrogate.velocity_model
    surrogate.frequency_model_ = _restore_ensemble(
        clone(freq_template),
        stored["frequency"],
        meta["best_params"],
        meta["search"],
        meta["search_cv_folds"],
        names,
        1,
    )
    surrogate.velocity_model_ = None
    if stored["velocity"]:
        surrogate.velocity_model_ = _restore_ensemble(
            clone(vel_template),
            stored["velocity"],
            meta["velocity_best_params"],
            meta["velocity_search"],
            meta["velocity_search_cv_folds"],
            names,
            2,
        )
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
