"""Errors of the settings layer: every message names the key, the value and what is allowed."""

from __future__ import annotations

import functools


class ConfigError(ValueError):
    """The configuration (or a command-line value) is invalid; the message names the key or file,
    the value and what is allowed."""


@functools.cache
def _schema(model) -> dict:
    return model.model_json_schema()


def _resolve(node: dict, root: dict) -> dict:
    while "$ref" in node:
        node = root["$defs"][node["$ref"].rsplit("/", 1)[1]]
    return node


def _branches(node: dict, root: dict) -> list[dict]:
    node = _resolve(node, root)
    if "anyOf" in node:
        return [_resolve(b, root) for b in node["anyOf"] if b.get("type") != "null"]
    return [node]


def _locate(model, loc) -> tuple[str, dict, dict]:
    """The dotted key of a pydantic error location, the schema of its value and of its parent
    (union member tags such as 'int' are left out of the key)."""
    root = _schema(model)
    node, parent, key = root, root, ""
    for part in loc:
        if part == "[key]":
            continue
        nxt = None
        for b in _branches(node, root):
            if isinstance(part, int) and "items" in b:
                nxt = b["items"]
            elif isinstance(part, int) and "prefixItems" in b:
                nxt = b["prefixItems"][part] if part < len(b["prefixItems"]) else {}
            elif part in b.get("properties", {}):
                nxt = b["properties"][part]
            elif isinstance(b.get("additionalProperties"), dict):
                nxt = b["additionalProperties"]
            elif "patternProperties" in b:
                nxt = next(iter(b["patternProperties"].values()))
            if nxt is not None:
                parent = b
                break
        if nxt is None:  # a union member's tag, or a key the schema does not know
            if any("properties" in b or "patternProperties" in b for b in _branches(node, root)):
                parent = _branches(node, root)[0]
                key += f".{part}" if key else str(part)
                node = {}
            continue
        key += f"[{part}]" if isinstance(part, int) else (f".{part}" if key else str(part))
        node = nxt
    return key, _resolve(node, root), _resolve(parent, root)


def _choice(s: dict) -> str:
    if "const" in s:
        return repr(s["const"])
    if "enum" in s:
        return str(s["enum"])
    limits = [
        f"{word} {s[name]}"
        for name, word in (("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="), ("exclusiveMaximum", "<"))
        if name in s
    ]
    return " ".join([s.get("type", ""), " and ".join(limits)]).strip() if limits else ""


def _allowed(s: dict) -> str:
    choices = [_choice(b) or b.get("type", "") for b in s.get("anyOf", [s])]
    if len(choices) > 1 or (choices and choices[0] and choices[0] != s.get("type")):
        return f" (allowed: {' or '.join(choices)})"
    return ""


_WORDS = {
    "greater_than_equal": "is less than the minimum of {ge}",
    "greater_than": "is less than or equal to the minimum of {gt}",
    "less_than_equal": "is greater than the maximum of {le}",
    "less_than": "is greater than or equal to the maximum of {lt}",
    "string_pattern_mismatch": "does not match {pattern!r}",
    "too_short": "is too short (at least {min_length})",
    "too_long": "is too long (at most {max_length})",
    "finite_number": "is not a finite number",
}


def describe_errors(exc, model, prefix: str = "") -> list[str]:
    """One line per error of the pydantic ValidationError `exc` of `model`: the dotted key (under
    `prefix`), the value and what is allowed."""
    out = []
    errors = exc.errors()
    for e in errors:
        if e["type"] in ("too_short", "too_long") and any(
            len(o["loc"]) > len(e["loc"]) and o["loc"][: len(e["loc"])] == e["loc"] for o in errors
        ):
            continue  # a list whose items failed counts as empty after validation
        key, s, parent = _locate(model, e["loc"])
        key = ".".join(p for p in (prefix, key) if p) or "(top level)"
        where, name = key.rpartition(".")[0] or "(top level)", key.rpartition(".")[2]
        kind, ctx = e["type"], e.get("ctx", {})
        if kind == "missing":
            out.append(f"{where}: {name!r} is a required property")
        elif kind == "extra_forbidden":
            out.append(
                f"{where}: Additional properties are not allowed ({name!r} was unexpected); "
                f"allowed keys: {sorted(parent.get('properties', {}))}"
            )
        else:
            types = {b.get("type") for b in ([s] + s.get("anyOf", [])) if b.get("type")}
            if len([b for b in s.get("anyOf", []) if b.get("type") != "null"]) > 1:
                word = "not allowed"  # a union: one message naming every choice
            elif kind in _WORDS:
                bounds = {"ge": "minimum", "gt": "exclusiveMinimum", "le": "maximum", "lt": "exclusiveMaximum"}
                b = next((x for x in s.get("anyOf", [s]) if x.get("type") != "null"), s)
                # the value, then the rule it breaks, as the JSON schema's messages read
                word = f"{e['input']!r} " + _WORDS[kind].format(**ctx | {k: b[v] for k, v in bounds.items() if v in b})
            elif kind.endswith("_type") or kind.endswith("_parsing"):
                word = f"is not of type {' or '.join(repr(t) for t in sorted(types)) or kind}"
            else:
                word = e["msg"].removeprefix("Value error, ")
            out.append(f"config key {key} = {e['input']!r}: {word}{_allowed(s)}")
    return sorted(dict.fromkeys(out))
