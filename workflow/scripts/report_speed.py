"""Snakemake rule report_speed: the figures and the out-of-domain table of one validation speed (thin)."""

import logging

from pbmdem.report.outputs import write_speed

sm = snakemake  # noqa: F821
logging.basicConfig(
    level=logging.INFO,
    format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    handlers=[logging.FileHandler(sm.log[0]), logging.StreamHandler()],
)
logging.captureWarnings(True)
write_speed(
    validation_dir=sm.params.validation_dir,
    rpm=sm.wildcards.rpm,
    replicates=sm.params.replicates,
    process=sm.params.process,
    bands=sm.input.bands,
    model=sm.input.model,
    out={name: sm.output[name] for name in ("sizes", "psd", "liquid", "frequency", "domain_csv", "domain_html")},
)
