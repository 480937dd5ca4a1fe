"""Shared matplotlib helpers of every stage's figures (the bottom layer: any stage may use them).

`pyplot()` is matplotlib on its file backend (Agg: no display needed) and `save_figure` writes a
figure atomically at the project's resolution `DPI` and closes it; every module that draws uses
them instead of setting matplotlib up on its own.

Each kind of figure that several stages draw is drawn by one function here: `size_distribution`
(the cumulative mass size distribution over a batch: a PBM run's psd.png, the report's
psd_evolution) and `final_sizes` (final d10/d50/d90 against impeller speed: the findings' speed
figure, the PBM-ANN speed sweep); `SIZE_STYLES` gives d10, d50 and d90 one marker and colour in
every figure.

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
#: m -> mm
MM = 1e3
#: m3/s -> mL/min
ML_PER_MIN = 6e7
#: (statistic, marker, colour) of d10, d50 and d90 in every figure of granule sizes
SIZE_STYLES = (("d90", "^", "tab:red"), ("d50", "o", "black"), ("d10", "v", "tab:blue"))
#: line styles of successive times in a size-distribution figure
TIME_STYLES = ("-", "--", "-.", ":", (0, (5, 1, 1, 1, 1, 1)))


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


def size_distribution(ax, curves, title: str, xlim=None) -> None:
    """Cumulative mass size distributions on `ax`, a log diameter axis with readable ticks: `curves`
    is a list of (label, diameters in mm, mass % finer than d, colour position 0-1 on viridis), one
    line style per curve (TIME_STYLES); the 50 % line marks the d50; `xlim` (mm) where the mass is."""
    cmap = pyplot().get_cmap("viridis")
    for k, (label, d_mm, cumulative, shade) in enumerate(curves):
        ax.plot(d_mm, cumulative, color=cmap(shade), ls=TIME_STYLES[k % len(TIME_STYLES)], lw=2.0, label=label)
    ax.set_xscale("log")
    ax.axhline(50.0, color="0.6", lw=0.8)
    if xlim is not None:
        ax.set_xlim(*xlim)
    ax.set_ylim(0, 100)
    log_ticks(ax, "x")
    ax.set(xlabel="diameter (mm)", ylabel="mass finer than d (%)")
    ax.set_title(title)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, loc="lower right")


def final_sizes(ax, rpm, frame, band: bool = False) -> None:
    """Final d10, d50 and d90 (columns of `frame`, m) against impeller speed `rpm` on `ax`, in mm,
    one marker and colour each (SIZE_STYLES); with `band` the surrogate members' range (columns
    <stat>_member_min, <stat>_member_max) shaded behind each line."""
    for stat, marker, color in SIZE_STYLES:
        if band:
            lo, hi = MM * frame[f"{stat}_member_min"], MM * frame[f"{stat}_member_max"]
            ax.fill_between(rpm, lo, hi, color=color, alpha=0.18, lw=0)
        ax.plot(rpm, MM * frame[stat], marker=marker, color=color, lw=1.8, label=f"final {stat}")
    ax.set(xlabel="impeller speed (rpm)", ylabel="final granule size (mm)")
    ax.grid(alpha=0.3)
