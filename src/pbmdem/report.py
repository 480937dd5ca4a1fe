"""The reproduction report: PBM-ANN and PBM-constant against the coupled PBM-DEM model.

`compare` computes, per validation speed, the relative error of d50(t) of PBM-ANN and
PBM-constant against PBM-DEM (largest over the process and at its end, on PBM-DEM's output
times) and the wall-time ratio PBM-DEM / PBM-ANN. `build_report` writes that table as CSV and a
self-contained HTML page (figures embedded) with the DEM-stage facts and surrogate metrics.
"""

from __future__ import annotations

import base64
import html
import io
import json
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.atomic import write_text
from pbmdem.readers import read_json, read_table

STYLES = {"pbm_dem": dict(color="black", lw=2.2), "pbm_ann": dict(color="tab:orange", ls="--", lw=2),
          "pbm_constant": dict(color="tab:blue", ls=":", lw=2)}


def domain_statement(table: pd.DataFrame, speeds: dict) -> str:
    """HTML paragraph stating where the surrogate left its training domain (never left out)."""
    lines = []
    for row in table.itertuples():
        speed = speeds[row.rpm]
        if row.ann_out_of_domain_intervals > 0:  # NaN (results from before the count) is not > 0
            ann = speed.ann.intervals
            messages = sorted({m for m in ann.get("out_of_domain", pd.Series(dtype=str)).dropna().astype(str) if m})
            lines.append(f"{row.rpm:g} rpm: PBM-ANN used the surrogate outside its training domain in "
                         f"{row.ann_out_of_domain_intervals} of {row.ann_intervals} intervals "
                         f"({row.ann_out_of_domain_warnings} warnings): " + html_escape("; ".join(messages)[:2000]))
        if row.constant_calibration_out_of_domain_warnings > 0:
            lines.append(f"{row.rpm:g} rpm: the constant kernel's calibration used the surrogate outside its "
                         f"training domain ({row.constant_calibration_out_of_domain_warnings} warnings)")
    if not lines:
        return "<p>Surrogate domain: every PBM-ANN interval and calibration stayed within the training range.</p>"
    return ("<p><b>Warning: surrogate outside its training domain.</b> Its predictions there are "
            "extrapolations.</p><ul>" + "".join(f"<li>{line}</li>" for line in lines) + "</ul>")


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def _img_file(path: str | Path) -> str:
    return "data:image/png;base64," + base64.b64encode(Path(path).read_bytes()).decode()


