"""Load and validate the workflow configuration.

Two layers: the JSON schema in `workflow/schemas/config.schema.yaml` (types, ranges, required
keys; the Snakefile applies it with `snakemake.utils.validate`) and `check_config`, which checks
what a schema cannot express: number fractions that sum to 1, ascending diameters, particles that
fit the bowl, a bed that covers the impeller, grid names that exist. Every error names the key,
the offending value and what is allowed.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

import jsonschema
import yaml
from referencing import Registry, Resource
from referencing.jsonschema import DRAFT202012

FRACTION_TOLERANCE = 1e-6


class ConfigError(ValueError):
    """The configuration is invalid; the message names the key and what is allowed."""


class UniqueKeyLoader(yaml.SafeLoader):
    """YAML SafeLoader that rejects a key given twice in one mapping (PyYAML silently keeps the
    last one), naming the key and both lines."""

    def construct_mapping(self, node, deep=False):
        seen: dict = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                first = seen.get(key)
            except TypeError:  # unhashable key: let PyYAML report it
                continue
            line = key_node.start_mark.line + 1
            if first is not None:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r} on line {line} (first given on line {first}); "
                    "each key may appear only once in a mapping", key_node.start_mark)
            seen[key] = line
        return super().construct_mapping(node, deep=deep)


def load_yaml(path: str | Path, what: str = "YAML file"):
    """Parse a YAML file with duplicate keys rejected; errors name the file (ConfigError)."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ConfigError(f"{what} {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{what} {path} cannot be read: {exc}") from None
    try:
        return yaml.load(text, Loader=UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        raise ConfigError(f"{what} {path} is not valid YAML: {exc}") from None


def non_finite_values(obj, prefix: str = "") -> list[str]:
    """Every NaN or infinite number in a nested config, as 'config key K = V: ...' messages
    (JSON-schema range checks let NaN through, since every comparison with NaN is false)."""
    out: list[str] = []
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += non_finite_values(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            out += non_finite_values(v, f"{prefix}[{i}]")
    elif isinstance(obj, float) and not math.isfinite(obj):
        out.append(f"config key {prefix or '(top level)'} = {obj!r}: not a finite number (allowed: finite numbers "
                   "within the key's range)")
    return out


RPM_MAX = 20000.0


def check_rpm(rpm, key: str = "--rpm") -> float:
    """An impeller speed as a float, or ConfigError naming `key` and the value (> 0, <= 20000 rpm,
    the range the schema allows for grid.impeller_rpm and validation.rpm)."""
    try:
        value = float(rpm)
    except (TypeError, ValueError):
        raise ConfigError(f"{key} = {rpm!r}: not a number (allowed: 0 < rpm <= {RPM_MAX:g})") from None
    if not math.isfinite(value) or not 0.0 < value <= RPM_MAX:
        raise ConfigError(f"{key} = {rpm!r}: impossible impeller speed (allowed: a finite number, "
                          f"0 < rpm <= {RPM_MAX:g})")
    return value


def schema_dir() -> Path:
    here = Path(__file__).resolve()
    for parent in here.parents:
        candidate = parent / "workflow" / "schemas"
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError("workflow/schemas not found beside the pbmdem sources")


def _registry(folder: Path) -> Registry:
    resources = []
    for path in folder.glob("*.schema.yaml"):
        resources.append((path.name, Resource.from_contents(yaml.safe_load(path.read_text()),
                                                            default_specification=DRAFT202012)))
    return Registry().with_resources(resources)


def _key(path) -> str:
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "(top level)"


def _describe(error: jsonschema.ValidationError) -> str:
    key = _key(error.absolute_path)
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


def merge_defaults(defaults: dict, override: dict | None) -> dict:
    """Deep copy of `defaults` with the keys of `override` replacing them, nested dicts merged."""
    out = copy.deepcopy(defaults)
    for key, value in (override or {}).items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merge_defaults(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def validate_schema(cfg: dict) -> None:
    folder = schema_dir()
    schema = yaml.safe_load((folder / "config.schema.yaml").read_text())
    validator = jsonschema.Draft202012Validator(schema, registry=_registry(folder))
    errors = sorted(validator.iter_errors(cfg), key=lambda e: list(map(str, e.absolute_path)))
    problems = non_finite_values(cfg)
    # a non-finite value is reported once, by the check above
    problems += [_describe(e) for e in errors
                 if not (isinstance(e.instance, float) and not math.isfinite(e.instance))]
    if problems:
        raise ConfigError("invalid configuration:\n  " + "\n  ".join(problems))


def check_config(cfg: dict) -> dict:
    """Checks beyond the schema; returns cfg unchanged or raises ConfigError listing every problem."""
    problems: list[str] = []
    bowl = cfg["granulator"]["bowl"]
    imp = cfg["granulator"]["impeller"]
    radius = 0.5 * bowl["diameter"]
    if imp["blade_length"] >= radius:
        problems.append(f"granulator.impeller.blade_length = {imp['blade_length']}: must be smaller than the "
                        f"bowl radius {radius}")
    if imp.get("hub_diameter", 0.01) / 2 >= imp["blade_length"]:
        problems.append(f"granulator.impeller.hub_diameter = {imp.get('hub_diameter')}: must be smaller than "
                        f"twice the blade length {2 * imp['blade_length']}")
    impeller_top = imp["clearance"] + imp["blade_height"]
    if impeller_top >= bowl["height"]:
        problems.append(f"granulator.impeller: clearance + blade_height = {impeller_top} must be below the "
                        f"bowl height {bowl['height']}")
    dem = cfg["dem"]
    if dem["bed_height"] <= impeller_top:
        problems.append(f"dem.bed_height = {dem['bed_height']}: the bed must cover the impeller, i.e. exceed "
                        f"clearance + blade_height = {impeller_top}")
    if dem["bed_height"] >= bowl["height"]:
        problems.append(f"dem.bed_height = {dem['bed_height']}: must be below the bowl height {bowl['height']}")
    gap = radius - imp["blade_length"]
    for name, dist in cfg["size_distributions"].items():
        d, w = dist["diameters"], dist["number_fractions"]
        key = f"size_distributions.{name}"
        if len(d) != len(w):
            problems.append(f"{key}: {len(d)} diameters but {len(w)} number_fractions; one fraction per class")
            continue
        if any(b <= a for a, b in zip(d, d[1:])):
            problems.append(f"{key}.diameters = {d}: must be strictly ascending (class k is the k-th size)")
        total = math.fsum(w)
        if abs(total - 1.0) > FRACTION_TOLERANCE:
            problems.append(f"{key}.number_fractions = {w}: sum to {total:.6g}, must sum to 1 "
                            f"(within {FRACTION_TOLERANCE})")
        d_max = max(d)
        free_height = bowl["height"] - impeller_top
        if 3 * d_max >= free_height:
            problems.append(f"{key}.diameters: largest {d_max} m does not fit the bowl: the space above the "
                            f"impeller ({free_height:.4g} m) must exceed 3 particle diameters")
        if 2 * d_max >= radius:
            problems.append(f"{key}.diameters: largest {d_max} m does not fit the bowl: it must be below "
                            f"half the bowl radius ({radius / 2:.4g} m)")
        if d_max > 0 and gap < 0:
            problems.append(f"{key}: no gap between blade tips and wall")
    for name in cfg["grid"]["size_distributions"]:
        if name not in cfg["size_distributions"]:
            problems.append(f"grid.size_distributions: {name!r} is not defined; defined names: "
                            f"{sorted(cfg['size_distributions'])}")
    validation = cfg.get("validation") or {}
    if "distribution" in validation and validation["distribution"] not in cfg["size_distributions"]:
        problems.append(f"validation.distribution: {validation['distribution']!r} is not defined; defined names: "
                        f"{sorted(cfg['size_distributions'])}")
    sweep = validation.get("sweep") or {}
    if "start" in sweep and "stop" in sweep and not sweep["stop"] > sweep["start"]:
        problems.append(f"validation.sweep: stop = {sweep['stop']} must be greater than start = {sweep['start']}")
    if problems:
        raise ConfigError("invalid configuration:\n  " + "\n  ".join(problems))
    return cfg


def validate(cfg: dict) -> dict:
    validate_schema(cfg)
    return check_config(cfg)


def load_config(path: str | Path) -> dict:
    path = Path(path)
    cfg = load_yaml(path, "config file")
    if not isinstance(cfg, dict):
        raise ConfigError(f"config file {path}: the top level must be a mapping of sections")
    try:
        return validate(cfg)
    except ConfigError as exc:
        raise ConfigError(f"config file {path}: {exc}") from None
