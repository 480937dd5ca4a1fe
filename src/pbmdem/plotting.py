"""Shared matplotlib helpers of every stage's figures (the bottom layer: any stage may use them).

`pyplot()` is matplotlib on its file backend (Agg: no display needed) and `save_figure` writes a
figure atomically at the project's resolution `DPI` and closes it; every module that draws uses
them instead of setting matplotlib up on its own.

`log_ticks` labels a log axis so that labels never overlap: plain numbers (0.05, 2, 300) at the
decades; on an axis shorter than two decades also at 2 and 5 times a decade, and on one shorter
than half a decade at every minor tick (else the minor ticks stay unlabelled). matplotlib's
default labels the minor ticks of short log axes in its own width-blind way, and the labels run
together ("0.050.060.07...").
"""

from __future__ import annotations

import math
from pathlib import Path

from pbmdem.atomic import atomic_path

#: resolution of the figures (dots per inch): 110 dpi puts a 10 x 4 in figure at 1100 px, the
#: width of the report's page
DPI = 110


def pyplot():
    """matplotlib.pyplot on the Agg backend (figures are written to files; no display needed)."""
    import matplotlib  # lazy: matplotlib ~0.26 s, pyplot ~0.55 s (measured); only figure writers pay

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt  # lazy: after the backend is chosen above

    return plt


def save_figure(fig, path, dpi: float = DPI) -> Path:
    """Write `fig` to `path` (format from the suffix) atomically, and close it."""
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi, format=Path(path).suffix.lstrip(".") or "png")
    finally:
        pyplot().close(fig)
    return Path(path)


def _plain(value: float) -> str:
    return f"{value:g}"


def log_ticks(ax, axes: str = "x") -> None:
    """Readable tick labels on the log axes `axes` ("x", "y" or "xy") of `ax`; call after the limits are set."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter  # lazy: ~0.4 s (measured)

    for name in axes:
        axis = getattr(ax, f"{name}axis")
        lo, hi = sorted(getattr(ax, f"get_{name}lim")())
        span = math.log10(hi / lo) if lo > 0 and hi > 0 else 99.0
        axis.set_major_locator(LogLocator(base=10.0, numticks=12))
        axis.set_major_formatter(FuncFormatter(lambda v, _: _plain(v)))
        axis.set_minor_locator(LogLocator(base=10.0, subs=tuple(range(2, 10)), numticks=12))
        if span < 0.5:
            axis.set_minor_formatter(FuncFormatter(lambda v, _: _plain(v)))
        elif span < 2.0:
            axis.set_minor_formatter(FuncFormatter(lambda v, _: _plain(v) if _mantissa(v) in (2, 5) else ""))
        else:
            axis.set_minor_formatter(NullFormatter())


def _mantissa(value: float) -> int:
    if value <= 0:
        return 0
    return round(value / 10.0 ** math.floor(math.log10(value) + 1e-9))
