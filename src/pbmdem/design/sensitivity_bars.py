"""The figure of the global sensitivity analysis: one panel per output (d10, d50, d90), a pair of
bars per factor: the total index ST and the first-order index S1 of the ensemble mean with their
confidence intervals, and each ensemble member's index as a dot on its bar (their spread is how
much of the answer the surrogate's uncertainty could change)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.plotting import pyplot, save_figure

from .batches import STATISTICS
from .sensitivity import label

#: colour of each index's bar
COLORS = {"ST": "#4575b4", "S1": "#fdae61"}


def plot_sensitivity(table: pd.DataFrame, path: str | Path, confidence: float) -> None:
    """The bars of `table` (`sensitivity.COLUMNS`) as a PNG at `path`."""
    plt = pyplot()

    outputs = [s for s in STATISTICS if s in set(table.output)]
    params = list(dict.fromkeys(table.parameter))
    fig, axes = plt.subplots(1, len(outputs), figsize=(4.2 * len(outputs) + 0.6, 4.6), squeeze=False, sharey=True)
    x = np.arange(len(params))
    width = 0.38
    for ax, output in zip(axes[0], outputs):
        rows = table[table.output == output]
        mean = rows[rows.member.astype(str) == "mean"].set_index("parameter").reindex(params)
        members = rows[rows.member.astype(str) != "mean"]
        for offset, index in ((-width / 2, "ST"), (width / 2, "S1")):
            ax.bar(
                x + offset,
                mean[index].to_numpy(float),
                width,
                yerr=mean[f"{index}_conf"].to_numpy(float),
                color=COLORS[index],
                capsize=3,
                label=f"{index} (mean; bars {100 * confidence:g} %)",
            )
            for k, p in enumerate(params):
                values = members.loc[members.parameter == p, index].to_numpy(float)
                ax.scatter(
                    np.full(values.size, x[k] + offset),
                    values,
                    s=12,
                    color="black",
                    zorder=5,
                    label="members" if (k == 0 and index == "ST") else None,
                )
        ax.axhline(0.0, color="0.4", lw=0.8)
        ax.set_xticks(x, [label(p) for p in params], rotation=30, ha="right", fontsize=8)
        ax.set_title(f"final {output}")
        ax.grid(alpha=0.3, axis="y")
    axes[0, 0].set_ylabel("Sobol' index (share of the variance)")
    axes[0, 0].legend(fontsize=7, loc="upper left")
    fig.suptitle("Global sensitivity of PBM-ANN's final granule size (ST total, S1 first order)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
