"""HTML of the report: a page per table (for Snakemake's report, which shows HTML results inline),
and the self-contained `results/report/report.html` assembled from the very files the workflow
registered with Snakemake's report (figures embedded as data URIs, tables read from their CSVs).
"""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path

import pandas as pd

from pbmdem.atomic import write_text
from pbmdem.readers import read_json, read_table
from pbmdem.tables import COMPARISON, GRID_PAIRS, RUNS

from .display import MM, number, shown, split_columns
from .statements import out_of_domain_sentence, target_sentences

STYLE = (
    "body{font-family:sans-serif;max-width:1100px;margin:1.5em auto;padding:0 1em;line-height:1.4}"
    "table.t{border-collapse:collapse;font-size:12px;margin:0.4em 0 1em 0;max-width:100%}"
    "table.t td,table.t th{padding:2px 6px;border-bottom:1px solid #ddd;text-align:left;vertical-align:top}"
    "table.t th{background:#f3f3f3;max-width:14em}table.t td{max-width:40em;overflow-wrap:anywhere}"
    "img{max-width:100%}.met{color:#11772e}.notmet{color:#b00020}p.note{font-size:12px;color:#444}"
)


def escape(text) -> str:
    return html.escape(str(text))


def table_html(frame: pd.DataFrame, keys: int = 1) -> str:
    """`frame` as HTML tables of at most `display.MAX_COLUMNS` columns each (the first `keys`
    columns repeated in each part), values as they are (display tables hold strings)."""
    return "".join(
        part.to_html(index=False, border=0, classes="t", na_rep="n/a", escape=True)
        for part in split_columns(frame, keys)
    )


def page(title: str, body: str) -> str:
    return (
        f"<!doctype html><html><head><meta charset='utf-8'><title>{escape(title)}</title>"
        f"<style>{STYLE}</style></head><body>{body}</body></html>\n"
    )


def table_page(title: str, intro: str, tables: list[tuple[str, pd.DataFrame]], keys: int = 1) -> str:
    """A page of one or more display tables with a heading each."""
    body = [f"<h2>{escape(title)}</h2>", f"<p>{escape(intro)}</p>" if intro else ""]
    for heading, frame in tables:
        body += [f"<h3>{escape(heading)}</h3>" if heading else "", table_html(frame, keys)]
    return page(title, "".join(body))


def write_table(
    csv_path: str | Path, html_path: str | Path, frame: pd.DataFrame, title: str, intro: str = "", keys: int = 1
) -> None:
    """A display table as CSV and as its HTML page, both atomically."""
    from pbmdem.atomic import write_csv

    write_csv(csv_path, frame)
    write_text(html_path, table_page(title, intro, [("", frame)], keys))


def _image(path: str | Path, alt: str) -> str:
    data = base64.b64encode(Path(path).read_bytes()).decode()
    return f"<img alt='{escape(alt)}' src='data:image/png;base64,{data}'>"


def read_display(path: str | Path, what: str) -> pd.DataFrame:
    """A display table as written (every cell text: "0" stays "0", "n/a" stays "n/a")."""
    return read_table(path, what, dtype=str, keep_default_na=False)


def inline(text: str) -> str:
    """rst inline markup of the findings (**bold**, ``code``) as HTML, the rest escaped."""
    import re

    text = escape(text)
    text = re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", text)
    return re.sub(r"``(.+?)``", r"<code>\1</code>", text)


def rst_to_html(text: str) -> str:
    """The findings' reStructuredText (paragraphs, section titles, bullet lists, **bold**, ``code``
    and `.. image:: data:...` blocks with `:alt:`) as HTML."""
    import re

    out = []
    for block in text.strip().split("\n\n"):
        lines = block.strip().splitlines()
        if not lines:
            continue
        if lines[0].startswith(".. image:: data:image/png;base64,"):
            src = lines[0].split("::", 1)[1].strip() + "".join(
                ln.strip() for ln in lines[1:] if not ln.strip().startswith(":")
            )
            alt = next((ln.split(":alt:", 1)[1].strip() for ln in lines[1:] if ":alt:" in ln), "figure")
            out.append(f"<p><img alt='{escape(alt)}' src='{src}' style='max-width:100%'></p>")
        elif len(lines) == 2 and set(lines[1]) <= set("-=~") and len(lines[1]) >= len(lines[0]):
            out.append(f"<h2>{escape(lines[0])}</h2>")
        elif lines[0].startswith("* "):
            items = re.split(r"\n(?=\* )", "\n".join(lines))
            out.append("<ul>" + "".join(f"<li>{inline(' '.join(i[2:].split()))}</li>" for i in items) + "</ul>")
        else:
            out.append(f"<p>{inline(' '.join(lines))}</p>")
    return "".join(out)


