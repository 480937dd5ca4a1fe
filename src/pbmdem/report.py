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

from pbmdem.atomic import write_csv, write_text
from pbmdem.readers import read_json, read_table

METHODS = {"pbm_dem": "PBM-DEM", "pbm_ann": "PBM-ANN", "pbm_constant": "PBM-constant"}
STYLES = {"pbm_dem": dict(color="black", lw=2.2), "pbm_ann": dict(color="tab:orange", ls="--", lw=2),
          "pbm_constant": dict(color="tab:blue", ls=":", lw=2)}


def load_method(validation_dir: str | Path, rpm: str, method: str) -> dict:
    folder = Path(validation_dir) / f"rpm{rpm}" / method
    what = f"{METHODS.get(method, method)} result"
    out = {"summary": read_table(folder / "summary.csv", what, columns=("time", "d50"), finite=("time", "d50")),
           "bins": read_table(folder / "final_bins.csv", what),
           "timing": read_json(folder / "timing.json", what, keys=("total_wall_time_s",))}
    if (folder / "intervals.csv").exists():
        out["intervals"] = read_table(folder / "intervals.csv", what)
    return out


def relative_d50_error(reference: pd.DataFrame, other: pd.DataFrame) -> tuple[float, float]:
    """(max over time, at the end) of |d50_other - d50_ref| / d50_ref on the reference's times."""
    d_other = np.interp(reference.time, other.time, other.d50)
    err = np.abs(d_other - reference.d50.to_numpy()) / reference.d50.to_numpy()
    return float(err.max()), float(err[-1])


def compare(validation_dir: str | Path, rpms, grid_rpm) -> pd.DataFrame:
    rows = []
    grid = {float(r) for r in grid_rpm}
    for rpm in rpms:
        data = {m: load_method(validation_dir, rpm, m) for m in METHODS}
        ref = data["pbm_dem"]["summary"]
        ann_max, ann_end = relative_d50_error(ref, data["pbm_ann"]["summary"])
        con_max, con_end = relative_d50_error(ref, data["pbm_constant"]["summary"])
        t_dem = data["pbm_dem"]["timing"]["total_wall_time_s"]
        t_ann = data["pbm_ann"]["timing"]["total_wall_time_s"]
        rows.append({
            "rpm": float(rpm), "in_training_grid": float(rpm) in grid,
            "d50_start_mm": 1e3 * ref.d50.iloc[0], "d50_end_dem_mm": 1e3 * ref.d50.iloc[-1],
            "d50_end_ann_mm": 1e3 * data["pbm_ann"]["summary"].d50.iloc[-1],
            "d50_end_constant_mm": 1e3 * data["pbm_constant"]["summary"].d50.iloc[-1],
            "ann_d50_rel_error_max": ann_max, "ann_d50_rel_error_end": ann_end,
            "constant_d50_rel_error_max": con_max, "constant_d50_rel_error_end": con_end,
            "dem_calls": int(len(data["pbm_dem"].get("intervals", []))),
            "pbm_dem_wall_s": t_dem, "pbm_dem_liggghts_wall_s": data["pbm_dem"]["timing"]["provider_wall_time_s"],
            "pbm_ann_wall_s": t_ann, "pbm_constant_wall_s": data["pbm_constant"]["timing"]["total_wall_time_s"],
            "wall_time_ratio_dem_over_ann": t_dem / t_ann if t_ann > 0 else float("nan"),
            **domain_counts(data),
        })
    return pd.DataFrame(rows)


def domain_counts(data: dict) -> dict:
    """How often the surrogate was used outside its training domain at one speed: PBM-ANN
    intervals with an out-of-domain warning (of all intervals) and the constant kernel's
    calibration (older results without the columns count as unknown, NaN)."""
    ann = data["pbm_ann"].get("intervals")
    if ann is not None and "out_of_domain_count" in ann.columns:
        counts = ann.out_of_domain_count.fillna(0)
        ann_intervals, ann_warnings = int((counts > 0).sum()), int(counts.sum())
    else:
        ann_intervals = ann_warnings = float("nan")
    return {"ann_out_of_domain_intervals": ann_intervals,
            "ann_intervals": int(len(ann)) if ann is not None else 0,
            "ann_out_of_domain_warnings": ann_warnings,
            "constant_calibration_out_of_domain_warnings":
                data["pbm_constant"]["timing"].get("out_of_domain_count", float("nan"))}