def figures(speed, model: str | Path | None = None) -> list[tuple[str, str]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pbmdem.validation.comparison import bands_of

    rpm = speed.rpm
    band = bands_of(speed)
    out = []
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for ax, stat in zip(axes, ("d10", "d50", "d90")):
        b = band[band.statistic == stat]
        ax.fill_between(b.time, 1e3 * b.dem_min, 1e3 * b.dem_max, color="0.8",
                        label=f"PBM-DEM band ({int(b.n_dem_replicates.iloc[0])} replicates)")
        ax.plot(b.time, 1e3 * b.dem_mean, **STYLES["pbm_dem"], label="PBM-DEM mean")
        if "ann_member_min" in b:
            ax.fill_between(b.time, 1e3 * b.ann_member_min, 1e3 * b.ann_member_max, color="tab:orange", alpha=0.25,
                            label="PBM-ANN ensemble members")
        ax.plot(b.time, 1e3 * b.ann, **STYLES["pbm_ann"], label="PBM-ANN")
        ax.plot(b.time, 1e3 * b.constant, **STYLES["pbm_constant"], label="PBM-constant")
        ax.set(xlabel="time (s)", ylabel=f"{stat} (mm)", title=f"{rpm} rpm: {stat}")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    out.append((f"d10, d50, d90 vs time with the PBM-DEM band, {rpm} rpm", _png(fig)))

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for run, label, style in ((speed.dem[0], "PBM-DEM (replicate 0)", STYLES["pbm_dem"]),
                              (speed.ann, "PBM-ANN", STYLES["pbm_ann"]),
                              (speed.constant, "PBM-constant", STYLES["pbm_constant"])):
        b = run.final_bins
        ax.semilogx(1e3 * b.diameter, b.mass_fraction, label=label, **style)
    ax.set(xlabel="diameter (mm)", ylabel="mass fraction per bin", title=f"{rpm} rpm: final mass PSD")
    ax.legend()
    fig.tight_layout()
    out.append((f"final mass PSD, {rpm} rpm", _png(fig)))

    dem_i, ann_i = speed.dem[0].intervals, speed.ann.intervals
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8))
    for k, rep in enumerate(speed.dem):
        a1.plot(rep.intervals.t_start, rep.intervals.mean_frequency_per_pair, "ko-", alpha=0.6,
                label="DEM (PBM-DEM loops)" if k == 0 else None)
    a1.plot(ann_i.t_start, ann_i.mean_frequency_per_pair, "s--", color="tab:orange", label="surrogate (PBM-ANN loop)")
    a1.set(xlabel="interval start (s)", ylabel="pair-weighted mean c (1/s per pair)",
           title=f"{rpm} rpm: collision frequency per interval")
    a1.legend()
    # class-pair frequencies: DEM vs the surrogate on the very same samples (the PBM-DEM loop's)
    dem_c, ann_c = [], []
    outside = 0
    if model is not None:
        from pbmdem.surrogate import load_surrogate
        from pbmdem.surrogate.domain import out_of_domain_recorded

        surrogate = load_surrogate(model)
        for _, row in dem_i.iterrows():
            d = np.asarray(json.loads(row.class_diameters))
            n = np.asarray(json.loads(row.class_counts), float)
            with out_of_domain_recorded(f"report, {rpm} rpm, PBM-DEM interval {row.interval}") as found:
                c = surrogate.frequency_matrix(d, n, float(rpm))
            outside += bool(found)
            dem_c.append(json.loads(row.class_frequencies))
            ann_c.append(c[np.triu_indices(len(d))].tolist())
    dem_c, ann_c = np.concatenate(dem_c or [[]]), np.concatenate(ann_c or [[]])
    keep = dem_c > 0
    a2.loglog(dem_c[keep], ann_c[keep], "o", alpha=0.7)
    if keep.any():
        lo, hi = min(dem_c[keep].min(), ann_c[keep].min()), max(dem_c.max(), ann_c.max())
        a2.plot([lo, hi], [lo, hi], "k:")
    a2.set(xlabel="DEM c_ij (1/s per pair)", ylabel="surrogate c_ij, same sample",
           title="class pairs of every PBM-DEM interval (replicate 0)")
    fig.tight_layout()
    caption = f"collision frequencies per coupling interval, {rpm} rpm"
    if outside:
        caption += (f" (the surrogate was outside its training domain on {outside} of {len(dem_i)} "
                    "PBM-DEM samples)")
    out.append((caption, _png(fig)))
    return out


def _table(frame: pd.DataFrame, floatfmt: str = "{:.4g}") -> str:
    return frame.to_html(index=False, float_format=lambda x: floatfmt.format(x), border=0, classes="t")


