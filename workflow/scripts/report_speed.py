"""Snakemake rule report_speed: the figures and the out-of-domain table of one validation speed (thin)."""

from pbmdem.joblog import log_job
from pbmdem.report.figures import write_speed

sm = snakemake  # noqa: F821
log_job(sm.log[0])
write_speed(
    validation_dir=sm.params.validation_dir,
    rpm=sm.wildcards.rpm,
    replicates=sm.params.replicates,
    process=sm.params.process,
    bands=sm.input.bands,
    model=sm.input.model,
    out={name: sm.output[name] for name in ("sizes", "psd", "liquid", "frequency", "domain_csv", "domain_html")},
)