def domain_statement(table: pd.DataFrame, validation_dir, rpms) -> str:
    """HTML paragraph stating where the surrogate left its training domain (never left out)."""
    lines = []
    for rpm, row in zip(rpms, table.itertuples()):
        if row.ann_out_of_domain_intervals > 0:  # NaN (results from before the count) is not > 0
            ann = load_method(validation_dir, rpm, "pbm_ann")["intervals"]
            messages = sorted({m for m in ann.get("out_of_domain", pd.Series(dtype=str)).dropna().astype(str) if m})
            lines.append(f"{rpm} rpm: PBM-ANN used the surrogate outside its training domain in "
                         f"{row.ann_out_of_domain_intervals} of {row.ann_intervals} intervals "
                         f"({row.ann_out_of_domain_warnings} warnings): " + html_escape("; ".join(messages)[:2000]))
        if row.constant_calibration_out_of_domain_warnings > 0:
            lines.append(f"{rpm} rpm: the constant kernel's calibration used the surrogate outside its training "
                         f"domain ({row.constant_calibration_out_of_domain_warnings} warnings)")
    if not lines and table.ann_out_of_domain_intervals.isna().any():
        return ("<p>Surrogate domain: not recorded for (some of) these results; they were computed before "
                "out-of-domain counting. Rerun the validation rules to count.</p>")
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


def figures(validation_dir: str | Path, rpm: str, model: str | Path | None = None) -> list[tuple[str, str]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = {m: load_method(validation_dir, rpm, m) for m in METHODS}
    out = []
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8))
    for m, label in METHODS.items():
        s = data[m]["summary"]
        a1.plot(s.time, 1e3 * s.d50, label=label, **STYLES[m])
        a2.plot(s.time, 1e3 * s.number_mean_diameter, label=label, **STYLES[m])
    a1.set(xlabel="time (s)", ylabel="d50 of mass (mm)", title=f"{rpm} rpm: d50")
    a2.set(xlabel="time (s)", ylabel="number-mean diameter (mm)", title=f"{rpm} rpm: mean diameter")
    a1.legend()
    fig.tight_layout()
    out.append((f"d50 and mean diameter vs time, {rpm} rpm", _png(fig)))

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for m, label in METHODS.items():
        b = data[m]["bins"]
        ax.semilogx(1e3 * b.diameter, b.mass_fraction, label=label, **STYLES[m])
    ax.set(xlabel="diameter (mm)", ylabel="mass fraction per bin", title=f"{rpm} rpm: final mass PSD")
    ax.legend()
    fig.tight_layout()
    out.append((f"final mass PSD, {rpm} rpm", _png(fig)))

    dem_i, ann_i = data["pbm_dem"]["intervals"], data["pbm_ann"]["intervals"]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8))
    a1.plot(dem_i.t_start, dem_i.mean_frequency_per_pair, "ko-", label="DEM (PBM-DEM loop)")
    a1.plot(ann_i.t_start, ann_i.mean_frequency_per_pair, "s--", color="tab:orange", label="surrogate (PBM-ANN loop)")
    a1.set(xlabel="interval start (s)", ylabel="pair-weighted mean c (1/s per pair)",
           title=f"{rpm} rpm: collision frequency per interval")
    a1.legend()
    # class-pair frequencies: DEM vs the surrogate on the very same samples (the PBM-DEM loop's)
    dem_c, ann_c = [], []
    outside = 0
    if model is not None:
        from pbmdem.surrogate.domain import out_of_domain_recorded
        from pbmdem.surrogate import load_surrogate

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
           title="class pairs of every PBM-DEM interval")
    fig.tight_layout()
    caption = f"collision frequencies per coupling interval, {rpm} rpm"
    if outside:
        caption += (f" (the surrogate was outside its training domain on {outside} of {len(dem_i)} "
                    "PBM-DEM samples)")
    out.append((caption, _png(fig)))
    return out


def _table(frame: pd.DataFrame, floatfmt: str = "{:.4g}") -> str:
    return frame.to_html(index=False, float_format=lambda x: floatfmt.format(x), border=0, classes="t")


def build_report(*, validation_dir, rpms, grid_rpm, runs, collisions, metrics, parity, metadata, sweep,
                 sweep_plot, html: str | Path, comparison: str | Path, model: str | Path | None = None,
                 speed_study: dict | None = None) -> pd.DataFrame:
    """`speed_study`: paths of the DEM speed-response outputs (table, flow, plot, velocity_plot)."""
    table = compare(validation_dir, rpms, grid_rpm)
    write_csv(comparison, table)
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
    ann_ok = (table.ann_d50_rel_error_max <= 0.05).all()
    parts.append(f"<p>Target: PBM-ANN d50 within 5 % of PBM-DEM over the whole process - "
                 f"{'met' if ann_ok else 'not met'} (largest error {table.ann_d50_rel_error_max.max():.1%}); "
                 f"PBM-ANN at least 1000x faster - "
                 f"{'met' if (table.wall_time_ratio_dem_over_ann >= 1000).all() else 'not met'} (ratio "
                 f"{table.wall_time_ratio_dem_over_ann.min():.0f}-{table.wall_time_ratio_dem_over_ann.max():.0f}x).</p>")
    parts.append(domain_statement(table, validation_dir, rpms))
    for rpm in rpms:
        for caption, uri in figures(validation_dir, rpm, model):
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
