"""The ``surrogate:`` config section: defaults, validation, estimator construction (``build_surrogate``)."""

from __future__ import annotations

import copy
from pathlib import Path

import yaml
from sklearn.base import clone

from pbmdem.config import merge_defaults

from .baselines import HGBBaseline, PhysicalScaling
from .ensemble import EnsembleMLPRegressorCV
from .features import check_impeller_radius
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


def impeller_radius_from(config: dict | None, source: str = "the config") -> float:
    """``granulator.impeller.blade_length`` (m) of a full workflow config.

    The impeller radius has one owner, the config's granulator; there is no default: a config
    without it is an error naming the key (the surrogate's tip-speed feature needs it).
    """
    try:
        value = config["granulator"]["impeller"]["blade_length"]
    except (TypeError, KeyError):
        raise SurrogateConfigError(
            f"{source} has no granulator.impeller.blade_length: the surrogate's tip-speed feature needs the "
            f"impeller radius (pass the full workflow config, e.g. config/config.yaml)") from None
    try:
        return check_impeller_radius(value)
    except ValueError:
        raise SurrogateConfigError(f"{source}: granulator.impeller.blade_length = {value!r}; allowed: a number "
                                   f"> 0 (m)") from None


def member_seeds(settings: dict) -> tuple[int, ...]:
    """The ensemble members' seeds: ``seeds``, or ``random_state, random_state + 1, ...``
    (``ensemble_size`` of them) when ``seeds`` is null."""
    size = int(settings["ensemble_size"])
    if size < 1:
        raise SurrogateConfigError(f"surrogate.ensemble_size = {size}; allowed: an integer >= 1")
    if settings["seeds"] is None:
        return tuple(int(settings["random_state"]) + k for k in range(size))
    seeds = tuple(int(s) for s in settings["seeds"])
    if len(seeds) != size:
        raise SurrogateConfigError(f"surrogate.seeds has {len(seeds)} entries but surrogate.ensemble_size is {size}")
    return seeds


def build_surrogate(settings: dict, impeller_radius: float, n_jobs: int | None = None) -> CollisionSurrogate:
    """A :class:`CollisionSurrogate` configured from a complete ``surrogate:`` section.

    Every estimator parameter comes from ``settings`` (none from the estimators' defaults);
    ``impeller_radius`` (m) is ``granulator.impeller.blade_length``. The frequency and the
    impact-velocity model share the settings.
    """
    ensemble = EnsembleMLPRegressorCV(
        hidden_layer_sizes=tuple(tuple(int(u) for u in h) for h in settings["hidden_layer_sizes"]),
        alpha=tuple(float(a) for a in settings["alpha"]),
        seeds=member_seeds(settings),
        max_iter=int(settings["max_iter"]),
        activation=settings["activation"],
        solver=settings["solver"],
        cv=settings["cv"]["strategy"],
        n_splits=int(settings["cv"]["n_splits"]),
        n_jobs=n_jobs,
    )
    return CollisionSurrogate(
        frequency_model=ensemble,
        velocity_model=clone(ensemble),
        impeller_radius=check_impeller_radius(impeller_radius),
        physics_offset=settings["physics_offset"],
        domain_margin=float(settings["domain_margin"]),
    )


def build_baselines(settings: dict) -> dict:
    """The baselines of the evaluation (``hgb`` seeded with ``random_state``, ``physical``)."""
    return {"hgb": HGBBaseline(random_state=int(settings["random_state"])), "physical": PhysicalScaling()}