HYPERPARAMETER_NAMES = {
    "hidden_layer_sizes": "hidden layers (neurons per layer)",
    "alpha": "L2 penalty alpha",
    "activation": "activation",
    "learning_rate_init": "initial learning rate",
}


def kernel_source(meta: dict) -> str:
    """The surrogate family PBM-ANN uses, why, and what was fitted, in words (from ``model.json``)."""
    state = meta.get("frequency_state") or {}
    if isinstance(state.get("best_params"), dict):
        fitted = "selected hyperparameters " + hyperparameters(state["best_params"])
    else:
        fitted = "fitted " + ("; ".join(map(str, state.get("fitted") or [])) or "not recorded")
    selection = (meta.get("cv_scores") or {}).get("selection") or "not recorded"
    return f"Kernel source: {meta.get('family', 'not recorded')} ({selection}); {fitted}"


def hyperparameters(params) -> str:
    """Selected hyperparameters in words: 'hidden layers (neurons per layer) 8 x 8, L2 penalty alpha 0.1'
    (per target when the metadata holds one mapping per target)."""
    if not isinstance(params, dict) or not params:
        return "not recorded"
    if all(isinstance(v, dict) for v in params.values()):
        return "; ".join(f"{target}: {hyperparameters(v)}" for target, v in params.items())

    def value(v):
        if isinstance(v, (list, tuple)):
            return " x ".join(str(x) for x in v)
        return f"{v:g}" if isinstance(v, float) else str(v)

    return ", ".join(
        f"{HYPERPARAMETER_NAMES.get(k.split('__')[-1], k.split('__')[-1].replace('_', ' '))} {value(v)}"
        for k, v in params.items()
    )


def _verdicts(sentences: list[str]) -> str:
    items = []
    for s in sentences:
        cls = "met" if ": met at every speed" in s else "notmet"
        items.append(f"<li class='{cls}'>{escape(s)}</li>")
    return "<ul>" + "".join(items) + "</ul>"


def _sweep(path) -> pd.DataFrame:
    sweep = read_table(path, "impeller-speed sweep table", columns=("rpm", "d10", "d50", "d90"))
    out = pd.DataFrame({"impeller speed (rpm)": sweep.rpm.map(lambda v: f"{v:g}")})
    for stat in ("d10", "d50", "d90"):
        out[f"final {stat} (mm)"] = (MM * sweep[stat]).map(lambda v: f"{v:.3f}")
    if "wall_time_s" in sweep:
        out["wall time (s)"] = sweep.wall_time_s.map(lambda v: number(v, ".3g"))
    if "out_of_domain_intervals" in sweep:
        out["intervals outside the training domain"] = sweep.out_of_domain_intervals.map(lambda v: number(v, ".0f"))
    return out


def _metrics(path) -> pd.DataFrame:
    met = read_table(path, "surrogate metrics table", columns=("target", "model", "fold"))
    met = met[met.fold.astype(str).isin(["pooled", "mean"])]
    names = {
        "target": "target",
        "model": "model",
        "fold": "fold",
        "n_test": "test rows",
        "r2_log10": "R2 of log10 (-)",
        "mae_log10": "MAE of log10 (decades)",
        "noise_floor_r2_log10": "replicate noise floor R2 (-)",
        "tv_distance": "velocity bins TV distance (-)",
    }
    return shown(met, names, ".3g")


