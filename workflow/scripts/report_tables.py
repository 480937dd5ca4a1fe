"""Snakemake rule report_tables: the comparison table in display form and the targets (thin)."""

from pbmdem.joblog import log_job
from pbmdem.report.outputs import write_comparison

sm = snakemake  # noqa: F821
log_job(sm.log[0])
write_comparison(comparison=sm.input.comparison, out=dict(sm.output.items()))
