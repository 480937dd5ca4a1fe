"""Contour maps of the design space: one column per value of the third factor; the top row d50
with the specification status of every grid point, the bottom row d90 with the width of the
surrogate's uncertainty band of d50."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.config import Specification
from pbmdem.plotting import ML_PER_MIN, pyplot, save_figure

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
    """The maps of `table` (`space.design_space`) as a PNG at `path`."""
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
