"""The figures of one validation speed (sizes in mm, times in s): size bands, size-distribution
evolution, liquid and porosity, collision frequency; `write_speed` (rule report_speed) writes them
with the speed's out-of-domain table.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pbmdem.config.pbm import ProcessSettings
from pbmdem.pbm.results import cumulative_mass
from pbmdem.plotting import log_ticks, pyplot, save_figure, size_distribution
from pbmdem.readers import InputFileError, read_table, require_columns
from pbmdem.surrogate import load_surrogate
from pbmdem.tables import STATISTICS
from pbmdem.validation.results import load_speed

from .display import MM, PERCENT
from .frequencies import interval_frequencies, surrogate_on_dem_samples
from .statements import out_of_domain, out_of_domain_sentence
from .words import write_titled_table

#: the columns of the tables these figures read, checked where `write_speed` reads them: a run's
#: summary.csv, bins.csv (the order of `psd_evolution`'s reading) and a speed's bands.csv
SUMMARY_COLUMNS = ("time", "d10", "d50", "d90", "mean_liquid_content", "mean_porosity")
BINS_COLUMNS = ("time", "diameter", "mass_density_lnd")
BANDS_COLUMNS = ("statistic", "time", "n_dem_replicates", "dem_mean", "dem_min", "dem_max", "ann")

STYLES = {
    "PBM-DEM": dict(color="black", lw=2.0),
    "PBM-ANN": dict(color="tab:orange", ls="--", lw=2.0),
    "PBM-constant": dict(color="tab:blue", ls=":", lw=2.0),
}
# bands: filled, with a drawn edge, so that a band narrower than a line is still seen (as a thicker line)
BAND = {
    "PBM-DEM": dict(facecolor="0.55", edgecolor="0.35", lw=0.8, alpha=0.45),
    "PBM-ANN": dict(facecolor="tab:orange", edgecolor="tab:orange", lw=0.8, alpha=0.3),
}


def _width_text(lo, hi) -> str:
    """'at most 0.012 mm wide': how wide a band is, so that a reader knows why it may look thin."""
    width = float(np.nanmax(np.asarray(hi, float) - np.asarray(lo, float))) if len(lo) else float("nan")
    return f"up to {width:.2g} mm wide" if np.isfinite(width) else "width n/a"


def _spray(ax, process) -> None:
    ax.axvspan(process.spray_start, process.spray_end, color="tab:cyan", alpha=0.10, lw=0, label="liquid addition")


def _column(frame: pd.DataFrame, name: str) -> np.ndarray:
    return frame[name].to_numpy(float)


def _models(ax, process, dem, n: int, ann, constant, members, dem_band: bool = True) -> None:
    """One panel of a speed: the liquid addition, PBM-DEM's band and mean (`dem`: time, min, max, mean
    of `n` replicates), PBM-ANN's members' band (time, min, max; None: none) and mean, PBM-constant."""
    _spray(ax, process)
    if dem_band:
        ax.fill_between(*dem[:3], **BAND["PBM-DEM"], label=f"PBM-DEM band (min-max of {n} replicates)")
    ax.plot(dem[0], dem[3], **STYLES["PBM-DEM"], label="PBM-DEM mean")
    if members is not None:
        ax.fill_between(*members, **BAND["PBM-ANN"], label="PBM-ANN band (min-max of the surrogate's members)")
    ax.plot(*ann, **STYLES["PBM-ANN"], label="PBM-ANN (mean prediction)")
    if constant is not None:
        ax.plot(*constant, **STYLES["PBM-constant"], label="PBM-constant")


def legend_below(fig, ax, ncol: int, bottom: float, relabel=None) -> None:
    """The report's figure legend: `ax`'s entries (labels through `relabel`) below the panels, 8 pt,
    no frame; the panels fill the figure above the share `bottom` of its height."""
    handles, labels = ax.get_legend_handles_labels()
    labels = labels if relabel is None else [relabel(label) for label in labels]
    fig.legend(handles, labels, loc="lower center", ncol=ncol, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, bottom, 1, 1))


def size_bands(bands: pd.DataFrame, process, rpm: str, what: str = "bands table"):
    """d10/d50/d90 (mm) against time (s), one panel each, from a speed's bands.csv (`BANDS_COLUMNS`)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(12, 4.2))
    for ax, stat in zip(axes, STATISTICS):
        b = bands[bands["statistic"] == stat].sort_values("time")
        if b.empty:
            raise InputFileError(f"{what}: no rows of statistic {stat!r}")
        members = (b.time, MM * b.ann_member_min, MM * b.ann_member_max) if "ann_member_min" in b else None
        constant = (b.time, MM * b.constant) if "constant" in b.columns else None
        dem = (b.time, MM * b.dem_min, MM * b.dem_max, MM * b.dem_mean)
        _models(ax, process, dem, int(b["n_dem_replicates"].iloc[0]), (b.time, MM * b.ann), constant, members)
        ax.set(xlabel="time (s)", ylabel=f"{stat} (mm)", title=f"{stat}, {rpm} rpm")
        ax.grid(alpha=0.3)
    d50 = bands[bands["statistic"] == "d50"]

    def relabel(label: str) -> str:  # the band's width in the legend is that of the d50 panel
        if not label.startswith("PBM-DEM band"):
            return label
        return label[:-1] + f"; {_width_text(MM * d50.dem_min, MM * d50.dem_max)} in d50)"

    legend_below(fig, axes[0], 3, 0.12, relabel)
    return fig


