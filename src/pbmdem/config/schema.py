"""The configuration schema (JSON schema, draft 2020-12): validation and the defaults it holds.

The schema files are package data (`pbmdem/data/schemas/`, the same files as the workflow's
`workflow/schemas/`), so an installed pbmdem finds them from any directory. Every optional key
carries its default in the schema, and `complete(cfg)` validates a configuration and fills those
defaults in, once, for every path (Snakefile, CLI, library, tests). Errors name the key, the value
and what is allowed; NaN and infinite numbers are refused (JSON-schema range checks let NaN
through, since every comparison with NaN is false).
"""

from __future__ import annotations

import copy
import functools
import math
from importlib import resources
from pathlib import Path

from .errors import ConfigError

ROOT_SCHEMA = "config.schema.yaml"


def schema_dir() -> Path:
    """The folder of the schema files shipped with the package."""
    return Path(str(resources.files("pbmdem") / "data" / "schemas"))


@functools.cache
def _schemas() -> dict:
    import yaml

    return {p.name: yaml.safe_load(p.read_text()) for p in schema_dir().glob("*.schema.yaml")}


@functools.lru_cache(maxsize=1)
def _validator():
    import jsonschema
    from referencing import Registry, Resource
    from referencing.jsonschema import DRAFT202012

    schemas = _schemas()
    # the referenced section schemas without their own "$schema": a subschema naming its dialect
    # would be checked by jsonschema's plain validator of that dialect, which fills no defaults
    registry = Registry().with_resources(
        (
            name,
            Resource.from_contents({k: v for k, v in s.items() if k != "$schema"}, default_specification=DRAFT202012),
        )
        for name, s in schemas.items()
    )
    base = jsonschema.Draft202012Validator
    check_properties = base.VALIDATORS["properties"]

    def properties_with_defaults(validator, properties, instance, schema):
        # fill the defaults of absent keys, then validate as usual (nested objects are reached
        # through their own 'properties', so their defaults are filled too)
        if isinstance(instance, dict):
            for name, sub in properties.items():
                if isinstance(sub, dict) and "default" in sub and name not in instance:
                    instance[name] = copy.deepcopy(sub["default"])
        yield from check_properties(validator, properties, instance, schema)

    filling = jsonschema.validators.extend(base, {"properties": properties_with_defaults})
    return filling(schemas[ROOT_SCHEMA], registry=registry)


def non_finite_values(obj, prefix: str = "") -> list[str]:
    """Every NaN or infinite number in a nested config, as 'config key K = V: ...' messages."""
    out: list[str] = []
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += non_finite_values(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            out += non_finite_values(v, f"{prefix}[{i}]")
    elif isinstance(obj, float) and not math.isfinite(obj):
        out.append(
            f"config key {prefix or '(top level)'} = {obj!r}: not a finite number (allowed: finite numbers "
            "within the key's range)"
        )
    return out


def key_path(path, whole: str = "(top level)") -> str:
    """A key's path in a JSON document as `a.b[2].c` (`whole` for the document itself)."""
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or whole


def _describe(error) -> str:
    key = key_path(error.absolute_path)
    s = error.schema if isinstance(error.schema, dict) else {}
    v = error.validator
    if v == "required":
        return f"{key}: {error.message}"
    if v == "additionalProperties":
        allowed = sorted(s.get("properties", {}))
        return f"{key}: {error.message}; allowed keys: {allowed}"
    limits = []
    for name, word in (("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="), ("exclusiveMaximum", "<")):
        if name in s:
            limits.append(f"{word} {s[name]}")
    allowed = f" (allowed: {s.get('type', '')} {' and '.join(limits)})".replace("  ", " ") if limits else ""
    if "enum" in s:
        allowed = f" (allowed: {s['enum']})"
    return f"config key {key} = {error.instance!r}: {error.message}{allowed}"


def complete(cfg: dict) -> dict:
    """A validated copy of `cfg` with every default of the schema filled in; ConfigError listing
    every problem otherwise."""
    if not isinstance(cfg, dict):
        raise ConfigError("the top level of a configuration must be a mapping of sections")
    out = copy.deepcopy(cfg)
    errors = sorted(_validator().iter_errors(out), key=lambda e: list(map(str, e.absolute_path)))
    problems = non_finite_values(cfg)
    # a non-finite value is reported once, by the check above
    problems += [_describe(e) for e in errors if not (isinstance(e.instance, float) and not math.isfinite(e.instance))]
    if problems:
        raise ConfigError("invalid configuration:\n  " + "\n  ".join(problems))
    return out


def complete_section(name: str, section: dict) -> dict:
    """A validated copy of one optional section (e.g. 'pbm', 'surrogate') with its schema's
    defaults filled in; ConfigError naming `name.key` otherwise."""
    out = copy.deepcopy(section)
    validator = type(_validator())(_schemas()[f"{name}.schema.yaml"])
    errors = sorted(validator.iter_errors(out), key=lambda e: list(map(str, e.absolute_path)))
    problems = non_finite_values(section, name)
    for e in errors:
        if not (isinstance(e.instance, float) and not math.isfinite(e.instance)):
            e.path.appendleft(name)
            problems.append(_describe(e))
    if problems:
        raise ConfigError("invalid configuration:\n  " + "\n  ".join(problems))
    return out


def section_defaults(name: str) -> dict:
    """The defaults of one optional section (e.g. 'pbm', 'surrogate'), as the schema holds them."""
    return complete_section(name, {})
