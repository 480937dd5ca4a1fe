"""config/config.yaml holds the study's choices and their reasons, not a copy of the defaults.

A setting whose value in the file equals its default (the model's, `pbmdem config --show-defaults`)
is kept only with a comment giving the reason: on its line, or in the comment block that
introduces its group of keys.
"""

from __future__ import annotations

import json

import yaml
from pydantic import BaseModel
from pydantic_core import PydanticUndefined

from pbmdem.config import ConfigFile

MISSING = object()


def _default(model, path: tuple[str, ...]):
    """The default of the setting at `path` under `model` (MISSING: required or not a setting)."""
    name, rest = path[0], path[1:]
    field = model.model_fields.get(name)
    if field is None:
        return MISSING
    annotation = field.annotation
    if rest:
        sub = annotation if isinstance(annotation, type) and issubclass(annotation, BaseModel) else None
        return _default(sub, rest) if sub is not None else MISSING
    if field.default_factory is not None:
        return field.default_factory().model_dump(mode="json")
    if field.default is PydanticUndefined:
        return MISSING
    value = field.default
    return json.loads(json.dumps(value, default=lambda m: m.model_dump(mode="json")))


def _leaves(node, path=()):
    """(path, key node, value node) of every scalar or list setting of a composed YAML mapping."""
    for key, value in node.value:
        here = (*path, key.value)
        if isinstance(value, yaml.MappingNode):
            yield from _leaves(value, here)
        else:
            yield here, key, value


def _commented(lines: list[str], k: int) -> bool:
    """Line k (0-based) carries a comment, or a comment block at its indentation introduces the
    run of sibling keys it belongs to."""
    if "#" in lines[k].split(":", 1)[1]:
        return True
    indent = len(lines[k]) - len(lines[k].lstrip())
    for line in reversed(lines[:k]):
        stripped = line.strip()
        depth = len(line) - len(line.lstrip())
        if not stripped or depth < indent:
            return False
        if depth == indent and stripped.startswith("#"):
            return True
    return False


def restated_defaults(path) -> list[str]:
    """Settings of the file `path` that restate their default without a comment."""
    text = path.read_text()
    lines = text.splitlines()
    data = yaml.safe_load(text)
    out = []
    for keys, key_node, _ in _leaves(yaml.compose(text)):
        default = _default(ConfigFile, keys)
        value = data
        for name in keys:
            value = value[name]
        if default is not MISSING and value == default and not _commented(lines, key_node.start_mark.line):
            out.append(".".join(keys))
    return out


def test_the_config_restates_no_default_without_its_reason(root):
    assert restated_defaults(root / "config" / "config.yaml") == []


def test_the_check_finds_a_bare_default(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text(
        "dem:\n  seed: 20141\n  replicates: 3  # three insertion seeds: the noise floor\n"
        "  # the sampling window\n  sampling_revolutions: 0\n  history_time: 0.05\n\n  position_every: 2\n"
    )
    assert restated_defaults(path) == ["dem.seed", "dem.position_every"]


def test_pbmdem_config_lists_checks_and_describes(root, tmp_path, capsys):
    """`pbmdem config`: every setting with its default, unit and meaning; a file checked with the
    key, the value and what is allowed (exit status 2, no traceback); the generated JSON schema."""
    from pbmdem.cli import main

    assert main(["config", "--show-defaults"]) == 0
    listing = capsys.readouterr().out
    assert "dem.timeout = 7200.0 [s] (> 0)\n    wall-time limit per run" in listing
    assert "pbm.solver.rtol = 0.001 (> 0, <= 1)" in listing
    assert listing.count(" = ") >= 150
    assert main(["config", "--check", str(root / "config" / "config.yaml")]) == 0
    assert "valid" in capsys.readouterr().out
    bad = tmp_path / "bad.yaml"
    mapping = yaml.safe_load((root / "config" / "test.yaml").read_text())
    mapping["pbm"]["solver"] = {"rtol": 2.0}
    bad.write_text(yaml.safe_dump(mapping))
    assert main(["config", "--check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"config file {bad}" in err and "pbm.solver.rtol = 2.0" in err and "<= 1" in err
    assert "Traceback" not in err
    assert main(["config", "--schema"]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert schema["$schema"].endswith("2020-12/schema") and schema["additionalProperties"] is False
    assert schema["$defs"]["Solver"]["properties"]["rtol"] == {
        "default": 0.001,
        "description": "relative local error per step (ssp3, heun)",
        "exclusiveMinimum": 0,
        "maximum": 1,
        "title": "Rtol",
        "type": "number",
    }
