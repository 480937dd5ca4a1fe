"""Units and number formats of the report, and tables split so that they fit a page.

The result files are in SI units (sizes in m); the report shows sizes in mm, fractions in %, and
names every column with its unit, e.g. "d50 at end (mm)". Missing values (NaN) read "n/a".
"""

from __future__ import annotations

import math

import pandas as pd

#: m -> mm
MM = 1e3
#: fraction -> %
PERCENT = 100.0
#: columns a page holds side by side (at the report's font size, on an A4/letter page or a laptop screen)
MAX_COLUMNS = 8


def _missing(value) -> bool:
    try:
        return value is None or math.isnan(float(value))
    except (TypeError, ValueError):
        return False


def number(value, spec: str = ".4g") -> str:
    """`value` formatted with `spec`; "n/a" for a missing value."""
    return "n/a" if _missing(value) else format(float(value), spec)


def mm(value_m, decimals: int = 3) -> str:
    """A size in m shown in mm with `decimals` decimals."""
    return "n/a" if _missing(value_m) else f"{MM * float(value_m):.{decimals}f}"


def percent(fraction, decimals: int = 2) -> str:
    """A fraction shown in % with `decimals` decimals."""
    return "n/a" if _missing(fraction) else f"{PERCENT * float(fraction):.{decimals}f}"


def value_range(lo, hi, decimals: int = 3) -> str:
    """ "lo - hi" of two numbers already in display units."""
    if _missing(lo) or _missing(hi):
        return "n/a"
    return f"{float(lo):.{decimals}f} - {float(hi):.{decimals}f}"


def yes_no(flag) -> str:
    return "n/a" if _missing(flag) else ("yes" if bool(flag) else "no")


def shown(frame: pd.DataFrame, names: dict[str, str], spec: str = ".4g") -> pd.DataFrame:
    """The columns of `frame` named in `names` (those present, in the order of `names`), renamed to
    their display names (with units) and their float values formatted with `spec`."""
    out = frame[[c for c in names if c in frame.columns]].rename(columns=names)
    return out.map(lambda v: number(v, spec) if isinstance(v, float) else v)


def split_columns(frame: pd.DataFrame, keys: int = 1, max_columns: int = MAX_COLUMNS) -> list[pd.DataFrame]:
    """`frame` as one or more tables of at most `max_columns` columns each, every part repeating
    the first `keys` columns (what identifies a row), so that each part fits a page."""
    if frame.shape[1] <= max_columns:
        return [frame]
    key_cols = list(frame.columns[:keys])
    rest = list(frame.columns[keys:])
    per_part = max(1, max_columns - keys)
    return [frame[key_cols + rest[k : k + per_part]] for k in range(0, len(rest), per_part)]
