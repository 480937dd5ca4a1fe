"""The files of the report's table rules, one function per rule (rules/report.smk), each a display
table written as CSV and HTML; the figure rules are `figures.write_speed` and
`findings.write_findings` (they need scikit-learn, ~3 s to import, which these do not).
"""

from __future__ import annotations

from pbmdem.config import Config, Granulator, Pbm, SizeDistribution
from pbmdem.readers import read_table
from pbmdem.tables import COMPARISON

from .provenance import provenance
from .statements import target_sentences, targets
from .tables import calibration_check_table, comparison_tables, design_space_table, process_settings, speeds
from .words import write_titled_table


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
    write_titled_table(out["settings_csv"], out["settings_html"], settings, "settings")
    write_titled_table(
        out["speeds_csv"],
        out["speeds_html"],
        speeds(machine, validation_rpm, grid_rpm),
        "speeds",
        {"tip_radius_mm": 1e3 * machine.impeller.tip_radius},
    )


def write_comparison(*, comparison, out: dict) -> None:
    """The comparison table in display form and the targets. `out`: comparison_<name>_csv and
    comparison_<name>_html for name in d50, tails, accuracy, cost, domain; targets_csv, targets_html."""
    table = COMPARISON.read(comparison)
    for name, frame in comparison_tables(table).items():
        write_titled_table(out[f"comparison_{name}_csv"], out[f"comparison_{name}_html"], frame, f"comparison_{name}")
    write_titled_table(
        out["targets_csv"],
        out["targets_html"],
        targets(table),
        "targets",
        {},
        " ".join(target_sentences(table)),
        keys=3,
    )


def write_design_tables(*, design, check, third_key: str, confidence: float, out: dict) -> None:
    """The design space and the calibration check in display form. `out`: design_space_table_csv,
    design_space_table_html, calibration_check_csv, calibration_check_html."""
    table = read_table(design, "design-space table", columns=("rpm", "liquid_rate", third_key, "spec_status"))
    write_titled_table(
        out["design_space_table_csv"],
        out["design_space_table_html"],
        design_space_table(table, third_key),
        "design_space",
        {"points": len(table), "counts": list(table.spec_status.value_counts().items())},
        keys=3,
    )
    recovery = read_table(check, "calibration check", columns=("case", "parameter", "true", "estimate", "recovered"))
    recovered = int(recovery.recovered.astype(str).str.lower().eq("true").sum())
    write_titled_table(
        out["calibration_check_csv"],
        out["calibration_check_html"],
        calibration_check_table(recovery, confidence),
        "calibration_check",
        {"recovered": recovered, "cases": len(recovery)},
        keys=2,
    )


def write_provenance(*, config: dict, settings: dict, basedir, runs, metadata, out: dict, workdir=None) -> None:
    """The provenance table. `config`: the job's completed configuration; `settings`: the same without
    the execution settings; `basedir`: the project; `workdir`: where the workflow ran. `out`: csv, html."""
    table = provenance(Config.from_mapping(config).sha256(), settings, basedir, runs, metadata, workdir=workdir)
    write_titled_table(out["csv"], out["html"], table, "provenance")
