"""Render LIGGGHTS input decks from the templates in `liggghts_templates/`.

A LIGGGHTS input script can run shell commands (`shell ...`), so nothing from a config file is
pasted into a deck as text. Every substituted value passes through `number()` (a finite float or
int within a stated range, formatted by Python) or `known_name()` (a member of a fixed set or a
plain identifier), and the template is filled with `string.Template.substitute`, which fails on
any placeholder left unfilled.
"""

from __future__ import annotations

import math
import re
import string
from importlib import resources
from pathlib import Path

_IDENTIFIER = re.compile(r"^[A-Za-z][A-Za-z0-9_-]{0,63}$")


class DeckValueError(ValueError):
    """A value meant for a LIGGGHTS deck is not an allowed number or name."""


def template_dir() -> Path:
    """The `liggghts_templates/` folder of the source tree (or of an installed copy)."""
    here = Path(__file__).resolve()
    for parent in here.parents:
        candidate = parent / "liggghts_templates"
        if candidate.is_dir():
            return candidate
    packaged = resources.files("pbmdem") / "liggghts_templates"
    return Path(str(packaged))


def number(name: str, value, *, minimum: float | None = None, maximum: float | None = None,
           integer: bool = False, exclusive_minimum: bool = False) -> str:
    """Validate `value` as a finite number in range and return its text for a deck."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DeckValueError(f"{name} = {value!r}: a number is required, got {type(value).__name__}")
    if not math.isfinite(value):
        raise DeckValueError(f"{name} = {value!r}: a finite number is required")
    if integer and float(value) != int(value):
        raise DeckValueError(f"{name} = {value!r}: an integer is required")
    if minimum is not None:
        if exclusive_minimum and not value > minimum:
            raise DeckValueError(f"{name} = {value!r}: must be greater than {minimum}")
        if not exclusive_minimum and value < minimum:
            raise DeckValueError(f"{name} = {value!r}: must be at least {minimum}")
    if maximum is not None and value > maximum:
        raise DeckValueError(f"{name} = {value!r}: must be at most {maximum}")
    return str(int(value)) if integer else repr(float(value))


def known_name(name: str, value, allowed: set[str] | None = None) -> str:
    """Validate a name: a member of `allowed` if given, otherwise a plain identifier."""
    if not isinstance(value, str):
        raise DeckValueError(f"{name} = {value!r}: a name (string) is required")
    if allowed is not None:
        if value not in allowed:
            raise DeckValueError(f"{name} = {value!r}: allowed names are {sorted(allowed)}")
        return value
    if not _IDENTIFIER.match(value):
        raise DeckValueError(
            f"{name} = {value!r}: a name must start with a letter and contain only letters, digits, "
            "'_' or '-' (at most 64 characters)"
        )
    return value


def numbers(name: str, values, **limits) -> str:
    """Validate a sequence of numbers; return them space-separated."""
    return " ".join(number(f"{name}[{k}]", v, **limits) for k, v in enumerate(values))


def render(template_name: str, values: dict[str, str]) -> str:
    """Fill `liggghts_templates/<template_name>` with already-validated text values.

    Values must come from `number`, `numbers` or `known_name` (or be built only from them);
    a value containing a line break or a LIGGGHTS comment/variable character is refused as a
    last line of defence.
    """
    for key, text in values.items():
        if not isinstance(text, str):
            raise DeckValueError(f"deck value {key} is not text; validate it with deck.number()")
        if key.endswith("_block"):
            continue  # multi-line blocks are assembled from validated numbers by the caller
        if any(ch in text for ch in "\n\r#$&;\"'`"):
            raise DeckValueError(f"deck value {key} = {text!r} contains a character not allowed in a deck")
    text = (template_dir() / template_name).read_text()
    try:
        return string.Template(text).substitute(values)
    except KeyError as exc:
        raise DeckValueError(f"template {template_name} needs a value for {exc.args[0]}") from None
