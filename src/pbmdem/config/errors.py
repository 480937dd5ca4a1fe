"""Errors of the settings layer and the checks of single values given on a command line."""

from __future__ import annotations

import math


class ConfigError(ValueError):
    """The configuration (or a command-line value) is invalid; the message names the key or file,
    the value and what is allowed."""


#: the largest impeller speed the schema allows (grid.impeller_rpm, validation.rpm), rpm
RPM_MAX = 20000.0


def check_rpm(rpm, key: str = "--rpm") -> float:
    """An impeller speed as a float, or ConfigError naming `key` and the value (0 < rpm <= RPM_MAX)."""
    try:
        value = float(rpm)
    except (TypeError, ValueError):
        raise ConfigError(f"{key} = {rpm!r}: not a number (allowed: 0 < rpm <= {RPM_MAX:g})") from None
    if not math.isfinite(value) or not 0.0 < value <= RPM_MAX:
        raise ConfigError(
            f"{key} = {rpm!r}: impossible impeller speed (allowed: a finite number, 0 < rpm <= {RPM_MAX:g})"
        )
    return value
