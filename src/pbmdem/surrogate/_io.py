"""Atomic file writes for the surrogate outputs, on top of :mod:`pbmdem.atomic`."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from pbmdem.atomic import atomic_path


def atomic_write(path: str | os.PathLike, write: Callable[[str], object]) -> Path:
    """Call ``write(tmp_path)`` on a temp file beside ``path``, then move it into place."""
    with atomic_path(path) as tmp:
        write(str(tmp))
    return Path(path)
