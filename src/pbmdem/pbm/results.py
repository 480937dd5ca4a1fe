"""PBM results: time series, size statistics, tidy tables, plots, atomic saving.

Size statistics use the solid-volume-equivalent pivot diameters d_k. The mass (solid-volume)
distribution puts the bin's solid N_k x_k between the diameter edges of the bin (geometric
midpoints of neighbouring pivot diameters); its cumulative Q3 is piecewise linear in ln d
between edges, and d10/d50/d90 are read from it. Number-mean diameter sum N_k d_k / sum N_k;
mass-mean diameter sum N_k x_k d_k / sum N_k x_k. Mean liquid content sum L / sum S (liquid
volume per solid volume); mean porosity sum G / (sum S + sum G).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from pbmdem.atomic import write_csv, write_json
from pbmdem.plotting import pyplot, save_figure, size_distribution

from .grid import Grid
from .state import State, surface_fraction

if TYPE_CHECKING:
    import pandas as pd


#: share of a batch's final number of granules merged at the grid floor above which it is flagged
FLOOR_LIMIT = 0.01


def grid_floor(state: State, grid: Grid) -> dict:
    """The breakage fragments smaller than the first pivot x_0 merged into it by ``state``'s time,
    from the batch's start (the grid floor; each counted once, at its birth from a granule above
    the floor: a granule at x_0 does not break): ``merged_number`` fragments carrying
    ``merged_volume`` m3 of solid, counted as merged_volume / x_0 granules of x_0, so that
    ``lost_number`` granules are missing from the population; ``merged_fraction`` = merged_number
    / the final number of granules (cumulative: above 1 where merged granules aggregate and break
    again), ``flagged`` when it exceeds FLOOR_LIMIT (1 %), ``floor_diameter`` d_0 (m)."""
    total = float(np.sum(state.number))
    n, v = float(state.merged_number), float(state.merged_volume)
    fraction = n / total if total > 0 else (0.0 if n == 0 else float("inf"))
    return {
        "merged_number": n,
        "merged_volume": v,
        "lost_number": max(n - v / float(grid.x[0]), 0.0),
        "final_number": total,
        "merged_fraction": fraction,
        "flagged": bool(fraction > FLOOR_LIMIT),
        "floor_diameter": float(grid.d[0]),
    }


def floor_words(floor: dict, what: str) -> str:
    """One line on the grid floor (:func:`grid_floor`) of the batch ``what``: 'clipping: none in
    <what>', or the fragments merged at the floor, their share of the final number (FLAGGED above
    FLOOR_LIMIT), the granules lost and the solid kept there."""
    if floor["merged_number"] <= 0:
        return f"clipping: none in {what} (no breakage fragment below the grid floor)"
    flag = f" (FLAGGED: above {100 * FLOOR_LIMIT:g} %)" if floor["flagged"] else ""
    return (
        f"clipping: {floor['merged_number']:.4g} breakage fragments merged at the grid floor "
        f"({1e3 * floor['floor_diameter']:.3g} mm) in {what}, {100 * floor['merged_fraction']:.3g} % of its final "
        f"number of granules{flag}; {floor['lost_number']:.4g} granules lost, {floor['merged_volume']:.4g} m3 of "
        "solid kept at the floor"
    )


def cumulative_mass(mass, scale: float = 1.0) -> np.ndarray:
    """The mass finer than each bin's upper edge as ``scale`` x its share of the total (1: fractions,
    100: %), along the last axis of ``mass`` (..., K), the solid per bin; 0 where there is no mass.
    The one cumulative distribution of :func:`mass_quantiles`, psd.png and the report's figure."""
    m = np.asarray(mass, float)
    total = m.sum(axis=-1, keepdims=True)
    return np.divide(scale * np.cumsum(m, axis=-1), total, out=np.zeros(m.shape), where=total > 0)


