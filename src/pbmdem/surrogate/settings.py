"""The ``surrogate:`` config section: defaults, validation, estimator construction."""

from __future__ import annotations

import copy
from pathlib import Path

import yaml

from pbmdem.config import merge_defaults

from .features import DEFAULT_IMPELLER_RADIUS
from .model import CollisionSurrogate

_REPO = Path(__file__).resolve().parents[3]
SCHEMA_PATH = _REPO / "workflow" / "schemas" / "surrogate.schema.yaml"
DEFAULTS_PATH = _REPO / "config" / "config.yaml"  # its surrogate: section holds the defaults

#: Same values as the surrogate: section of config/config.yaml (a test keeps them equal).
DEFAULTS: dict = {
    "hidden_layer_sizes": [[8], [8, 8]],
    "alpha": [0.01, 0.1, 1.0],
    "ensemble_size": 5,
    "seeds": [0, 1, 2, 3, 4],
    "random_state": 0,
    "max_iter": 2000,
    "activation": "tanh",
    "solver": "lbfgs",
    "cv": {"strategy": "leave_one_group_out", "n_splits": 5},
    "zero_collisions": "drop",
    "domain_margin": 0.0,
    "physics_offset": "cross_section",
}


class SurrogateConfigError(ValueError):
    """Invalid ``surrogate:`` configuration."""


def load_schema(path: str | Path = SCHEMA_PATH) -> dict:
    with open(path, encoding="utf-8") as fh:
        return yaml.safe_load(fh)


def validate_section(section: dict, schema_path: str | Path = SCHEMA_PATH) -> None:
    """Validate a (partial or complete) ``surrogate:`` section against the schema + extra checks."""
    import jsonschema

    validator = jsonschema.Draft202012Validator(load_schema(schema_path))
    errors = sorted(validator.iter_errors(section), key=lambda e: list(e.absolute_path))
    if errors:
        msg = "; ".join(f"surrogate.{'.'.join(map(str, e.absolute_path)) or '<section>'}: {e.message}"
                        for e in errors)
        raise SurrogateConfigError(msg)
    seeds, size = section.get("seeds"), section.get("ensemble_size")
    if seeds is not None and size is not None and len(seeds) != size:
        raise SurrogateConfigError(f"surrogate.seeds has {len(seeds)} entries but ensemble_size is {size}")


def resolve_settings(config: dict | None = None, schema_path: str | Path = SCHEMA_PATH) -> dict:
    """Complete, validated ``surrogate:`` settings from a full workflow config or a bare section.

    Missing keys take :data:`DEFAULTS`. If only ``ensemble_size`` is overridden, the default seed
    list is dropped (seeds become random_state, random_state + 1, ...).
    """
    config = config or {}
    section = config.get("surrogate", config if "granulator" not in config else {}) or {}
    if not isinstance(section, dict):
        raise SurrogateConfigError("the surrogate section must be a mapping")
    base = copy.deepcopy(DEFAULTS)
    if "ensemble_size" in section and "seeds" not in section:
        base["seeds"] = None
    merged = merge_defaults(base, section)
    validate_section(merged, schema_path)
    return merged


def impeller_radius_from(config: dict | None) -> float:
    """``granulator.impeller.blade_length`` of a full workflow config, else the default."""
    try:
        return float(config["granulator"]["impeller"]["blade_length"])
    except (TypeError, KeyError):
        return DEFAULT_IMPELLER_RADIUS


def build_surrogate(settings: dict, impeller_radius: float = DEFAULT_IMPELLER_RADIUS,
                    n_jobs: int | None = None) -> CollisionSurrogate:
    """A :class:`CollisionSurrogate` configured from resolved settings."""
    return CollisionSurrogate(
        hidden_layer_sizes=tuple(tuple(h) for h in settings["hidden_layer_sizes"]),
        alpha=tuple(float(a) for a in settings["alpha"]),
        ensemble_size=int(settings["ensemble_size"]),
        seeds=None if settings["seeds"] is None else tuple(int(s) for s in settings["seeds"]),
        random_state=int(settings["random_state"]),
        max_iter=int(settings["max_iter"]),
        activation=settings["activation"],
        solver=settings["solver"],
        cv=settings["cv"]["strategy"],
        n_splits=int(settings["cv"]["n_splits"]),
        impeller_radius=float(impeller_radius),
        zero_policy=settings["zero_collisions"],
        domain_margin=float(settings["domain_margin"]),
        n_jobs=n_jobs,
        physics_offset=settings["physics_offset"],
    )
