"""Parity plot of held-out encounter-frequency predictions (DEM vs model, log-log, coloured by impeller speed)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.plotting import log_ticks, pyplot, save_figure

from .features import TARGET_NAME

MODEL_LABELS = {
    "mlp": "MLP ensemble (ANN)",
    "kriging": "Kriging",
    "rsm": "response surface",
    "hgb": "gradient boosting",
    "physical": "physical scaling",
}


def _square_log_axes(ax, lo: float, hi: float) -> None:
    """Log-log parity axes with the same range on both."""
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_aspect("equal")
    log_ticks(ax, "xy")


def parity_plot(
    predictions: pd.DataFrame,
    path: str | os.PathLike,
    metrics: pd.DataFrame | None = None,
    models=tuple(MODEL_LABELS),
    dpi: int = 120,
) -> Path:
    """Write a PNG with one panel per model: held-out DEM vs predicted frequency per pair."""
    plt = pyplot()
    models = [m for m in models if f"{m}_log10" in predictions]
    obs = 10.0 ** predictions[TARGET_NAME].to_numpy(float)
    rpms = np.sort(predictions["rpm"].unique())
    cmap = plt.get_cmap("viridis")
    colours = {r: cmap(0.1 + 0.8 * k / max(1, len(rpms) - 1)) for k, r in enumerate(rpms)}
    all_pred = np.concatenate([10.0 ** predictions[f"{m}_log10"].to_numpy(float) for m in models])
    lo = np.nanmin(np.concatenate([obs, all_pred])) / 1.5
    hi = np.nanmax(np.concatenate([obs, all_pred])) * 1.5

    vel_models = [m for m in models if f"{m}_velocity_mu_log10" in predictions]
    n_rows = 2 if vel_models else 1
    fig, axes = plt.subplots(
        n_rows, len(models), figsize=(3.6 * len(models), 4.0 * n_rows), squeeze=False, layout="constrained"
    )
    for ax in axes[1][len(vel_models) :] if vel_models else []:
        ax.axis("off")
    for ax, m in zip(axes[1] if vel_models else [], vel_models):
        _velocity_panel(ax, m, predictions, rpms, colours, metrics)
    for ax, m in zip(axes[0], models):
        pred = 10.0 ** predictions[f"{m}_log10"].to_numpy(float)
        for r in rpms:
            sel = predictions["rpm"].to_numpy() == r
            if f"{m}_std_log10" in predictions:
                s = predictions[f"{m}_std_log10"].to_numpy(float)[sel]
                yerr = np.vstack([pred[sel] * (1 - 10.0**-s), pred[sel] * (10.0**s - 1)])
                ax.errorbar(
                    obs[sel],
                    pred[sel],
                    yerr=yerr,
                    fmt="o",
                    ms=4,
                    color=colours[r],
                    ecolor=colours[r],
                    elinewidth=0.8,
                    alpha=0.85,
                    label=f"{r:g} rpm",
                )
            else:
                ax.plot(obs[sel], pred[sel], "o", ms=4, color=colours[r], alpha=0.85, label=f"{r:g} rpm")
        ax.plot([lo, hi], [lo, hi], "k-", lw=0.8)
        ax.plot([lo, hi], [2 * lo, 2 * hi], "k:", lw=0.6)
        ax.plot([lo, hi], [lo / 2, hi / 2], "k:", lw=0.6)
        _square_log_axes(ax, lo, hi)
        ax.set_xlabel("DEM encounter frequency per pair (1/s)")
        ax.set_ylabel("predicted (held-out runs) (1/s)" + (", +-1 std" if f"{m}_std_log10" in predictions else ""))
        title = MODEL_LABELS.get(m, m)
        if metrics is not None:
            row = metrics[(metrics["model"] == m) & (metrics["fold"] == "pooled")]
            if "target" in row:
                row = row[row["target"] == "encounter_frequency"]
            if len(row):
                title += f"\nR2(log10) {row['r2_log10'].iloc[0]:.3f}, MAE {row['mae_log10'].iloc[0]:.3f} dec"
                if "noise_floor_r2_log10" in row and np.isfinite(row["noise_floor_r2_log10"].iloc[0]):
                    title += f"\n(replicate noise floor R2 {row['noise_floor_r2_log10'].iloc[0]:.3f})"
        ax.set_title(title, fontsize=10)
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
    axes[0][0].legend(title="impeller", fontsize=8, loc="upper left")
    fig.suptitle(
        "Grouped cross-validation: each point predicted by models that never saw its DEM run (dotted: factor 2)",
        fontsize=10,
    )

    return save_figure(fig, path, dpi=dpi)


def _velocity_panel(ax, m: str, predictions: pd.DataFrame, rpms, colours: dict, metrics) -> None:
    """Model `m`'s held-out median impact speed against the DEM's, one colour per impeller speed."""
    sel_v = predictions[f"{m}_velocity_mu_log10"].notna().to_numpy()
    obs_v = 10.0 ** predictions["velocity_mu_log10"].to_numpy(float)
    pred_v = 10.0 ** predictions[f"{m}_velocity_mu_log10"].to_numpy(float)
    both = np.concatenate([obs_v[sel_v], pred_v[sel_v]])
    vlo, vhi = np.nanmin(both) / 1.5, np.nanmax(both) * 1.5
    for r in rpms:
        sel = sel_v & (predictions["rpm"].to_numpy() == r)
        ax.plot(obs_v[sel], pred_v[sel], "o", ms=4, color=colours[r], alpha=0.85, label=f"{r:g} rpm")
    ax.plot([vlo, vhi], [vlo, vhi], "k-", lw=0.8)
    _square_log_axes(ax, vlo, vhi)
    ax.set_xlabel("DEM median impact speed (m/s, log-normal fit)")
    ax.set_ylabel("predicted (held-out runs) (m/s)")
    title = f"{MODEL_LABELS.get(m, m)}: impact speed"
    if metrics is not None and "target" in metrics:
        row = metrics[
            (metrics["model"] == m) & (metrics["fold"] == "pooled") & (metrics["target"] == "impact_velocity")
        ]
        if len(row):
            title += (
                f"\nR2(log10) {row['r2_log10'].iloc[0]:.3f}, MAE {row['mae_log10'].iloc[0]:.3f} dec, "
                f"TV distance {row['tv_distance'].iloc[0]:.3f}"
            )
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", lw=0.3, alpha=0.5)


def empty_plot(path: str | os.PathLike, message: str) -> Path:
    """A placeholder PNG with a message (e.g. when no held-out evaluation was possible)."""
    fig, ax = pyplot().subplots(figsize=(5, 2))
    ax.axis("off")
    ax.text(0.5, 0.5, message, ha="center", va="center")
    return save_figure(fig, path, dpi=100)
