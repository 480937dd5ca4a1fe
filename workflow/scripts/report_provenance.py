"""Snakemake rule report_provenance: configuration hashes, git commit and software versions (thin).

The configuration hash is that of the job's completed configuration (`snakemake.config`, which
the Snakefile completes from the typed config), like the execution settings a DEM job reads; the
rule's params are the settings without the execution settings, so that changing only those
reruns nothing (docs/validation.md, "Report"). The project (this script's checkout) and the working
directory are recorded in the table, not as params: moving the project reruns nothing."""

import os
from pathlib import Path

from pbmdem.joblog import log_job
from pbmdem.report.outputs import write_provenance

sm = snakemake  # noqa: F821
log_job(sm.log[0])
write_provenance(
    config=sm.config,
    settings=sm.params.settings,
    basedir=Path(sm.scriptdir).resolve().parents[1],
    workdir=os.getcwd(),
    runs=sm.input.runs,
    metadata=sm.input.metadata,
    out={"csv": sm.output.csv, "html": sm.output.html},
)
