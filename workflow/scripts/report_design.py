"""Snakemake rule report_design: the design-space and calibration-check tables in display form (thin)."""

from pbmdem.joblog import log_job
from pbmdem.report.outputs import write_design_tables

sm = snakemake  # noqa: F821
log_job(sm.log[0])
write_design_tables(
    design=sm.input.design,
    check=sm.input.check,
    third_key=sm.params.third_key,
    confidence=sm.params.confidence,
    out=dict(sm.output.items()),
)
