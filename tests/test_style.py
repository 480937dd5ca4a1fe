"""Style: the Python sources are ruff-clean and ruff-formatted, the Snakefile and rules
snakefmt-clean (both tools pinned in requirements.txt and configured in pyproject.toml)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def _tool(name: str) -> str:
    return str(Path(sys.executable).with_name(name))


def test_ruff_is_clean(root):
    proc = subprocess.run(
        [_tool("ruff"), "check", "src", "workflow/scripts", "tests", "benchmarks"],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout[-6000:] + proc.stderr[-2000:]


def test_python_is_ruff_formatted(root):
    proc = subprocess.run(
        [_tool("ruff"), "format", "--check", "--diff", "src", "workflow/scripts", "tests", "benchmarks"],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout[-6000:] + proc.stderr[-2000:]


def test_snakefmt_is_clean(root):
    files = ["Snakefile", *sorted(str(p.relative_to(root)) for p in (root / "rules").glob("*.smk"))]
    proc = subprocess.run(
        [_tool("snakefmt"), "--check", "--diff", *files], cwd=root, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stdout[-6000:] + proc.stderr[-2000:]
