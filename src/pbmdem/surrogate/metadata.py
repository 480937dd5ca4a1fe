"""The contract of a surrogate's metadata file (``model.json``), checked when it is loaded.

`check_metadata` validates the parsed file against `SCHEMA` (a declared JSON schema: types,
required keys, signs and bounds) and then what a JSON schema cannot express: every number finite
(Python's JSON reader accepts NaN and Infinity), one training range per feature name, each range
finite with lower <= upper. Every violation is a `MetadataError` naming the file, the key and the
value. Nothing in the file can switch off the domain check: the ranges are required and finite,
and `params.domain_margin` (the slack around them) is bounded as in the config schema.

Only the format and its version are left to the loader (`persistence.read_metadata`), which
reports them with its own errors (a file of another format or version is not checked here).
"""

from __future__ import annotations

import math
import os

from jsonschema import Draft202012Validator

from pbmdem.config.errors import key_path

from .velocity import SPEED_LAWS

#: the largest relative slack around a feature's training range (surrogate.domain_margin)
MAX_DOMAIN_MARGIN = 1.0

_NUMBER = {"type": "number"}
_FOLDS = {"type": "array", "items": {"type": "array"}}
_MLP = {
    "type": "object",
    "required": ["hidden_layer_sizes", "alpha", "seeds"],
    "properties": {
        "hidden_layer_sizes": {
            "type": "array",
            "minItems": 1,
            "items": {"type": "array", "minItems": 1, "items": {"type": "integer", "minimum": 1}},
        },
        "alpha": {"type": "array", "minItems": 1, "items": {"type": "number", "minimum": 0}},
        "seeds": {"type": "array", "minItems": 1, "items": {"type": "integer"}},
    },
}
_KRIGING = {
    "type": "object",
    "required": ["n_restarts_optimizer", "linear_trend", "random_state", "n_members"],
    "properties": {
        "n_restarts_optimizer": {"type": "integer", "minimum": 0},
        "linear_trend": {"type": "boolean"},
        "random_state": {"type": "integer"},
        "n_members": {"type": "integer", "minimum": 1},
    },
}
_RSM = {
    "type": "object",
    "required": ["degree", "n_members"],
    "properties": {
        "degree": {"type": "array", "minItems": 1, "items": {"type": "integer", "minimum": 1, "maximum": 4}},
        "n_members": {"type": "integer", "minimum": 1},
    },
}
#: An inner model of the surrogate: its family and that family's parameters.
_INNER = {
    "type": "object",
    "required": ["family", "params"],
    "oneOf": [
        {"properties": {"family": {"const": "mlp"}, "params": _MLP}},
        {"properties": {"family": {"const": "kriging"}, "params": _KRIGING}},
        {"properties": {"family": {"const": "rsm"}, "params": _RSM}},
    ],
}
#: The fitted state of an inner model besides its pipelines (per family; the loader reads it).
_STATE = {
    "type": "object",
    "required": ["n_outputs"],
    "properties": {
        "n_outputs": {"type": "integer", "minimum": 1},
        "best_params": {
            "type": "object",
            "required": ["hidden_layer_sizes", "alpha"],
            "properties": {
                "hidden_layer_sizes": {"type": "array", "minItems": 1, "items": {"type": "integer", "minimum": 1}},
                "alpha": {"type": "number", "minimum": 0},
            },
        },
        "search": {
            "type": "object",
            "required": ["best_rmse_log10", "results"],
            "properties": {
                "best_rmse_log10": {"type": ["number", "null"], "minimum": 0},
                "results": {"type": "array", "items": {"type": "object"}},
            },
        },
        "search_cv_folds": _FOLDS,
        "cv_mse": {"type": "array", "items": {"type": "object", "additionalProperties": _NUMBER}},
    },
}
_SCALE = {"type": "number", "exclusiveMinimum": 0}

