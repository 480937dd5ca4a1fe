"""The files of a calibration (`pbmdem calibrate`, rule calibration_check), of the design space and
of the sensitivity analysis: tables as CSV, a JSON of the figures of merit, and their figures; all
written atomically."""

from __future__ import annotations

import logging
from pathlib import Path

import pandas as pd

from pbmdem.atomic import write_csv, write_json
from pbmdem.plotting import pyplot, save_figure

from .calibration import Estimate
from .proof import calibration_check
from .sensitivity import plot_sensitivity, sensitivity
from .space import design_space, plot_design_space

MARKERS = {"d10": "^", "d50": "o", "d90": "s"}
COLORS = {"d10": "tab:blue", "d50": "tab:green", "d90": "tab:purple"}


def estimate_summary(estimate: Estimate) -> dict:
    """The JSON form of a calibration: estimates with intervals, correlation, non-identifiable
    pairs and the optimiser's figures."""
    return {
        "parameters": estimate.table.to_dict(orient="records"),
        "correlation": estimate.correlation.to_dict(),
        "unidentifiable_pairs": [{"a": a, "b": b, "correlation": r} for a, b, r in estimate.unidentifiable],
        **{k: v for k, v in estimate.info.items() if k != "message"},
        "optimizer_message": estimate.info.get("message", ""),
    }


def write_estimate(estimate: Estimate, outdir: str | Path, title: str = "calibration") -> None:
    """estimates.csv, correlation.csv, residuals.csv, calibration.json and fit.png in `outdir`."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    write_csv(outdir / "estimates.csv", estimate.table)
    write_csv(outdir / "correlation.csv", estimate.correlation.rename_axis("parameter").reset_index())
    write_csv(outdir / "residuals.csv", estimate.residuals)
    write_json(outdir / "calibration.json", estimate_summary(estimate))
    plot_fit({title: estimate.residuals}, outdir / "fit.png")


def plot_fit(cases: dict[str, pd.DataFrame], path: str | Path) -> None:
    """Measured d10/d50/d90 with their sd (error bars) and the fitted model, one row per case
    (name -> residual table), one column per impeller speed."""
    plt = pyplot()

    n_cols = max(frame.rpm.nunique() for frame in cases.values())
    fig, axes = plt.subplots(len(cases), n_cols, figsize=(3.6 * n_cols, 3.2 * len(cases)), squeeze=False)
    for row, (name, frame) in enumerate(cases.items()):
        for col, (rpm, at_rpm) in enumerate(frame.groupby("rpm")):
            ax = axes[row, col]
            for stat, sel in at_rpm.groupby("statistic"):
                ax.errorbar(
                    sel.time,
                    1e3 * sel.measured,
                    yerr=1.96e3 * sel.sd,
                    fmt=MARKERS.get(stat, "o"),
                    color=COLORS.get(stat),
                    ms=4,
                    capsize=2,
                    label=f"{stat} measured (95 %)",
                )
                ax.plot(sel.time, 1e3 * sel.model, "-", color=COLORS.get(stat), lw=1.2, label=f"{stat} fitted")
            ax.set_title(f"{name}: {rpm:g} rpm", fontsize=9)
            ax.set_xlabel("time (s)")
            ax.set_ylabel("size (mm)")
        for col in range(frame.rpm.nunique(), n_cols):
            axes[row, col].axis("off")
    axes[0, 0].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    save_figure(fig, path)


def write_design_space(loop, model_path, design, table_path, maps_path, info_path) -> pd.DataFrame:
    """Rule design_space: the design-space table (CSV), its maps (PNG) and its figures of merit
    (JSON: batches, wall time, processes, points of each status)."""
    table, info = design_space(loop, model_path, design)
    write_csv(table_path, table)
    plot_design_space(table, design.third_factor.key, design.specification, maps_path)
    write_json(
        info_path, {**info, "specification": design.specification.to_dict(), "third_factor": design.third_factor.key}
    )
    return table


def write_sensitivity(loop, model_path, settings, table_path, figure_path, info_path) -> pd.DataFrame:
    """Rule sensitivity: the Sobol' indices (CSV), their bars (PNG) and the figures of merit (JSON:
    factors, batches, wall time, samples out of the training domain or failed)."""
    table, info = sensitivity(loop, model_path, settings)
    write_csv(table_path, table)
    plot_sensitivity(table, figure_path, settings.confidence)
    write_json(info_path, {**info, "confidence": settings.confidence, "seed": settings.seed})
    return table


def write_calibration_check(loop, model_path, validation_dir, rpms, replicates, settings, n_jobs, out: dict):
    """Rule calibration_check: the recovery table, the fit figure, PBM-DEM's measured table and each
    case's calibration summary (JSON). `out`: table, figure, measured, summary."""
    table, estimates, data = calibration_check(loop, model_path, validation_dir, rpms, replicates, settings, n_jobs)
    write_csv(out["table"], table)
    write_csv(out["measured"], data["pbm_dem"])
    plot_fit({case: est.residuals for case, est in estimates.items()}, out["figure"])
    write_json(out["summary"], {case: estimate_summary(est) for case, est in estimates.items()})
    log = logging.getLogger(__name__)
    for row in table.to_dict(orient="records"):
        log.log(
            logging.INFO if row["recovered"] else logging.WARNING,
            "calibration check %s: %s true %.4g, estimate %.4g, %g %% interval [%.4g, %.4g]: %s",
            row["case"],
            row["parameter"],
            row["true"],
            row["estimate"],
            100 * settings.confidence,
            row["ci_low"],
            row["ci_high"],
            "recovered" if row["recovered"] else "NOT recovered",
        )
    return table
