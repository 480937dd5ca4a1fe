"""Snakemake rule report: the self-contained results/report/report.html from the registered files (thin)."""

from pbmdem.joblog import log_job
from pbmdem.report.html import SPEED_FIGURES, build_report

sm = snakemake  # noqa: F821
log_job(sm.log[0])
tables = (
    "settings",
    "speeds",
    "provenance",
    "targets",
    "comparison_d50",
    "comparison_accuracy",
    "comparison_cost",
    "comparison_domain",
)
speeds = {
    rpm: {
        **{key: sm.input[f"speed{k}_{key}"] for key in SPEED_FIGURES},
        "out_of_domain": sm.input[f"speed{k}_domain_csv"],
    }
    for k, rpm in enumerate(sm.params.rpms)
}
build_report(
    html_path=sm.output.html,
    tables={name: sm.input[f"table_{name}"] for name in tables},
    speeds=speeds,
    comparison=sm.input.comparison,
    sweep=sm.input.sweep,
    sweep_plot=sm.input.sweep_plot,
    metrics=sm.input.metrics,
    parity=sm.input.parity,
    metadata=sm.input.metadata,
    runs=sm.input.runs,
    collisions=sm.input.collisions,
    proposals=sm.input.proposals,
    findings=sm.input.findings_rst,
    speed_study={
        "table": sm.input.speed_response,
        "flow": sm.input.flow_development,
        "plot": sm.input.speed_plot,
        "velocity_plot": sm.input.velocity_plot,
    },
)
