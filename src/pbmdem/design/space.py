"""The design space: PBM-ANN's final d10/d50/d90 over impeller speed x binder rate x a third
factor, with the ensemble members' band, each point's status against the specification
(`STATUSES`; docs/design.md, "The grid" and "The specification region") and its contour maps.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.config import CoupledLoop, DesignSpace, Specification
from pbmdem.coupling.lumping import LIQUID_KEY
from pbmdem.plotting import ML_PER_MIN, pyplot, save_figure
from pbmdem.surrogate import load_surrogate

from .batches import STATISTICS, Case, outcomes_table, run_cases

log = logging.getLogger(__name__)

STATUSES = ("meets", "uncertain", "fails", "out_of_domain", "failed")


def grid_cases(design: DesignSpace, n_members: int) -> list[Case]:
    """The cases of the design space: every speed x binder rate x third-factor value, each with the
    ensemble mean and every member."""
    cases = []
    for third in design.third_factor.values:
        for rate in design.liquid_rate.values():
            for rpm in design.impeller_rpm.values():
                values = ((LIQUID_KEY, rate), (design.third_factor.key, float(third)))
                cases += [Case(rpm, values, member) for member in (None, *range(n_members))]
    return cases


def point_table(outcomes: pd.DataFrame, third_key: str) -> pd.DataFrame:
    """One row per grid point from the table of its cases (`batches.outcomes_table`), the members'
    range of each size, the most out-of-domain intervals of any of its cases and its failed cases."""
    keys = ["rpm", LIQUID_KEY, third_key]
    rows = []
    for (rpm, rate, third), group in outcomes.groupby(keys, sort=False):
        mean = group[group.member < 0].iloc[0]
        members = group[group.member >= 0]
        row = {"rpm": rpm, "liquid_rate": rate, third_key: third}
        for s in STATISTICS:
            row[s] = mean[s]
            values = members[s].to_numpy(float)
            ok = np.isfinite(values)
            row[f"{s}_member_min"] = float(values[ok].min()) if ok.any() else float("nan")
            row[f"{s}_member_max"] = float(values[ok].max()) if ok.any() else float("nan")
        row["out_of_domain_intervals"] = int(group.out_of_domain_intervals.max())
        row["failed_cases"] = int((group.failed.astype(str) != "").sum())
        row["members"] = len(members)
        rows.append(row)
    return pd.DataFrame(rows)


def specification_status(table: pd.DataFrame, spec: Specification) -> pd.Series:
    """The status of every point of `table` (columns of `point_table`) against `spec`."""
    d50_min = -np.inf if spec.d50_min is None else spec.d50_min
    d50_max = np.inf if spec.d50_max is None else spec.d50_max
    d90_max = np.inf if spec.d90_max is None else spec.d90_max
    lo50, hi50 = table.d50_member_min.to_numpy(float), table.d50_member_max.to_numpy(float)
    lo90, hi90 = table.d90_member_min.to_numpy(float), table.d90_member_max.to_numpy(float)
    # the whole band meets it; or some part of it: an interval of d50 that overlaps the range, the lowest d90
    robust = (lo50 >= d50_min) & (hi50 <= d50_max) & (hi90 <= d90_max)
    possible = (hi50 >= d50_min) & (lo50 <= d50_max) & (lo90 <= d90_max)
    d50, d90 = table.d50.to_numpy(float), table.d90.to_numpy(float)
    possible |= (d50 >= d50_min) & (d50 <= d50_max) & (d90 <= d90_max)
    status = np.where(robust, "meets", np.where(possible, "uncertain", "fails"))
    status = np.where(table.out_of_domain_intervals.to_numpy() > 0, "out_of_domain", status)
    status = np.where(table.failed_cases.to_numpy() > 0, "failed", status)
    return pd.Series(status, index=table.index, name="spec_status")


def design_space(loop: CoupledLoop, model_path: str | Path, design: DesignSpace) -> tuple[pd.DataFrame, dict]:
    """The design-space table (one row per grid point, with `spec_status`) and its figures of
    merit: the batches run, their wall time and the points of each status."""
    n_members = load_surrogate(model_path).n_members
    cases = grid_cases(design, n_members)
    t0 = time.perf_counter()
    outcomes = run_cases(loop, model_path, cases, design.n_jobs)
    wall = time.perf_counter() - t0
    table = point_table(outcomes_table(outcomes), design.third_factor.key)
    table["spec_status"] = specification_status(table, design.specification)
    counts = {s: int((table.spec_status == s).sum()) for s in STATUSES}
    per_minute = 60.0 * len(cases) / wall if wall > 0 else float("nan")
    info = {
        "batches": len(cases),
        "wall_time_s": wall,
        "batches_per_minute": per_minute,
        "n_jobs": design.n_jobs,
        "points": len(table),
        **counts,
    }
    log.info(
        "design space: %(batches)d PBM-ANN batches (%(points)d points x (mean + %(members)d members)) in "
        "%(wall_time_s).1f s on %(n_jobs)d process(es), %(batches_per_minute).0f batches per minute: %(statuses)s",
        {**info, "members": n_members, "statuses": ", ".join(f"{v} {k}" for k, v in counts.items())},
    )
    if counts["out_of_domain"]:
        log.warning(
            "design space: at %d of %d points the surrogate was evaluated outside its training domain; they are "
            "marked out_of_domain and not judged against the specification",
            counts["out_of_domain"],
            len(table),
        )
    if counts["failed"]:
        log.warning("design space: the PBM failed at %d of %d points (marked failed)", counts["failed"], len(table))
    return table, info


#: marker and colour of each specification status
STYLE = {
    "meets": ("o", "#1a9850", "meets (whole band)"),
    "uncertain": ("D", "#fdae61", "uncertain (band straddles a limit)"),
    "fails": ("s", "#d73027", "fails"),
    "out_of_domain": ("x", "black", "outside the training domain"),
    "failed": ("*", "purple", "PBM failed"),
}


def _grid(panel: pd.DataFrame, column: str):
    x = np.sort(panel.rpm.unique())
    y = np.sort(panel.liquid_rate.unique())
    z = panel.pivot_table(index="liquid_rate", columns="rpm", values=column, dropna=False).reindex(index=y, columns=x)
    return x, ML_PER_MIN * y, z.to_numpy(float)  # binder rate in mL/min


def _levels(values: pd.Series) -> np.ndarray:
    finite = 1e3 * values[np.isfinite(values)]
    if finite.empty or finite.max() <= finite.min():
        return np.linspace(0.0, 1.0, 13) if finite.empty else np.linspace(finite.min() * 0.99, finite.max() * 1.01, 13)
    return np.linspace(finite.min(), finite.max(), 13)


def _spec_text(spec: Specification) -> str:
    parts = []
    if spec.d50_min is not None or spec.d50_max is not None:
        lo = "" if spec.d50_min is None else f"{1e3 * spec.d50_min:g} mm <= "
        hi = "" if spec.d50_max is None else f" <= {1e3 * spec.d50_max:g} mm"
        parts.append(f"{lo}d50{hi}")
    if spec.d90_max is not None:
        parts.append(f"d90 <= {1e3 * spec.d90_max:g} mm")
    return ", ".join(parts) or "no specification"


def plot_design_space(table: pd.DataFrame, third_key: str, spec: Specification, path: str | Path) -> None:
    """The contour maps of `table` (`design_space`) as a PNG at `path` (docs/design.md, "Outputs")."""
    plt = pyplot()

    thirds = sorted(table[third_key].unique())
    fig, axes = plt.subplots(2, len(thirds), figsize=(4.2 * len(thirds) + 1, 7.5), squeeze=False)
    label = third_key.split(".")[-1].replace("_", " ")
    # one colour scale per row across the panels, so that the panels compare by eye
    levels = {s: _levels(table[s]) for s in ("d50", "d90")}
    for col, third in enumerate(thirds):
        panel = table[table[third_key] == third]
        x, y, d50 = _grid(panel, "d50")
        _, _, d90 = _grid(panel, "d90")
        _, _, lo = _grid(panel, "d50_member_min")
        _, _, hi = _grid(panel, "d50_member_max")
        top, bottom = axes[0, col], axes[1, col]
        # contours need two values on each axis and a finite value; the markers are always drawn
        contours = min(d50.shape) >= 2 and np.isfinite(d50).any()
        if contours:
            filled = top.contourf(x, y, 1e3 * d50, levels=levels["d50"], cmap="viridis", extend="both")
            fig.colorbar(filled, ax=top, label="d50 (mm), ensemble mean")
        for status, (marker, color, text) in STYLE.items():
            sel = panel[panel.spec_status == status]
            top.scatter(sel.rpm, ML_PER_MIN * sel.liquid_rate, marker=marker, color=color, s=28, label=text)
        top.set_title(f"{label} = {third:g}")
        if contours and np.isfinite(d90).any():
            filled = bottom.contourf(x, y, 1e3 * d90, levels=levels["d90"], cmap="magma", extend="both")
            fig.colorbar(filled, ax=bottom, label="d90 (mm), ensemble mean")
        width = np.where(d50 > 0, (hi - lo) / d50, np.nan)
        if contours and np.isfinite(width).sum() >= 4:
            lines = bottom.contour(x, y, 100 * width, levels=5, colors="white", linewidths=0.8)
            bottom.clabel(lines, fmt="%.0f %%", fontsize=7)
        for ax in (top, bottom):
            ax.set_xlabel("impeller speed (rpm)")
            ax.set_ylabel("binder rate (mL/min)")
    axes[0, 0].legend(fontsize=7, loc="upper left", framealpha=0.8)
    fig.suptitle(
        f"PBM-ANN design space: specification {_spec_text(spec)}; white lines (bottom): width of the members' "
        "d50 band, % of d50",
        fontsize=9,
    )
    fig.tight_layout()
    save_figure(fig, path)