def mass_quantiles(mass: np.ndarray, d_edges: np.ndarray, q=(0.1, 0.5, 0.9)) -> np.ndarray:
    """Diameters below which fractions ``q`` of the solid lie; ``mass`` (T, K) or (K,) (NaN for a
    row without solid). Log-linear in d inside the bin where the cumulative distribution reaches q."""
    m = np.atleast_2d(np.asarray(mass, float))
    T, K = m.shape
    C = np.empty((T, K + 1))
    C[:, 0] = 0.0
    C[:, 1:] = cumulative_mass(m)
    C[:, -1] = 1.0
    qs = np.asarray(q, float)
    # the first edge k with C[k] >= q (searchsorted "left" of each row, C non-decreasing), in 1..K
    k = np.clip((C[:, :, None] < qs).sum(axis=1), 1, K)
    rows = np.arange(T)[:, None]
    lo, hi = C[rows, k - 1], C[rows, k]
    le = np.log(d_edges)
    f = (qs - lo) / (hi - lo)
    out = np.exp(le[k - 1] + f * (le[k] - le[k - 1]))
    out[m.sum(axis=1) <= 0] = np.nan
    return out if np.ndim(mass) == 2 else out[0]


class Result:
    """Time series of a PBM run: ``times`` (T,), ``number``/``liquid``/``gas`` (T, K) per bin,
    ``state`` (the final, resumable :class:`State`) and ``info`` (run metadata). A run of the
    two-dimensional model also sets ``classes`` (T, 3, Mx, J) and ``class_volumes`` (Mx,)."""

    classes: np.ndarray | None = None
    class_volumes: np.ndarray | None = None

    def __init__(self, grid: Grid, records, state: State, info: dict):
        self.grid = grid
        self.times = np.asarray(records.times, float)
        self.number = np.asarray(records.number, float)
        self.liquid = np.asarray(records.liquid, float)
        self.gas = np.asarray(records.gas, float)
        self.liquid_added = np.asarray(records.liquid_added, float)
        self.refused_volume = np.asarray(records.refused, float)
        self.steps = np.asarray(records.steps, int)
        # breakage fragments merged into the first pivot so far and their solid (m3; State)
        self.merged_number = np.asarray(records.merged_number, float)
        self.merged_volume = np.asarray(records.merged_volume, float)
        self.state = state
        self.info = dict(info)

    @classmethod
    def concat(cls, results: list[Result]) -> Result:
        """Join consecutive runs (e.g. the intervals of a coupled loop); duplicate joint times are
        kept once."""
        first = results[0]

        class _R:
            pass

        rec = _R()
        keep = [np.ones(first.times.size, bool)] + [r.times > prev.times[-1] for prev, r in zip(results, results[1:])]
        for name, attr in (
            ("times", "times"),
            ("number", "number"),
            ("liquid", "liquid"),
            ("gas", "gas"),
            ("liquid_added", "liquid_added"),
            ("refused", "refused_volume"),
            ("steps", "steps"),
            ("merged_number", "merged_number"),
            ("merged_volume", "merged_volume"),
        ):
            setattr(rec, name, np.concatenate([getattr(r, attr)[k] for r, k in zip(results, keep)]))
        classes = None
        if all(getattr(r, "classes", None) is not None for r in results):  # two-dimensional runs
            classes = np.concatenate([r.classes[k] for r, k in zip(results, keep)])
        info = dict(results[-1].info)
        info["steps"] = int(sum(r.info.get("steps", 0) for r in results))
        info["wall_time_s"] = float(sum(r.info.get("wall_time_s", 0.0) for r in results))
        info["segments"] = len(results)
        limits = [r.info["step_limits"] for r in results if isinstance(r.info.get("step_limits"), dict)]
        if limits:
            info["step_limits"] = {k: int(sum(lim.get(k, 0) for lim in limits)) for k in limits[-1]}
        out = cls(first.grid, rec, results[-1].state, info)
        if classes is not None:
            out.classes, out.class_volumes = classes, results[-1].class_volumes
        out.info["grid_floor"] = out.grid_floor()  # the whole batch's (the state's tallies carry over)
        return out

    def grid_floor(self) -> dict:
        """The breakage fragments merged into the first pivot by the end of the run (cumulative
        from the batch's start; :func:`grid_floor`)."""
        return grid_floor(self.state, self.grid)

    # ------------------------------------------------------------- derived quantities
    @property
    def solid(self) -> np.ndarray:
        return self.number * self.grid.x

    def mass_fractions(self) -> np.ndarray:
        S = self.solid
        return S / S.sum(axis=1, keepdims=True)

    def moments(self, orders=(0, 1, 2)) -> np.ndarray:
        """Moments of the number distribution in solid volume, (T, len(orders))."""
        return np.stack([(self.number * self.grid.x**k).sum(axis=1) for k in orders], axis=1)

    def size_quantiles(self) -> np.ndarray:
        """(T, 3) d10, d50, d90 (m) of the mass distribution at the recorded times (the summary's
        columns, without the rest of it: the many batches of the design space read only these)."""
        return mass_quantiles(self.solid, self.grid.d_edges)

    def summary(self) -> pd.DataFrame:
        d = self.grid.d
        N, S, L, G = self.number, self.solid, self.liquid, self.gas
        Ntot, Stot, Ltot, Gtot = N.sum(1), S.sum(1), L.sum(1), G.sum(1)
        q = self.size_quantiles()

        return pd.DataFrame(
            {
                "time": self.times,
                "total_number": Ntot,
                "total_solid_volume": Stot,
                "total_liquid_volume": Ltot,
                "total_gas_volume": Gtot,
                "d10": q[:, 0],
                "d50": q[:, 1],
                "d90": q[:, 2],
                "number_mean_diameter": (N * d).sum(1) / Ntot,
                "mass_mean_diameter": (S * d).sum(1) / Stot,
                "mean_volume": Stot / Ntot,
                "mean_liquid_content": Ltot / Stot,
                "mean_porosity": Gtot / (Stot + Gtot),
                "mean_surface_liquid_fraction": surface_fraction(Stot, Ltot, Gtot),
                "liquid_added": self.liquid_added,
                "refused_solid_volume": self.refused_volume,
                "merged_number": self.merged_number,
                "merged_solid_volume": self.merged_volume,
                "steps": self.steps,
            }
        )

    def bins(self) -> pd.DataFrame:
        """Tidy per-bin table: one row per (time, bin)."""
        T, K = self.number.shape
        S = self.solid
        Stot = S.sum(1, keepdims=True)
        g = self.grid
        dlog = np.log(g.d_edges[1:] / g.d_edges[:-1])
        lc = np.divide(self.liquid, S, out=np.zeros_like(S), where=S > 0)
        eps = np.divide(self.gas, S + self.gas, out=np.zeros_like(S), where=(S + self.gas) > 0)

        return pd.DataFrame(
            {
                "time": np.repeat(self.times, K),
                "bin": np.tile(np.arange(K), T),
                "solid_volume_pivot": np.tile(g.x, T),
                "diameter": np.tile(g.d, T),
                "number": self.number.ravel(),
                "solid_volume": S.ravel(),
                "liquid_volume": self.liquid.ravel(),
                "gas_volume": self.gas.ravel(),
                "mass_fraction": (S / Stot).ravel(),
                "mass_density_lnd": (S / Stot / dlog).ravel(),
                "liquid_content": lc.ravel(),
                "porosity": eps.ravel(),
                "surface_liquid_fraction": surface_fraction(S, self.liquid, self.gas).ravel(),
            }
        )

    def to_frames(self) -> dict[str, pd.DataFrame]:
        return {"summary": self.summary(), "bins": self.bins()}

    # ------------------------------------------------------------- plots and files
    def _where(self) -> str:
        """'600 rpm, feed fine, ann kernel': the run's speed, feed and kernel, as far as recorded."""
        parts = []
        if self.info.get("rpm") is not None:
            parts.append(f"{float(self.info['rpm']):g} rpm")
        if self.info.get("distribution"):
            parts.append(f"feed {self.info['distribution']}")
        if self.info.get("kernel_source"):
            parts.append(f"{self.info['kernel_source']} kernel")
        return ", ".join(parts)

    def plot_psd(self, path=None, n_curves: int = 6, ax=None):
        """Cumulative mass size distribution (mass % finer than d) at up to ``n_curves`` times: smooth
        where the density of the sectional grid zig-zags between neighbouring bins."""
        plt = pyplot()
        own = ax is None
        if own:
            fig, ax = plt.subplots(figsize=(6.4, 4.4), layout="constrained")
        g = self.grid
        cum = cumulative_mass(self.mass_fractions(), 100.0)
        idx = np.unique(np.linspace(0, self.times.size - 1, min(n_curves, self.times.size)).round().astype(int))
        occupied = np.nonzero(self.number.max(axis=0) > 1e-6 * self.number.max())[0]
        lo, hi = occupied.min(), occupied.max()
        curves = [
            (f"t = {self.times[i]:g} s", g.d_edges[1:] * 1e3, cum[i], 0.85 * n / max(1, len(idx) - 1))
            for n, i in enumerate(idx)
        ]
        where = self._where()
        size_distribution(
            ax,
            curves,
            "granule size distribution over the batch" + (f"\n{where}" if where else ""),
            xlim=(g.d_edges[max(lo - 1, 0)] * 1e3, g.d_edges[min(hi + 2, g.bins)] * 1e3),
        )
        if own and path is not None:
            self._savefig(fig, path)
            plt.close(fig)
        return ax

    def plot_sizes(self, path=None):
        """d10/d50/d90, number- and mass-mean diameter, liquid content and porosity vs time."""
        plt = pyplot()
        s = self.summary()
        fig, (a1, a2) = plt.subplots(2, 1, figsize=(6.4, 6.4), sharex=True, layout="constrained")
        for col, style, label in (
            ("d90", "-", "d90 (90 % of the mass finer)"),
            ("d50", "-", "d50 (median by mass)"),
            ("d10", "-", "d10 (10 % of the mass finer)"),
            ("mass_mean_diameter", "--", "mass-mean diameter"),
            ("number_mean_diameter", ":", "number-mean diameter"),
        ):
            a1.plot(s["time"], s[col] * 1e3, style, lw=1.8, label=label)
        a1.set_ylabel("granule diameter (mm)")
        a1.legend(fontsize=7)
        where = self._where()
        a1.set_title("granule sizes over the batch" + (f", {where}" if where else ""), fontsize=10)
        a1.grid(alpha=0.3)
        a2.plot(s["time"], s["mean_liquid_content"], label="liquid / solid volume (mean)")
        a2.plot(s["time"], s["mean_porosity"], label="porosity (mean)")
        a2.plot(s["time"], s["mean_surface_liquid_fraction"], label="surface-liquid fraction (mean)")
        a2.set_xlabel("time (s)")
        a2.set_ylabel("volume ratio or fraction (-)")
        a2.set_title("liquid content and porosity", fontsize=10)
        a2.grid(alpha=0.3)
        a2.legend(fontsize=7)
        if path is not None:
            self._savefig(fig, path)
        plt.close(fig)

    @staticmethod
    def _savefig(fig, path):
        save_figure(fig, path, dpi=120)

    def save(self, outdir) -> dict[str, Path]:
        """Write summary.csv, bins.csv, run.json, psd.png and d50.png into ``outdir`` (atomically)."""
        outdir = Path(outdir)
        paths = {name: write_csv(outdir / f"{name}.csv", frame) for name, frame in self.to_frames().items()}
        paths["info"] = write_json(outdir / "run.json", _jsonable(self.info))
        paths["psd"] = outdir / "psd.png"
        self.plot_psd(paths["psd"])
        paths["d50"] = outdir / "d50.png"
        self.plot_sizes(paths["d50"])
        return paths


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, float) and not np.isfinite(obj):
        return str(obj)
    return obj
