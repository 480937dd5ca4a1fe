"""The documentation names what exists: every `pbmdem.xxx` path in docs/*.md imports (a module,
or a module's attribute such as `pbmdem.dem.progress.ThermoProgress`)."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"
DOTTED = re.compile(r"\bpbmdem(?:\.[A-Za-z_][A-Za-z0-9_]*)+")


def named_paths() -> dict[str, str]:
    """Every dotted `pbmdem.` path of the docs, with the first document that names it."""
    out: dict[str, str] = {}
    for doc in sorted(DOCS.glob("*.md")):
        for name in DOTTED.findall(doc.read_text()):
            out.setdefault(name, doc.name)
    return out


def resolve(name: str):
    """The object a dotted path names: the longest importable module prefix, then attributes."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ModuleNotFoundError as exc:
            if exc.name is not None and not ".".join(parts[:k]).startswith(exc.name):
                raise  # a module that exists but imports something missing
            continue
        for attr in parts[k:]:
            obj = getattr(obj, attr)  # AttributeError: the docs name what is not there
        return obj
    raise ModuleNotFoundError(name)


def test_the_docs_name_module_paths():
    assert len(named_paths()) > 20


@pytest.mark.parametrize("name", sorted(named_paths()))
def test_every_module_path_in_the_docs_imports(name):
    try:
        resolve(name)
    except (ImportError, AttributeError) as exc:
        pytest.fail(f"docs/{named_paths()[name]} names {name}, which does not import: {exc}")
