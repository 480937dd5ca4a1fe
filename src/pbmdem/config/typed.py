"""Frozen, typed settings objects built from validated configuration mappings.

Every settings class of `pbmdem.config` is a frozen dataclass whose fields mirror the keys of its
config section. `build(cls, mapping, key)` turns a mapping that the schema has already validated
(and completed with its defaults) into an instance, converting YAML numbers and lists to the
field types (lists become tuples, so the objects are immutable and hashable); `plain(obj)` turns
an instance back into plain JSON-able data (tuples become lists), the form Snakemake params and
JSON files need. No defaults live here: a missing key is a programming error, reported with its
config key.
"""

from __future__ import annotations

import dataclasses
import functools
import types
import typing

from .errors import ConfigError


@functools.cache
def _hints(cls) -> dict:
    return typing.get_type_hints(cls)


def _convert(hint, value, key: str):
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        options = [a for a in args if a is not type(None)]
        for option in options:  # e.g. int | str: the first type the value already is
            base = typing.get_origin(option) or option
            if isinstance(base, type) and isinstance(value, base) and not (base is int and isinstance(value, bool)):
                return _convert(option, value, key)
        return _convert(options[0], value, key)
    if dataclasses.is_dataclass(hint):
        return build(hint, value, key)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"config key {key} = {value!r}: a list is required")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{key}[{k}]") for k, v in enumerate(value))
        return tuple(_convert(a, v, f"{key}[{k}]") for k, (a, v) in enumerate(zip(args, value)))
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"config key {key} = {value!r}: a mapping is required")
        return {str(k): _convert(args[1], v, f"{key}.{k}") for k, v in value.items()}
    if hint is float:
        return float(value)
    if hint is int:
        return int(value)
    if hint is bool:
        return bool(value)
    if hint is str:
        return str(value)
    return value


def build(cls, data, key: str):
    """An instance of the frozen dataclass `cls` from the validated mapping `data` (config key `key`)."""
    if not isinstance(data, dict):
        raise ConfigError(f"config key {key} = {data!r}: a mapping is required")
    hints = _hints(cls)
    kwargs = {}
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        if f.name not in data:
            raise ConfigError(
                f"config key {key}.{f.name} is missing (the configuration was not completed by "
                "pbmdem.config.load_config / validate)"
            )
        kwargs[f.name] = _convert(hints[f.name], data[f.name], f"{key}.{f.name}")
    return cls(**kwargs)


def plain(obj):
    """Plain data (dicts, lists, numbers, strings) of a settings object, for params and JSON."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: plain(getattr(obj, f.name)) for f in dataclasses.fields(obj) if f.init}
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in sorted(obj.items())}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    return obj


class Settings:
    """Mixin of the settings dataclasses: `from_dict`, `to_dict` and `replace`."""

    @classmethod
    def from_dict(cls, data: dict, key: str = ""):
        return build(cls, data, key or cls.__name__)

    def to_dict(self) -> dict:
        return plain(self)

    def replace(self, **changes):
        return dataclasses.replace(self, **changes)