def snapshot_times(recorded, process) -> list[float]:
    """The recorded times nearest to the start, the start, middle and end of the liquid addition and
    the end of the batch (duplicates dropped, ascending)."""
    recorded = np.unique(np.asarray(recorded, float))
    wanted = [0.0, process.spray_start, 0.5 * (process.spray_start + process.spray_end), process.spray_end, process.end]
    return sorted({float(recorded[np.argmin(np.abs(recorded - t))]) for t in wanted})


def cumulative_undersize(diameter: np.ndarray, density_lnd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(upper edges, mass % finer than them) of the bins at ``diameter`` (ascending) from the mass
    density per ln d; a bin's edges lie halfway between its diameter and its neighbours' in ln d, so
    that the curve passes through d50 where summary.csv has it."""
    d, q = diameter, np.clip(density_lnd, 0.0, None)
    width = np.gradient(np.log(d)) if len(d) > 1 else np.ones_like(d)
    ln = np.log(d)
    upper = np.exp(np.append(0.5 * (ln[1:] + ln[:-1]), ln[-1] + 0.5 * width[-1]))
    return upper, cumulative_mass(q * width, PERCENT)


def psd_evolution(bins: dict[str, pd.DataFrame], process, rpm: str):
    """Cumulative mass undersize (%) against diameter (mm) at `snapshot_times`, one panel per model
    (`bins`: title -> its bins.csv); times with an unchanged distribution share one curve."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(bins), figsize=(4.4 * len(bins), 4.3), sharex=True, sharey=True, squeeze=False)
    first = next(iter(bins.values()))
    times = snapshot_times(_column(first, "time"), process)
    shown = []  # diameters (m) where the mass is, for the common x range
    panels = {}
    for title, frame in bins.items():
        t, d, q = (_column(frame, name) for name in BINS_COLUMNS)
        curves = []  # (times, diameters, cumulative)
        for time in times:
            at = np.isclose(t, time, rtol=0.0, atol=1e-9 * max(1.0, abs(time)))
            if not at.any():
                continue  # a run that ended early shows what it has
            order = np.argsort(d[at])
            dd, cum = cumulative_undersize(d[at][order], q[at][order])
            if curves and len(curves[-1][1]) == len(dd) and np.allclose(curves[-1][2], cum, atol=0.2):
                curves[-1][0].append(time)  # unchanged: one curve for both times
                continue
            curves.append(([time], dd, cum))
            inside = (cum > 0.5) & (cum < 99.5)
            shown += list(dd[inside])
        panels[title] = curves
    # the grid runs far beyond the granules: show where the mass is
    xlim = (MM * min(shown) / 1.3, MM * max(shown) * 1.3) if shown else None
    shade = 0.85 / max(1, len(times) - 1)
    for k, (ax, (title, curves)) in enumerate(zip(axes[0], panels.items())):
        drawn = [
            ("t = " + " = ".join(f"{x:g}" for x in ts) + " s", MM * dd, cum, shade * times.index(ts[0]))
            for ts, dd, cum in curves
        ]
        size_distribution(ax, drawn, f"{title}, {rpm} rpm", xlim=xlim)
        if k:
            ax.set_ylabel("")
    fig.tight_layout()
    return fig


def liquid_porosity(speed, process, rpm: str):
    """Mean liquid content L/S (-) and mean porosity (%) against time (s): PBM-DEM replicates
    (band and mean), PBM-ANN ensemble members (band) and ensemble mean, PBM-constant."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    quantities = (
        ("mean_liquid_content", 1.0, "mean liquid content L/S (m3 liquid / m3 solid)"),
        ("mean_porosity", PERCENT, "mean porosity (%)"),
    )
    members = speed.members
    dem = [r.summary for r in speed.dem]
    grid = _column(dem[0], "time")
    ann, con = speed.ann.summary, speed.constant.summary
    t_ann = _column(ann, "time")
    for ax, (column, scale, ylabel) in zip(axes, quantities):
        stack = np.stack([np.interp(grid, _column(s, "time"), _column(s, column)) for s in dem]) * scale
        band = None
        if members is not None and len(members) and column in members.columns:
            per = [g.sort_values("time") for _, g in members.groupby("member")]
            curves = [np.interp(t_ann, g.time, g[column]) for g in per]
            band = (t_ann, np.min(curves, axis=0) * scale, np.max(curves, axis=0) * scale)
        lines = (grid, stack.min(axis=0), stack.max(axis=0), stack.mean(axis=0))
        constant = (_column(con, "time"), scale * _column(con, column))
        _models(ax, process, lines, len(dem), (t_ann, scale * _column(ann, column)), constant, band, len(dem) > 1)
        ax.set(xlabel="time (s)", ylabel=ylabel, title=f"{ylabel.split(' (')[0]}, {rpm} rpm")
        ax.grid(alpha=0.3)
    legend_below(fig, axes[0], 3, 0.12)
    return fig


def collision_frequency(frequencies: pd.DataFrame, pairs: pd.DataFrame, rpm: str):
    """Left: the mean collision frequency per pair of every coupling interval of every model (`frequencies`).
    Right: the surrogate's c_ij against the DEM's on PBM-DEM's samples (`pairs`), those outside its domain marked."""
    plt = pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    groups = list(frequencies.groupby(["model", "run"], sort=False))
    n_dem = sum(model == "PBM-DEM" for (model, _), _ in groups)
    greys = iter(np.linspace(0.0, 0.6, max(n_dem, 1)))
    for (model, run), g in groups:
        g = g.sort_values("t_start")
        style = dict(STYLES[model])
        if model == "PBM-DEM":
            style.update(lw=1.3, color=str(next(greys)))
        edges = np.append(g.t_start.to_numpy(float), g.t_end.to_numpy(float)[-1])
        values = g.mean_frequency_per_pair.to_numpy(float)
        left.stairs(values, edges, baseline=None, **style, label=f"{model}, {run}")
    left.set(
        xlabel="time (s)",
        ylabel="pair-weighted mean c (1/s per pair)",
        title=f"collision frequency per coupling interval, {rpm} rpm",
    )
    left.grid(alpha=0.3)
    left.legend(fontsize=7, loc="best")
    outside = pairs[pairs.out_of_domain] if len(pairs) else pairs
    inside = pairs[~pairs.out_of_domain] if len(pairs) else pairs
    right.loglog(inside.dem, inside.surrogate, "o", color="tab:orange", alpha=0.7, label="inside training domain")
    if len(outside):
        right.loglog(outside.dem, outside.surrogate, "x", color="tab:red", label="outside training domain")
    positive = pairs[(pairs.dem > 0) & (pairs.surrogate > 0)] if len(pairs) else pairs
    if len(positive):
        lo = float(min(positive.dem.min(), positive.surrogate.min()))
        hi = float(max(positive.dem.max(), positive.surrogate.max()))
        right.plot([lo / 1.2, hi * 1.2], [lo / 1.2, hi * 1.2], "k:", lw=1, label="equal")
    samples = pairs.groupby(["replicate", "interval"]).out_of_domain.first() if len(pairs) else pd.Series(dtype=bool)
    right.set(
        xlabel="DEM c_ij (1/s per pair)",
        ylabel="surrogate c_ij, same sample (1/s per pair)",
        title=f"class pairs of the PBM-DEM samples, {rpm} rpm",
    )
    right.text(
        0.02,
        0.98,
        f"surrogate outside its training domain on {int(samples.sum())} of {len(samples)} PBM-DEM samples",
        transform=right.transAxes,
        va="top",
        fontsize=8,
    )
    right.grid(alpha=0.3, which="both")
    log_ticks(right, "xy")
    right.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return fig


def write_speed(*, validation_dir, rpm: str, replicates: int, process: dict, bands, model, out: dict) -> None:
    """The figures and the out-of-domain table of one validation speed. `out`: sizes, psd, liquid,
    frequency (PNG), domain_csv, domain_html."""
    process = ProcessSettings.from_dict(process, "pbm.process")
    speed = load_speed(validation_dir, rpm, replicates)
    shown = {"PBM-DEM replicate 0": speed.dem[0], "PBM-ANN": speed.ann, "PBM-constant": speed.constant}
    for name, run in {**{f"PBM-DEM replicate {k}": r for k, r in enumerate(speed.dem)}, **shown}.items():
        require_columns(run.summary, SUMMARY_COLUMNS, f"{name} summary", run.folder / "summary.csv")
    band_table = read_table(bands, "bands table", columns=BANDS_COLUMNS)
    save_figure(size_bands(band_table, process, rpm, what=f"bands table {bands}"), out["sizes"])
    bins = {
        name: read_table(run.folder / "bins.csv", f"{name} bins table", columns=BINS_COLUMNS, finite=BINS_COLUMNS)
        for name, run in shown.items()
    }
    save_figure(psd_evolution(bins, process, rpm), out["psd"])
    save_figure(liquid_porosity(speed, process, rpm), out["liquid"])
    frequency = interval_frequencies(speed)
    pairs = surrogate_on_dem_samples(speed, load_surrogate(model))
    save_figure(collision_frequency(frequency, pairs, rpm), out["frequency"])
    domain = out_of_domain(speed)
    write_titled_table(
        out["domain_csv"],
        out["domain_html"],
        domain,
        "out_of_domain",
        {"rpm": rpm},
        out_of_domain_sentence(rpm, domain),
        keys=2,
    )
