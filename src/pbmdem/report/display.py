"""Units and number formats of the report ("n/a" for a missing value), and display tables as HTML,
split to fit a page (`words.write_titled_table` writes them as CSV and HTML).
"""

from __future__ import annotations

import math

import pandas as pd

from pbmdem.plotting import MM

#: fraction -> %
PERCENT = 100.0
#: columns a page holds side by side (at the report's font size, on an A4/letter page or a laptop screen)
MAX_COLUMNS = 8


def missing(value) -> bool:
    """None, NaN or a text that reads as NaN: shown as "n/a"."""
    try:
        return value is None or math.isnan(float(value))
    except (TypeError, ValueError):
        return False


def number(value, spec: str = ".4g") -> str:
    """`value` formatted with `spec`; "n/a" for a missing value."""
    return "n/a" if missing(value) else format(float(value), spec)


def mm(value_m, decimals: int = 3) -> str:
    """A size in m shown in mm with `decimals` decimals."""
    return "n/a" if missing(value_m) else f"{MM * float(value_m):.{decimals}f}"


def percent(fraction, decimals: int = 2) -> str:
    """A fraction shown in % with `decimals` decimals."""
    return "n/a" if missing(fraction) else f"{PERCENT * float(fraction):.{decimals}f}"


def value_range(lo, hi, decimals: int = 3) -> str:
    """ "lo - hi" of two numbers already in display units."""
    if missing(lo) or missing(hi):
        return "n/a"
    return f"{float(lo):.{decimals}f} - {float(hi):.{decimals}f}"


def yes_no(flag) -> str:
    return "n/a" if missing(flag) else ("yes" if bool(flag) else "no")


def split_columns(frame: pd.DataFrame, keys: int = 1, max_columns: int = MAX_COLUMNS) -> list[pd.DataFrame]:
    """`frame` as one or more tables of at most `max_columns` columns each, every part repeating
    the first `keys` columns (what identifies a row), so that each part fits a page."""
    if frame.shape[1] <= max_columns:
        return [frame]
    key_cols = list(frame.columns[:keys])
    rest = list(frame.columns[keys:])
    per_part = max(1, max_columns - keys)
    return [frame[key_cols + rest[k : k + per_part]] for k in range(0, len(rest), per_part)]


STYLE = (
    "body{font-family:sans-serif;max-width:1100px;margin:1.5em auto;padding:0 1em;line-height:1.4}"
    "table.t{border-collapse:collapse;font-size:12px;margin:0.4em 0 1em 0;max-width:100%}"
    "table.t td,table.t th{padding:2px 6px;border-bottom:1px solid #ddd;text-align:left;vertical-align:top}"
    "table.t th{background:#f3f3f3;max-width:14em}table.t td{max-width:40em;overflow-wrap:anywhere}"
)


def table_html(frame: pd.DataFrame, keys: int = 1) -> str:
    """`frame` as HTML tables of at most MAX_COLUMNS columns each (the first `keys` columns
    repeated in each part), values as they are (display tables hold strings)."""
    return "".join(
        part.to_html(index=False, border=0, classes="t", na_rep="n/a", escape=True)
        for part in split_columns(frame, keys)
    )