#: The fields of one fitted model (the pair model's, or a wall model's under ``walls``).
_MODEL_KEYS = (
    "params",
    "family",
    "frequency_state",
    "velocity_state",
    "n_velocity_rows",
    "duplicated_features",
    "feature_names",
    "feature_ranges",
    "training_point_ids",
    "n_training_rows",
)
SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "pbmdem surrogate metadata (model.json)",
    "type": "object",
    "required": ["format", "format_version", "model_sha256", "velocity_edges", *_MODEL_KEYS, "versions"],
    "properties": {
        "format": {"type": "string"},
        "format_version": {"type": "integer"},
        "model_sha256": {"type": "string", "pattern": "^[0-9a-f]{64}$"},
        "params": {
            "type": "object",
            "required": [
                "frequency_model",
                "velocity_model",
                "impeller_radius",
                "physics_offset",
                "domain_margin",
                "feature_transform",
                "uncertainty_scale",
                "velocity_uncertainty_scale",
            ],
            "properties": {
                "frequency_model": _INNER,
                "velocity_model": {"oneOf": [_INNER, {"type": "null"}]},
                "impeller_radius": {"type": "number", "exclusiveMinimum": 0, "maximum": 10},
                "physics_offset": {"enum": ["cross_section", "none"]},
                "domain_margin": {"type": "number", "minimum": 0, "maximum": MAX_DOMAIN_MARGIN},
                "feature_transform": {"enum": ["log", "none"]},
                "speed_law": {"enum": list(SPEED_LAWS)},
                "uncertainty_scale": _SCALE,
                "velocity_uncertainty_scale": _SCALE,
            },
        },
        "velocity_edges": {"type": "array", "minItems": 2, "items": _NUMBER},
        "family": {"enum": ["mlp", "kriging", "rsm"]},
        "frequency_state": _STATE,
        "velocity_state": {"oneOf": [_STATE, {"type": "null"}]},
        "n_velocity_rows": {"type": "integer", "minimum": 0},
        "duplicated_features": {
            "type": "array",
            # (feature, feature, Pearson r) as CollisionSurrogate.duplicated_features_ holds them
            "items": {
                "type": "array",
                "minItems": 2,
                "maxItems": 3,
                "prefixItems": [{"type": "string"}, {"type": "string"}, _NUMBER],
            },
        },
        "feature_names": {"type": "array", "minItems": 1, "uniqueItems": True, "items": {"type": "string"}},
        "feature_ranges": {
            "type": "object",
            "additionalProperties": {"type": "array", "minItems": 2, "maxItems": 2, "items": _NUMBER},
        },
        "training_point_ids": {"type": "array", "minItems": 1, "items": {"type": "string"}},
        "n_training_rows": {"type": "integer", "minimum": 1},
        "versions": {
            "type": "object",
            "required": ["sklearn"],
            "additionalProperties": {"type": "string"},
        },
    },
}

#: ``walls``: per wall (pbmdem.impact.WALLS) the wall model of pbmdem.surrogate.walls (optional:
#: a surrogate trained without the wall tables has none).
SCHEMA["properties"]["walls"] = {
    "type": "object",
    "propertyNames": {"enum": ["bowl", "impeller"]},
    "additionalProperties": {
        "type": "object",
        "required": list(_MODEL_KEYS),
        "properties": {k: SCHEMA["properties"][k] for k in _MODEL_KEYS},
    },
}

_VALIDATOR = Draft202012Validator(SCHEMA)


RETRAIN = " (the file was edited, damaged or written by another pbmdem version; retrain the surrogate)"


class MetadataError(ValueError):
    """A surrogate's metadata file violates its contract; the message names the file and the key."""


def _key(path) -> str:
    return key_path(path, "(the whole file)")


def _non_finite(obj, path=()):
    if isinstance(obj, float) and not math.isfinite(obj):
        yield path, obj
    elif isinstance(obj, dict):
        for k, v in obj.items():
            yield from _non_finite(v, (*path, k))
    elif isinstance(obj, list):
        for k, v in enumerate(obj):
            yield from _non_finite(v, (*path, k))


def check_metadata(meta, path: str | os.PathLike, fmt: str, version: int, error: type = MetadataError) -> dict:
    """`meta` (the parsed ``model.json`` at `path`) if it fulfils the contract, else `error` (the
    loader passes its IncompatibleVersionError) naming the file, the key, the value and what is
    allowed. Metadata of another format than `fmt` or another format version than `version` is
    returned unchecked, for the loader to refuse with its own message."""
    try:
        return _check(meta, path, fmt, version)
    except MetadataError as exc:
        if error is MetadataError:
            raise
        raise error(str(exc)) from None


def _check(meta, path, fmt: str, version: int) -> dict:
    where = f"surrogate metadata {path}"
    if not isinstance(meta, dict):
        raise MetadataError(f"{where}: a JSON object is required, found {type(meta).__name__} {meta!r:.60}")
    if meta.get("format") != fmt or meta.get("format_version") != version:
        return meta
    for key, value in _non_finite(meta):
        raise MetadataError(f"{where}: key {_key(key)} = {value!r}: every number must be finite{RETRAIN}")
    errors = sorted(_VALIDATOR.iter_errors(meta), key=lambda e: list(map(str, e.absolute_path)))
    if errors:
        lines = [f"key {_key(e.absolute_path)} = {e.instance!r:.80}: {e.message:.200}" for e in errors[:10]]
        more = f" (and {len(errors) - 10} more)" if len(errors) > 10 else ""
        raise MetadataError(f"{where}: " + "; ".join(lines) + more + RETRAIN)
    ranges = meta["feature_ranges"]
    missing = [n for n in meta["feature_names"] if n not in ranges]
    if missing:
        raise MetadataError(f"{where}: key feature_ranges lacks the training range of {missing}{RETRAIN}")
    for name in meta["feature_names"]:
        lo, hi = ranges[name]
        if not lo <= hi:
            raise MetadataError(
                f"{where}: key feature_ranges.{name} = {[lo, hi]}: the lower bound must not exceed the upper one"
                + RETRAIN
            )
    return meta
