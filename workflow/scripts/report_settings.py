"""Snakemake rule report_settings: the process-settings and impeller-speed tables (thin)."""

from pbmdem.joblog import log_job
from pbmdem.report.outputs import write_settings

sm = snakemake  # noqa: F821
log_job(sm.log[0])
write_settings(
    **sm.params.settings,
    out={name: sm.output[name] for name in ("settings_csv", "settings_html", "speeds_csv", "speeds_html")},
)
