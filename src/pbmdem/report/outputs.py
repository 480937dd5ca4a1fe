"""The files of the report rules, one function per rule (rules/report.smk): each reads its inputs
(errors name the file), builds the figures and tables of `figures`, `tables`, `statements` and
`provenance`, and writes them atomically; a table as CSV and as an HTML page (`display.write_table`:
Snakemake's report shows HTML inline and offers CSV for download).
"""

from __future__ import annotations

from pathlib import Path

from pbmdem.readers import InputFileError, read_table

from . import figures
from .display import write_table

#: summary.csv columns the figures of a speed read
SUMMARY_COLUMNS = ("time", "d10", "d50", "d90", "mean_liquid_content", "mean_porosity")
BINS_COLUMNS = ("time", "diameter", "mass_density_lnd")


def _require(frame, columns, path: Path, what: str) -> None:
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise InputFileError(f"{what} {path}: missing column(s) {missing}; present: {list(frame.columns)}")


def write_speed(*, validation_dir, rpm: str, replicates: int, process: dict, bands, model, out: dict) -> None:
    """The figures and the out-of-domain table of one validation speed. `out`: sizes, psd, liquid,
    frequency (PNG), domain_csv, domain_html."""
    from pbmdem.config.pbm import ProcessSettings
    from pbmdem.surrogate import load_surrogate
    from pbmdem.validation.results import load_speed, run_folder

    from .frequencies import interval_frequencies, surrogate_on_dem_samples
    from .statements import out_of_domain, out_of_domain_sentence

    process = ProcessSettings.from_dict(process, "pbm.process")
    speed = load_speed(validation_dir, rpm, replicates)
    folders = {f"PBM-DEM replicate {k}": run_folder(validation_dir, rpm, "pbm_dem", k) for k in range(replicates)}
    folders.update(
        {
            "PBM-ANN": run_folder(validation_dir, rpm, "pbm_ann"),
            "PBM-constant": run_folder(validation_dir, rpm, "pbm_constant"),
        }
    )
    runs = [*speed.dem, speed.ann, speed.constant]
    for (name, folder), run in zip(folders.items(), runs):
        _require(run.summary, SUMMARY_COLUMNS, folder / "summary.csv", f"{name} summary")
    band_table = read_table(
        bands, "bands table", columns=("statistic", "time", "n_dem_replicates", "dem_mean", "dem_min", "dem_max", "ann")
    )
    figures.save(figures.size_bands(band_table, process, rpm, what=f"bands table {bands}"), out["sizes"])
    shown = {
        "PBM-DEM replicate 0": folders["PBM-DEM replicate 0"],
        "PBM-ANN": folders["PBM-ANN"],
        "PBM-constant": folders["PBM-constant"],
    }
    bins = {
        name: read_table(folder / "bins.csv", f"{name} bins table", columns=BINS_COLUMNS, finite=BINS_COLUMNS)
        for name, folder in shown.items()
    }
    figures.save(figures.psd_evolution(bins, process, rpm), out["psd"])
    figures.save(figures.liquid_porosity(speed, process, rpm), out["liquid"])
    frequency = interval_frequencies(speed, folders["PBM-constant"] / "timing.json")
    pairs = surrogate_on_dem_samples(speed, load_surrogate(model))
    figures.save(figures.collision_frequency(frequency, pairs, rpm), out["frequency"])
    domain = out_of_domain(speed)
    write_table(
        out["domain_csv"],
        out["domain_html"],
        domain,
        f"Surrogate training domain, {rpm} rpm",
        out_of_domain_sentence(rpm, domain),
        keys=2,
    )


def write_settings(
    *,
    pbm: dict,
    granulator: dict,
    feed_name: str,
    feed: dict,
    coupling_intervals: int,
    dem_replicates: int,
    dem_sampling_time: float,
    validation_rpm,
    grid_rpm,
    out: dict,
) -> None:
    """The process-settings and speeds tables. `out`: settings_csv, settings_html, speeds_csv, speeds_html."""
    from pbmdem.config import Granulator, Pbm, SizeDistribution

    from .tables import process_settings, speeds

    pbm_settings = Pbm.from_dict(pbm, "pbm")
    machine = Granulator.from_dict(granulator, "granulator")
    settings = process_settings(
        pbm_settings,
        machine.bed_solid_volume,
        feed_name,
        SizeDistribution.from_dict(feed, f"size_distributions.{feed_name}"),
        coupling_intervals,
        dem_replicates,
        dem_sampling_time,
    )
    write_table(
        out["settings_csv"],
        out["settings_html"],
        settings,
        "Process settings",
        "The batch that PBM-DEM, PBM-ANN and PBM-constant run at every validation speed.",
    )
    write_table(
        out["speeds_csv"],
        out["speeds_html"],
        speeds(machine, validation_rpm, grid_rpm),
        "Impeller speeds",
        f"Tip speed 2 pi R rpm / 60 and Froude number omega^2 R / g at the blade tip "
        f"(R = {1e3 * machine.impeller.tip_radius:g} mm).",
    )