def build_report(*, validation_dir, rpms, replicates, runs, collisions, metrics, parity, metadata, sweep,
                 sweep_plot, comparison: str | Path, html: str | Path, model: str | Path | None = None,
                 speed_study: dict | None = None) -> pd.DataFrame:
    """`speed_study`: paths of the DEM speed-response outputs (table, flow, plot, velocity_plot)."""
    from pbmdem.validation.results import load_speed

    table = read_table(comparison, "comparison table", columns=("rpm",))
    speeds = {float(rpm): load_speed(validation_dir, rpm, replicates) for rpm in rpms}
    runs_df = read_table(runs, "DEM run table", columns=("total_collisions",))
    coll = read_table(collisions, "collision table")
    met = read_table(metrics, "surrogate metrics table")
    meta = read_json(metadata, "surrogate metadata")
    sweep_df = read_table(sweep, "impeller-speed sweep table")
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>pbmdem report</title><style>",
        "body{font-family:sans-serif;max-width:1100px;margin:2em auto;line-height:1.4}"
        "table.t{border-collapse:collapse;font-size:12px}table.t td,table.t th{padding:2px 6px;"
        "border-bottom:1px solid #ddd;text-align:right}img{max-width:100%}",
        "</style></head><body>",
        "<h1>pbmdem: PBM-ANN vs coupled PBM-DEM</h1>",
        "<p>Generated by the <code>report</code> rule from the results of this workflow run. "
        "Errors are relative errors of the mass-median diameter d50(t) against PBM-DEM on its output "
        "times; wall times were measured in this run on this machine.</p>",
        "<h2>Accuracy and computing time</h2>", _table(table),
    ]
    outside = table.ann_d50_outside_band_max.max()
    parts.append(f"<p>Targets: PBM-ANN's d50(t) within 2 % of the PBM-DEM band - "
                 f"{'met' if outside <= 0.02 else 'not met'} (largest distance outside {outside:.1%}); "
                 f"PBM-ANN at least 3000x faster - "
                 f"{'met' if (table.wall_time_ratio_dem_over_ann >= 3000).all() else 'not met'} (ratio "
                 f"{table.wall_time_ratio_dem_over_ann.min():.0f}-{table.wall_time_ratio_dem_over_ann.max():.0f}x).</p>")
    parts.append(domain_statement(table, speeds))
    for speed in speeds.values():
        for caption, uri in figures(speed, model):
            parts.append(f"<h3>{html_escape(caption)}</h3><img src='{uri}'>")
    if speed_study:
        parts += speed_study_section(speed_study)
    parts += ["<h2>Impeller-speed study (PBM-ANN)</h2>", _table(sweep_df), f"<img src='{_img_file(sweep_plot)}'>"]
    summary = met[met.get("fold", pd.Series(dtype=str)).astype(str).isin(["pooled", "mean"])] \
        if "fold" in met.columns else met
    parts += ["<h2>Surrogate (held-out DEM runs)</h2>", _table(summary),
              f"<p>Selected: {html_escape(json.dumps(meta.get('best_params', meta.get('params', {}))))}; "
              f"training runs: {len(meta.get('training_point_ids', []))}.</p>",
              f"<img src='{_img_file(parity)}'>"]
    facts = runs_df[[c for c in ("point_id", "n_particles", "timestep", "steps", "collision_interval",
                                 "total_collisions", "liggghts_wall_time_s", "particle_steps_per_s",
                                 "parse_cost_ratio", "convergence_change_when_interval_doubled")
                     if c in runs_df.columns]]
    parts += ["<h2>DEM stage</h2>", _table(facts),
              f"<p>{len(runs_df)} LIGGGHTS runs, {int(runs_df.total_collisions.sum())} collisions counted in "
              f"{len(coll)} class-pair rows.</p>", "</body></html>"]
    write_text(html, "\n".join(parts))
    return table


def speed_study_section(paths: dict) -> list[str]:
    """Encounter rate against impeller speed with replicate errors, the flow-development check
    and the impact-velocity distributions (sizes in the tables are per particle, rates in 1/s)."""
    response = pd.read_csv(paths["table"])
    flow = pd.read_csv(paths["flow"])
    cols = ["distribution", "rpm", "n_replicates", "n_particles", "encounters_per_particle_per_s",
            "encounters_per_particle_per_s_se", "new_contacts_per_particle_per_s",
            "new_contacts_per_particle_per_s_se", "mean_encounter_frequency_per_pair",
            "mean_encounter_frequency_per_pair_se", "impact_velocity_median"]
    shown = response[[c for c in cols if c in response.columns]].rename(columns={
        "encounters_per_particle_per_s": "encounters / particle (1/s)",
        "encounters_per_particle_per_s_se": "SE",
        "new_contacts_per_particle_per_s": "new contacts / particle (1/s)",
        "new_contacts_per_particle_per_s_se": "SE ",
        "mean_encounter_frequency_per_pair": "encounter freq. per pair (1/s)",
        "mean_encounter_frequency_per_pair_se": "SE  ",
        "impact_velocity_median": "median impact speed (m/s)"})
    ok = int(flow.within_error.sum())
    return [
        "<h2>DEM: encounter rate against impeller speed</h2>",
        "<p>An encounter is an impact of two granules that were apart by more than "
        "<code>dem.encounter_gap_fraction</code> of the smaller diameter since their previous contact "
        "(docs/dem.md). Mean over DEM replicates (insertion seeds) with standard errors.</p>",
        _table(shown), f"<img src='{_img_file(paths['plot'])}'>",
        f"<p>Flow development: the encounter rates of the first and second halves of the sampling window "
        f"agree within twice their replicate standard error at {ok} of {len(flow)} operating points "
        f"(half_z: their difference in combined standard errors).</p>",
        _table(flow[["distribution", "rpm", "half_difference", "half_difference_se", "half_z", "within_error"]]),
        "<h3>Impact-velocity distributions</h3>", f"<img src='{_img_file(paths['velocity_plot'])}'>",
    ]


def html_escape(text: str) -> str:
    return html.escape(str(text))
