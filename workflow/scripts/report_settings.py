"""Snakemake rule report_settings: the process-settings and impeller-speed tables (thin)."""

import logging

from pbmdem.report.outputs import write_settings

sm = snakemake  # noqa: F821
logging.basicConfig(
    level=logging.INFO,
    format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    handlers=[logging.FileHandler(sm.log[0]), logging.StreamHandler()],
)
logging.captureWarnings(True)
write_settings(
    **sm.params.settings,
    out={name: sm.output[name] for name in ("settings_csv", "settings_html", "speeds_csv", "speeds_html")},
)