def write_comparison(*, comparison, out: dict) -> None:
    """The comparison table in display form and the targets. `out`: comparison_<name>_csv and
    comparison_<name>_html for name in d50, tails, accuracy, cost, domain; targets_csv, targets_html."""
    from pbmdem.tables import COMPARISON

    from .statements import target_sentences, targets
    from .tables import comparison_tables

    table = COMPARISON.read(comparison)
    titles = {
        "d50": "d50 at the start and the end of the batch",
        "tails": "d10 and d90 at the end of the batch",
        "accuracy": "Accuracy against PBM-DEM",
        "cost": "Computing time",
        "domain": "Surrogate training domain",
    }
    for name, frame in comparison_tables(table).items():
        write_table(out[f"comparison_{name}_csv"], out[f"comparison_{name}_html"], frame, titles[name])
    write_table(
        out["targets_csv"], out["targets_html"], targets(table), "Targets", " ".join(target_sentences(table)), keys=3
    )


def write_design_tables(*, design, check, third_key: str, confidence: float, out: dict) -> None:
    """The design space and the calibration check in display form. `out`: design_space_table_csv,
    design_space_table_html, calibration_check_csv, calibration_check_html."""
    from pbmdem.readers import read_table

    from .tables import calibration_check_table, design_space_table

    table = read_table(design, "design-space table", columns=("rpm", "liquid_rate", third_key, "spec_status"))
    counts = ", ".join(f"{n} {s.replace('_', ' ')}" for s, n in table.spec_status.value_counts().items())
    write_table(
        out["design_space_table_csv"],
        out["design_space_table_html"],
        design_space_table(table, third_key),
        "Design space",
        f"{len(table)} grid points: {counts}. A point meets the specification only if every ensemble member does.",
        keys=3,
    )
    recovery = read_table(check, "calibration check", columns=("case", "parameter", "true", "estimate", "recovered"))
    recovered = int(recovery.recovered.astype(str).str.lower().eq("true").sum())
    write_table(
        out["calibration_check_csv"],
        out["calibration_check_html"],
        calibration_check_table(recovery, confidence),
        "Parameter estimation on data of known parameters",
        f"{recovered} of {len(recovery)} true values inside their interval.",
        keys=2,
    )


def write_provenance(*, config: dict, settings: dict, basedir, runs, metadata, out: dict, workdir=None) -> None:
    """The provenance table. `config`: the completed configuration of the job (for its
    `Config.sha256()`); `settings`: the same without the execution settings; `basedir`: the
    project; `workdir`: where the workflow ran (recorded, not compared). `out`: csv, html."""
    from pbmdem.config import Config

    from .provenance import provenance

    table = provenance(Config.from_mapping(config).sha256(), settings, basedir, runs, metadata, workdir=workdir)
    write_table(
        out["csv"],
        out["html"],
        table,
        "Provenance",
        "Configuration hashes, the workflow's git commit and the versions of the software.",
    )


