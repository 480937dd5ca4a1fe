"""Snakemake rule report_tables: the comparison table in display form and the targets (thin)."""

import logging

from pbmdem.report.outputs import write_comparison

sm = snakemake  # noqa: F821
logging.basicConfig(
    level=logging.INFO,
    format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    handlers=[logging.FileHandler(sm.log[0]), logging.StreamHandler()],
)
logging.captureWarnings(True)
write_comparison(comparison=sm.input.comparison, out=dict(sm.output.items()))