def _runs(path) -> pd.DataFrame:
    runs = RUNS.read(path, need=("point_id",))
    names = {
        "point_id": "operating point",
        "replicate": "replicate",
        "n_particles": "particles (-)",
        "timestep": "time step (s)",
        "steps": "steps (-)",
        "total_encounters": "encounters (-)",
        "total_collisions": "new contacts (-)",
        "liggghts_wall_time_s": "LIGGGHTS wall time (s)",
        "particle_steps_per_s": "particle-steps per s (1/s)",
        "parse_cost_ratio": "parse / LIGGGHTS time (-)",
    }
    return shown(runs, names)


def _speed_response(paths: dict) -> list[str]:
    response = read_table(paths["table"], "DEM speed-response table", columns=("distribution", "rpm"))
    flow = read_table(paths["flow"], "DEM flow-development table", columns=("within_error",))
    names = {
        "distribution": "feed",
        "rpm": "impeller speed (rpm)",
        "n_replicates": "replicates (-)",
        "n_particles": "particles (-)",
        "encounters_per_particle_per_s": "encounters per particle (1/s)",
        "encounters_per_particle_per_s_se": "SE (1/s)",
        "new_contacts_per_particle_per_s": "new contacts per particle (1/s)",
        "mean_encounter_frequency_per_pair": "encounter frequency per pair (1/s)",
        "impact_velocity_median": "median impact speed (m/s)",
    }
    response_shown = shown(response, names)
    flow_cols = {
        "distribution": "feed",
        "rpm": "impeller speed (rpm)",
        "half_difference": "second - first half (-)",
        "half_difference_se": "SE (-)",
        "half_z": "difference / SE (-)",
        "within_error": "within 2 SE",
    }
    flow = flow.assign(
        rpm=flow.rpm.map(lambda v: f"{v:g}"),
        within_error=flow.within_error.map(lambda v: "yes" if str(v).strip().lower() in ("true", "1") else "no"),
    )
    flow_shown = shown(flow, flow_cols, ".3g")
    ok = int(flow.within_error.astype(bool).sum())
    return [
        "<h2>DEM: encounter rate against impeller speed</h2>",
        "<p>An encounter is an impact of two granules that were apart by more than "
        "<code>dem.encounter_gap_fraction</code> of the smaller diameter since their previous contact "
        "(docs/dem.md). Means over the DEM replicates (insertion seeds) with standard errors (SE).</p>",
        table_html(response_shown, 2),
        _image(paths["plot"], "encounter rate against impeller speed"),
        f"<p>Flow development: the encounter rates of the first and second halves of the sampling window agree "
        f"within twice their replicate standard error at {ok} of {len(flow)} operating points.</p>",
        table_html(flow_shown, 2),
        "<h3>Impact-velocity distributions</h3>",
        _image(paths["velocity_plot"], "impact-velocity distributions"),
    ]


def _proposals(path) -> pd.DataFrame:
    table = read_table(path, "proposals table", columns=("name", "kind", "rpm", "interval", "reason"))

    def classes(text):
        try:
            return ", ".join(f"{MM * d:.2f}" for d in json.loads(text))
        except (TypeError, ValueError):
            return str(text)

    out = pd.DataFrame(
        {
            "name": table.name,
            "kind": table.kind,
            "speed (rpm)": table.rpm.map(lambda v: f"{v:g}"),
            "PBM-ANN interval": table.interval.astype(str),
            "reason": table.reason,
        }
    )
    if "diameters" in table:
        out["class diameters (mm)"] = table.diameters.map(classes)
    if "number_fractions" in table:
        out["number fractions (-)"] = table.number_fractions.astype(str)
    return out


#: the figures of one speed: key -> heading
SPEED_FIGURES = {
    "sizes": "d10, d50 and d90 against time: PBM-DEM replicate band, PBM-ANN ensemble-member band, PBM-constant",
    "psd": "mass size distribution over the batch (PBM-DEM replicate 0, PBM-ANN, PBM-constant)",
    "liquid": "mean liquid content and porosity against time",
    "frequency": "collision frequency per coupling interval, and the surrogate on PBM-DEM's samples",
}