def write_findings(
    *,
    speed,
    feed,
    comparison,
    speed_feed: str,
    feed_rpm: float,
    batch_s: float,
    out: dict,
    breakage=None,
    training=None,
    metadata=None,
    feed_check=None,
    sensitivity=None,
    sensitivity_info=None,
    confidence: float = 0.95,
    lumping=None,
    lumping_liquid=None,
    lumping_info=None,
) -> None:
    """The findings: the figures (speed, feed, and with `breakage` the breakage study) and their
    text (rst), atomically. `speed`, `feed`, `breakage`: the PBM-ANN study tables; `comparison`: the
    validation's comparison table; `training`, `metadata`: the grid collision table the surrogate
    was trained on and its metadata (model.json), for its training set and held-out accuracy beside
    the validation; `feed_check`: the feed check's table (or None: no check); `sensitivity`: the
    Sobol' indices and `sensitivity_info` their figures of merit (JSON; their words; `confidence`:
    the level of their intervals); `lumping`, `lumping_liquid`, `lumping_info`: the 1-D against 2-D
    study (pbmdem.coupling.lumping; its figure, display table and words); `out`: speed_png,
    feed_png, breakage_png, rst, and with `lumping` lumping_png, lumping_csv, lumping_html."""
    from pbmdem.atomic import write_text
    from pbmdem.plotting import save_figure as save

    from .findings import feed_figure, findings_rst, speed_figure

    speed_table = read_table(speed, "PBM-ANN speed study", columns=("rpm", "d10", "d50", "d90"))
    feed_table = read_table(feed, "PBM-ANN feed study", columns=("feed", "feed_d50", "d10", "d50", "d90"))
    comparison_table = read_table(comparison, "comparison table", columns=("rpm",))
    save(speed_figure(speed_table, speed_feed, batch_s), out["speed_png"])
    save(feed_figure(feed_table, feed_rpm, batch_s), out["feed_png"])
    extra: tuple[str, ...] = ()
    if breakage is not None:
        from .breakage import breakage_figure, breakage_words, clipping_words
        from .findings import image_directive

        study = read_table(breakage, "PBM-ANN breakage study", columns=("variant", "rpm", "d50", "critical_speed"))
        save(breakage_figure(study), out["breakage_png"])
        studies = {"speed study": speed_table, "feed study": feed_table, "breakage study": study}
        extra = (breakage_words(study), "", image_directive(out["breakage_png"]), "   :width: 640px", "")
        extra += (clipping_words(studies), "")
    learned = None
    if training is not None and metadata is not None:
        from pbmdem.surrogate.persistence import read_metadata
        from pbmdem.tables import GRID_PAIRS

        from .training import training_set, training_words

        meta = read_metadata(metadata)
        table = GRID_PAIRS.read(training, need=("point_id", "rpm", "distribution", "n_replicates"))
        learned = training_words(training_set(table, str(training), meta["training_point_ids"]), meta, str(training))
    check = None
    if feed_check is not None:
        from pbmdem.validation.feed_check import CHECK_COLUMNS

        check_table = read_table(feed_check, "feed check table", columns=CHECK_COLUMNS)
        check = check_table.iloc[0].to_dict()
    if sensitivity is not None:
        from .sensitivity import sensitivity_words

        indices = read_table(
            sensitivity,
            "Sobol' indices",
            columns=("parameter", "output", "member", "S1", "S1_conf", "ST", "ST_conf"),
            dtype={"member": str},
        )
        info = None
        if sensitivity_info is not None:
            import json

            info = json.loads(Path(sensitivity_info).read_text())
        extra = (*extra, sensitivity_words(indices, confidence, info), "")
    if lumping is not None:
        extra = (*extra, *_lumping_section(lumping, lumping_liquid, lumping_info, out))
    text = findings_rst(
        speed_table,
        feed_table,
        comparison_table,
        speed_feed=speed_feed,
        feed_rpm=feed_rpm,
        batch_s=batch_s,
        speed_png=str(out["speed_png"]),
        feed_png=str(out["feed_png"]),
        extra=extra,
        training=learned,
        feed_check=check,
    )
    write_text(out["rst"], text)


def _lumping_section(cases, liquid, info, out: dict) -> tuple[str, ...]:
    """The lumping study's figure and display table written, and its words with the figure (rst lines)."""
    import json

    from pbmdem.coupling.lumping import CASE_COLUMNS, LIQUID_COLUMNS
    from pbmdem.plotting import save_figure

    from .findings import image_directive
    from .lumping import lumping_figure, lumping_table, lumping_words, turn_speeds

    what = "lumping study (1-D against 2-D PBM)"
    table = read_table(cases, what, columns=CASE_COLUMNS, dtype={"feed": str, "failed": str})
    table["failed"] = table.failed.fillna("")
    per_size = read_table(liquid, "lumping study's liquid per size class", columns=LIQUID_COLUMNS)
    facts = {}
    if info is not None:
        try:
            facts = json.loads(Path(info).read_text())
        except (OSError, ValueError) as exc:
            raise InputFileError(f"lumping study's cost {info} cannot be read as JSON: {exc}") from None
    save_figure(lumping_figure(table, per_size), out["lumping_png"])
    turn1, turn2 = turn_speeds(table)
    turns = " and ".join(f"{t:g} rpm" if t is not None else "none" for t in (turn1, turn2))
    write_table(
        out["lumping_csv"],
        out["lumping_html"],
        lumping_table(table),
        "What lumping leaves out: final sizes of the 1-D and the 2-D PBM",
        f"PBM-ANN (the surrogate's mean) with the lumped and the size x liquid PBM on the same cases; the speed "
        f"above which the granules get smaller: {turns} (1-D and 2-D). Relative differences (2-D - 1-D) / 1-D.",
        keys=2,
    )
    return (
        lumping_words(table, per_size, facts),
        "",
        image_directive(out["lumping_png"]),
        "   :width: 640px",
        "   :alt: final d50 of the lumped and the two-dimensional PBM against speed, binder rate and feed",
        "",
    )
