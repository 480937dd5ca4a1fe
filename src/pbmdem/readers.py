"""Reading the files the library consumes (tables, JSON metadata), with errors that name the file.

Every failure (missing, unreadable, empty, malformed, a required column missing, a non-finite
number where a finite one is required) raises `InputFileError`, a ValueError whose message starts
with what the file is and its path, never a bare pandas or JSON traceback.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd


class InputFileError(ValueError):
    """A file read by pbmdem is missing or malformed; the message names the file."""


def read_table(path: str | Path, what: str = "table", *, columns=(), finite=(), **options) -> pd.DataFrame:
    """A CSV table; `columns` must be present, the numeric `finite` columns must hold finite numbers.
    `options` go to `pandas.read_csv` (e.g. dtype=str, keep_default_na=False for a table of text)."""
    path = Path(path)
    try:
        frame = pd.read_csv(path, **options)
    except FileNotFoundError:
        raise InputFileError(f"{what} {path} does not exist") from None
    except pd.errors.EmptyDataError:
        raise InputFileError(f"{what} {path} is empty (no header, no rows)") from None
    except (OSError, UnicodeDecodeError, pd.errors.ParserError, ValueError) as exc:
        raise InputFileError(f"{what} {path} cannot be read as CSV: {exc}") from None
    require_columns(frame, columns, what, path)
    for name in finite:
        if name not in frame.columns:
            continue
        bad = ~np.isfinite(pd.to_numeric(frame[name], errors="coerce").to_numpy(float))
        if (row := first_index(bad)) is not None:
            raise InputFileError(
                f"{what} {path}: column {name!r} row {row + 1} = {frame[name].iloc[row]!r}: "
                f"a finite number is required ({int(bad.sum())} such row(s))"
            )
    return frame


def require_columns(frame: pd.DataFrame, columns, what: str, path) -> None:
    """InputFileError naming `what` and `path` (where `frame` was read) unless every one of `columns` is present."""
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise InputFileError(f"{what} {path}: missing column(s) {missing}; present: {list(frame.columns)}")


def first_index(bad):
    """The index of the first true entry (in row-major order) of the boolean array `bad`: an int
    for a 1-D array, a tuple of ints otherwise; None if no entry is true. Checks name the first
    offending entry (its row, column or class), its value and what is allowed."""
    bad = np.asarray(bad)
    if not bad.any():  # the common case, as cheap as the check itself
        return None
    return int(np.argmax(bad)) if bad.ndim == 1 else tuple(int(i) for i in np.argwhere(bad)[0])


def read_json(path: str | Path, what: str = "JSON file", *, keys=()) -> dict:
    """A JSON object; `keys` must be present."""
    path = Path(path)
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputFileError(f"{what} {path} does not exist") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputFileError(f"{what} {path} cannot be read as JSON: {exc}") from None
    if not isinstance(obj, dict):
        raise InputFileError(f"{what} {path}: a JSON object is required, found {type(obj).__name__}")
    missing = [k for k in keys if k not in obj]
    if missing:
        raise InputFileError(f"{what} {path}: missing field(s) {missing}")
    return obj
