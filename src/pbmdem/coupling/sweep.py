"""The PBM-ANN impeller-speed sweep: final sizes against speed, grid speeds and speeds between."""

from __future__ import annotations

import logging
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.atomic import write_csv
from pbmdem.config import CoupledLoop, Sweep
from pbmdem.plotting import final_sizes, pyplot, save_figure
from pbmdem.readers import read_table
from pbmdem.tables import INTERVALS

from .methods import pbm_ann

#: the columns of a PBM-ANN run's summary.csv the sweep reports
SUMMARY_COLUMNS = ("time", "d10", "d50", "d90", "number_mean_diameter", "mass_mean_diameter", "total_number")

log = logging.getLogger(__name__)


def rpm_sweep(
    loop: CoupledLoop, sweep: Sweep, model_path: str | Path, table_path: str | Path, plot_path: str | Path
) -> pd.DataFrame:
    """PBM-ANN at every speed of `sweep`: final d10/d50/d90 and mean diameters (table), and the
    d50(t) curves and final sizes against speed (plot)."""
    speeds = sweep.speeds()
    rows, curves = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for rpm in speeds:
            folder = Path(tmp) / f"rpm{rpm:g}"
            t0 = time.perf_counter()
            outcome = pbm_ann(loop, model_path, rpm, folder)
            wall = time.perf_counter() - t0
            summary = read_table(
                folder / "summary.csv", "PBM-ANN summary", columns=SUMMARY_COLUMNS, finite=SUMMARY_COLUMNS
            )
            ood = INTERVALS.read(folder / "intervals.csv").get("out_of_domain_count", pd.Series([0]))
            last = summary.iloc[-1]
            rows.append(
                {
                    "rpm": float(rpm),
                    **{column: last[column] for column in SUMMARY_COLUMNS[1:]},  # the final values
                    "wall_time_s": wall,
                    "out_of_domain_intervals": int((ood.fillna(0) > 0).sum()),
                    "out_of_domain_count": int(ood.fillna(0).sum()),
                    # breakage fragments merged at the grid floor, share of the final number (Result.grid_floor)
                    "merged_fraction": float(outcome.totals["grid_floor"]["merged_fraction"]),
                }
            )
            curves.append((rpm, summary.time.to_numpy(), summary.d50.to_numpy()))
            log.info(
                "rpm sweep: %g rpm done (%d of %d) in %.2f s; final d50 %.4g m; surrogate out of its "
                "training domain in %d interval(s)",
                rpm,
                len(rows),
                len(speeds),
                wall,
                last.d50,
                rows[-1]["out_of_domain_intervals"],
            )
    table = pd.DataFrame(rows)
    write_csv(table_path, table)
    plot_sweep(table, curves, plot_path)
    return table


def plot_sweep(table: pd.DataFrame, curves: list, path: str | Path) -> None:
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    cmap = plt.get_cmap("viridis")
    for k, (rpm, t, d50) in enumerate(curves):
        ax1.plot(t, 1e3 * np.asarray(d50), color=cmap(k / max(1, len(curves) - 1)), label=f"{rpm:g} rpm")
    ax1.set_xlabel("time (s)")
    ax1.set_ylabel("d50 (mm)")
    ax1.set_title("PBM-ANN: d50 over the batch")
    ax1.legend(fontsize=7, ncol=2)
    final_sizes(ax2, table.rpm, table)
    ax2.set_ylim(bottom=0.0)
    ax2.set_title("PBM-ANN: final sizes vs impeller speed")
    ax2.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    save_figure(fig, path)
