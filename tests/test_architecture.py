"""The structure of the library: no import circles, no upward imports, the stages as packages.

The import graph is read from the source (every `import`, also those inside functions, which
are dependencies all the same). Layers, lowest first: the shared helpers (atomic files, readers,
the results layout, job logs), the figures' helpers (written through the atomic files), the table
contracts (`pbmdem.tables`, read through the readers), the settings layer (`pbmdem.config`), the
contracts (`pbmdem.impact`, then `pbmdem.frequency`), the stages
(`pbmdem.dem`, `pbmdem.pbm`, `pbmdem.surrogate`, independent of each other), the coupling of the
stages (`pbmdem.coupling`), the validation study (`pbmdem.validation`), what the fast model is for
(`pbmdem.design`: design space, calibration), the report, the command line. A module imports
only from its own unit or from lower layers.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
LAYERS = [
    {"atomic", "readers", "joblog", "layout", ""},
    {"plotting"},
    {"tables"},
    {"impact"},
    {"config"},
    {"frequency"},
    {"dem", "pbm", "surrogate"},
    {"coupling"},
    {"validation"},
    {"design"},
    {"report"},
    {"cli"},
]


def modules() -> dict[str, Path]:
    out = {}
    for path in (SRC / "pbmdem").rglob("*.py"):
        parts = path.relative_to(SRC).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


def import_graph() -> dict[str, set[str]]:
    mods = modules()
    graph = {}
    for name, path in mods.items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    base = ".".join(up + ([node.module] if node.module else []))
                targets = [base] + [f"{base}.{a.name}" for a in node.names]
            for t in targets:
                if not t.startswith("pbmdem"):
                    continue
                while t not in mods and "." in t:
                    t = t.rsplit(".", 1)[0]
                if t in mods and t != name:
                    deps.add(t)
        graph[name] = deps
    return graph


def unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def layer(module: str) -> int:
    return next(k for k, units in enumerate(LAYERS) if unit(module) in units)


def test_every_module_has_a_layer():
    for name in modules():
        assert any(unit(name) in units for units in LAYERS), name


def test_no_upward_or_sideways_imports():
    bad = [
        (m, d)
        for m, deps in import_graph().items()
        for d in deps
        if unit(d) != unit(m) and layer(d) >= layer(m) and unit(d) != ""
    ]
    assert not bad, "imports against the layering (module -> dependency): " + ", ".join(f"{m} -> {d}" for m, d in bad)


def test_no_import_circles():
    graph = import_graph()
    # modules importing their own package's __init__ (for a re-exported name) would be a circle
    # through the package; find every cycle with a depth-first search
    cycles, state, stack = [], {}, []

    def visit(node):
        state[node] = "open"
        stack.append(node)
        for dep in sorted(graph.get(node, ())):
            if dep.startswith(node + "."):
                continue  # a package's __init__ re-exporting its own modules is not a circle
            if state.get(dep) == "open":
                cycles.append(stack[stack.index(dep) :] + [dep])
            elif dep not in state:
                visit(dep)
        stack.pop()
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node)
    assert not cycles, "import circles: " + "; ".join(" -> ".join(c) for c in cycles)


@pytest.mark.parametrize("package", ["dem", "pbm", "surrogate", "coupling", "validation", "config", "report"])
def test_stages_are_packages_with_one_concept_per_module(package):
    folder = SRC / "pbmdem" / package
    assert (folder / "__init__.py").exists()
    doc = ast.get_docstring(ast.parse((folder / "__init__.py").read_text()))
    assert doc, f"pbmdem.{package} explains itself"
    for path in folder.glob("*.py"):
        assert ast.get_docstring(ast.parse(path.read_text())), f"{path.name} has no module docstring"


#: The longest a module of the library may be (issue 36: one concept per module)
MAX_MODULE_LINES = 400


def test_no_module_is_longer_than_400_lines():
    lines = {path.relative_to(SRC).as_posix(): len(path.read_text().splitlines()) for path in SRC.rglob("*.py")}
    assert len(lines) > 100  # the whole library was read
    too_long = {name: n for name, n in lines.items() if n > MAX_MODULE_LINES}
    assert not too_long, f"modules over {MAX_MODULE_LINES} lines (one concept per module): {too_long}"
