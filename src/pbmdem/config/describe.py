"""`pbmdem config`: every setting with its default, unit and description, the JSON schema generated
from the settings models, or the check of a config file (EXAMPLES)."""

from __future__ import annotations

import argparse
import json
import sys
import typing

from pydantic import BaseModel, TypeAdapter
from pydantic_core import PydanticUndefined

from . import load_config
from .errors import _choice, _resolve, _schema
from .settings import ConfigFile

_BOUNDS = (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<"), ("min_length", "items >="), ("max_length", "items <="))


EXAMPLES = """examples:
  pbmdem config --show-defaults                 # every setting: default, unit, bounds, meaning
  pbmdem config --check config/config.yaml      # the problems of a file, or 'valid'
  pbmdem config --schema > config.schema.json   # JSON schema for an editor
"""


def config_schema() -> dict:
    """The JSON schema (draft 2020-12) of a configuration file, generated from `ConfigFile`."""
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **ConfigFile.model_json_schema()}


def _model_of(annotation):
    """The settings model a field holds (itself, or in a tuple, dict or optional), if any."""
    for arg in (annotation, *typing.get_args(annotation)):
        if isinstance(arg, type) and issubclass(arg, BaseModel):
            return arg, arg is not annotation
    return None, False


def settings_table(model=ConfigFile, prefix: str = "") -> list[tuple[str, str, str, str, str]]:
    """(key, default, unit, bounds, description) of every setting under `model`, depth first."""
    rows = []
    for name, field in model.model_fields.items():
        key = f"{prefix}{name}"
        sub, container = _model_of(field.annotation)
        if sub is not None and not (container and field.default not in (PydanticUndefined, ())):
            inner = (
                f"{key}.<name>."
                if typing.get_origin(field.annotation) is dict
                else f"{key}[]."
                if container
                else f"{key}."
            )
            rows += settings_table(sub, inner)
            continue
        if field.is_required():
            default = "(required)"
        else:
            value = field.get_default(call_default_factory=True)
            default = json.dumps(TypeAdapter(field.annotation).dump_python(value, mode="json"))
        bounds = [
            f"{word} {getattr(m, attr)}"
            for m in field.metadata
            for attr, word in _BOUNDS
            if getattr(m, attr, None) is not None
        ]
        items = _item_bounds(model, name)
        bounds += [f"each {items}"] if items else []
        unit = (field.json_schema_extra or {}).get("unit", "") if isinstance(field.json_schema_extra, dict) else ""
        rows.append((key, default, unit, ", ".join(bounds), field.description or ""))
    return rows


def _item_bounds(model, name: str) -> str:
    """The bounds of the items of a list setting, from the generated JSON schema (`errors._schema`:
    once per model; regenerating it for every field took 0.4 s of the list's 0.5 s, measured)."""
    root = _schema(model)
    node = root.get("properties", {}).get(name, {})
    for branch in [node, *node.get("anyOf", [])]:
        if "items" in branch:
            items = _resolve(branch["items"], root)
            return _choice(items) or (f"matches {items['pattern']}" if "pattern" in items else "")
    return ""


def show_defaults(out=None) -> None:
    """Print every setting: key = default [unit] (bounds), then its description (to `out`, stdout)."""
    out = out or sys.stdout
    for key, default, unit, bounds, description in settings_table():
        unit = f" [{unit}]" if unit else ""
        bounds = f" ({bounds})" if bounds else ""
        print(f"{key} = {default}{unit}{bounds}\n    {description}", file=out)


def add_options(parser: argparse.ArgumentParser) -> None:
    """The description, examples and options of `pbmdem config`."""
    parser.description = "Every setting of a pbmdem configuration, declared once in pbmdem.config."
    parser.epilog = EXAMPLES
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--show-defaults", action="store_true", help="every setting: default, unit, bounds, meaning")
    what.add_argument("--schema", action="store_true", help="the JSON schema of a config file (generated)")
    what.add_argument("--check", metavar="FILE", help="check a config file (exit status 2 and the problems if invalid)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.show_defaults:
        show_defaults()
    elif args.schema:
        print(json.dumps(config_schema(), indent=2))
    else:
        cfg = load_config(args.check)
        print(f"{args.check}: valid (config sha256 {cfg.sha256()})")
    return 0
