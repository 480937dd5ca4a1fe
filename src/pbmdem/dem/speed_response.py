"""The DEM stage's speed response from the grid's per-replicate tables: whole-bed encounter and
new-contact rates per operating point with replicate standard errors, and the flow-development
check of the two halves of the sampling window (docs/dem.md, "Encounter rate against impeller speed")."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pbmdem.frequency import pair_counts
from pbmdem.plotting import log_ticks, pyplot, save_figure


def _mean_se(frame: pd.DataFrame, keys: list[str], columns: list[str]) -> pd.DataFrame:
    g = frame.groupby(keys, sort=True)
    mean = g[columns].mean()
    n = g.size()
    se = g[columns].std(ddof=1).div(np.sqrt(n), axis=0).add_suffix("_se")
    out = pd.concat([mean, se], axis=1)
    out.insert(0, "n_replicates", n)
    return out.reset_index()


def per_replicate_rates(replicates: pd.DataFrame) -> pd.DataFrame:
    """One row per run (point and replicate) with its whole-bed rates (from per-pair rows)."""
    rows = []
    for (point, rpm, dist, rep), run in replicates.groupby(["point_id", "rpm", "distribution", "replicate"]):
        k = int(max(run.class_i.max(), run.class_j.max())) + 1
        n = np.zeros(k)
        diag = run[run.class_i == run.class_j]
        n[diag.class_i.to_numpy()] = diag.n_i.to_numpy()
        pairs = pair_counts(n)[run.class_i.to_numpy(), run.class_j.to_numpy()].sum()
        t = float(run.sampling_time.iloc[0])
        total = float(n.sum())
        rows.append(
            {
                "point_id": point,
                "rpm": rpm,
                "distribution": dist,
                "replicate": rep,
                "n_particles": total,
                "encounters": float(run.encounters.sum()),
                "collisions": float(run.collisions.sum()),
                "encounters_per_particle_per_s": 2.0 * run.encounters.sum() / (total * t),
                "new_contacts_per_particle_per_s": 2.0 * run.collisions.sum() / (total * t),
                "mean_encounter_frequency_per_pair": run.encounters.sum() / (pairs * t),
                "impact_velocity_median": float(
                    np.average(run.impact_velocity_median.fillna(0.0), weights=run.encounters.clip(lower=1e-12))
                ),
            }
        )
    return pd.DataFrame(rows)


RATE_COLUMNS = [
    "encounters_per_particle_per_s",
    "new_contacts_per_particle_per_s",
    "mean_encounter_frequency_per_pair",
    "impact_velocity_median",
    "n_particles",
]


def speed_response(replicates: pd.DataFrame) -> pd.DataFrame:
    """Replicate mean and standard error of the whole-bed rates per operating point."""
    return _mean_se(per_replicate_rates(replicates), ["distribution", "rpm", "point_id"], RATE_COLUMNS)


def flow_development(runs: pd.DataFrame) -> pd.DataFrame:
    """First vs second half of the sampling window per point: `half_difference` (second / first - 1,
    replicate mean and SE), `half_z` (the halves' difference in combined replicate SE, Poisson for
    one replicate) and `within_error` (|half_z| <= 2)."""
    r = runs.copy()
    r["half_difference"] = r.encounters_second_half / r.encounters_first_half - 1.0
    out = _mean_se(
        r, ["distribution", "rpm", "point_id"], ["half_difference", "encounters_first_half", "encounters_second_half"]
    )
    combined = np.sqrt(out.encounters_first_half_se**2 + out.encounters_second_half_se**2)
    poisson = np.sqrt(out.encounters_first_half + out.encounters_second_half)
    err = combined.where(out.n_replicates > 1, poisson)
    out["half_z"] = (out.encounters_second_half - out.encounters_first_half) / err
    out["within_error"] = out.half_z.abs() <= 2.0
    return out


def plot_speed_response(response: pd.DataFrame, path) -> None:
    """Encounters per particle and second against impeller speed, one line per feed run at
    several speeds, with replicate standard errors; the raw new-contact rate on a second panel.
    Distributions run at one speed only (the design points) are grey markers: a point, not a speed
    response."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    several = response.groupby("distribution").rpm.transform("nunique") > 1
    single = response[~several]
    columns = ("encounters_per_particle_per_s", "new_contacts_per_particle_per_s")
    for ax, column in zip(axes, columns):
        if len(single):
            ax.plot(single.rpm, single[column], "o", color="0.6", markersize=4, label="single points")
    for dist, g in response[several].groupby("distribution"):
        g = g.sort_values("rpm")
        for ax, column, marker in zip(axes, columns, "os"):
            ax.errorbar(g.rpm, g[column], yerr=g[f"{column}_se"], marker=marker, capsize=3, label=dist)
    axes[0].set(
        xlabel="impeller speed (rpm)",
        ylabel="encounters per particle (1/s)",
        title="encounters (kernel-relevant), mean ± SE",
    )
    axes[1].set(
        xlabel="impeller speed (rpm)", ylabel="new contacts per particle (1/s)", title="raw new contacts (diagnostic)"
    )
    for ax in axes:
        ax.set_xscale("log")
        log_ticks(ax, "x")
        ax.grid(alpha=0.3)
        ax.legend(title="feed")
    fig.tight_layout()
    save_figure(fig, path)


def plot_impact_velocities(velocities: pd.DataFrame, path) -> None:
    """Distribution of impact speeds (all class pairs pooled) per speed, one panel per feed run at
    several speeds (the design points, one speed each, are left out)."""
    plt = pyplot()
    speeds = velocities.groupby("distribution").rpm.nunique()
    feeds = sorted(speeds.index[speeds > 1]) or sorted(speeds.index)
    # at most three panels a row, each as large as a single figure's panel (readable at page width)
    ncols = min(3, len(feeds))
    nrows = -(-len(feeds) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5.0 * ncols, 4.0 * nrows), squeeze=False, sharey=True)
    for ax in axes.ravel()[len(feeds) :]:
        ax.axis("off")
    for ax, dist in zip(axes.ravel(), feeds):
        sub = velocities[velocities.distribution == dist]
        for rpm, g in sub.groupby("rpm"):
            h = g.groupby(["v_lo", "v_hi"])["encounters"].sum().reset_index()
            h = h[h.v_lo > 0]
            total = h.encounters.sum()
            if total <= 0:
                continue
            centre = np.sqrt(h.v_lo * h.v_hi)
            ax.step(centre, h.encounters / total, where="mid", label=f"{rpm:g} rpm")
        ax.set(xscale="log", xlabel="impact speed (m/s)", ylabel="fraction of encounters (-)", title=f"feed {dist}")
        log_ticks(ax, "x")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=9, title="impeller speed")
    fig.tight_layout()
    save_figure(fig, path)