def build_report(
    *,
    html_path,
    tables: dict,
    speeds: dict,
    comparison,
    sweep,
    sweep_plot,
    metrics,
    parity,
    metadata,
    runs,
    collisions,
    speed_study: dict,
    proposals,
    findings=None,
) -> None:
    """Write the self-contained report page. `tables`: name -> CSV of the display tables
    (`settings`, `speeds`, `provenance`, `targets`, `comparison_d50`, `comparison_accuracy`,
    `comparison_cost`, `comparison_domain`); `speeds`: rpm -> {figure key of SPEED_FIGURES -> PNG,
    `out_of_domain` -> CSV}; the rest are the workflow's own tables and figures."""
    table = COMPARISON.read(comparison, need=("rpm",))
    shown = {name: read_display(path, f"report table {name}") for name, path in tables.items()}
    domain = {
        rpm: read_display(files["out_of_domain"], f"out-of-domain table of {rpm} rpm") for rpm, files in speeds.items()
    }
    meta = read_json(metadata, "surrogate metadata")
    coll = GRID_PAIRS.read(collisions, need=())
    runs_shown = _runs(runs)
    parts = [
        "<h1>pbmdem: how impeller speed and feed size change granule growth</h1>",
        rst_to_html(Path(findings).read_text()) if findings is not None else "",
        "<h2>Validation: how far to trust them</h2>",
        "<p>Written by the <code>report</code> rule from the result files of this workflow run (the same files "
        "<code>snakemake --report report.zip</code> collects). PBM-DEM is the mean and envelope of "
        "<code>validation.dem_replicates</code> coupled loops that differ only by their DEM insertion seeds. "
        "Sizes in mm; wall times measured in this run on this machine.</p>",
        "<h3>Targets</h3>",
        _verdicts(target_sentences(table)),
        table_html(shown["targets"], 3),
        "<h2>Surrogate training domain</h2>",
        "<p>Where PBM-ANN used the surrogate outside its training domain its frequencies are extrapolations; "
        "every coupling interval is accounted for:</p><ul>"
        + "".join(f"<li>{escape(out_of_domain_sentence(rpm, frame))}</li>" for rpm, frame in domain.items())
        + "</ul>",
        "<h2>Process settings</h2>",
        table_html(shown["settings"]),
        table_html(shown["speeds"]),
        "<h2>Comparison (one row per validation speed)</h2>",
        "<h3>d50</h3>",
        table_html(shown["comparison_d50"]),
        "<h3>Accuracy against PBM-DEM</h3>",
        table_html(shown["comparison_accuracy"]),
        "<h3>Computing time</h3>",
        table_html(shown["comparison_cost"]),
        "<h3>Surrogate domain</h3>",
        table_html(shown["comparison_domain"]),
    ]
    for rpm, files in speeds.items():
        parts.append(f"<h2>{escape(rpm)} rpm</h2>")
        for key, heading in SPEED_FIGURES.items():
            parts += [f"<h3>{escape(heading)}</h3>", _image(files[key], f"{heading}, {rpm} rpm")]
        parts += ["<h3>Surrogate domain, interval by interval</h3>", table_html(domain[rpm], 2)]
    parts += ["<h2>Impeller-speed study (PBM-ANN)</h2>", table_html(_sweep(sweep)), _image(sweep_plot, "sweep")]
    parts += [
        "<h2>Surrogate (held-out DEM runs)</h2>",
        table_html(_metrics(metrics), 3),
        f"<p>{escape(kernel_source(meta))}; training runs: {len(meta.get('training_point_ids', []))}.</p>",
        _image(parity, "surrogate parity"),
    ]
    parts += _speed_response(speed_study)
    parts += [
        "<h2>DEM runs</h2>",
        table_html(runs_shown, 2),
        f"<p>{len(runs_shown)} LIGGGHTS runs; {len(coll)} class-pair rows in the collision table.</p>",
    ]
    parts += ["<h2>Proposed operating points (active learning)</h2>", table_html(_proposals(proposals))]
    parts += ["<h2>Provenance</h2>", table_html(shown["provenance"])]
    write_text(html_path, page("pbmdem report", "".join(parts)))
