"""Snakemake rule sensitivity: Sobol' indices of PBM-ANN's final d10/d50/d90 (thin)."""

from pbmdem.config import CoupledLoop, Sensitivity
from pbmdem.design.outputs import write_sensitivity
from pbmdem.joblog import log_job

sm = snakemake  # noqa: F821
log_job(sm.log[0])
write_sensitivity(
    CoupledLoop.from_dict(sm.params.loop),
    sm.input.model,
    # as many processes as the job's threads (the results do not depend on it)
    Sensitivity.from_dict(sm.params.sensitivity).replace(n_jobs=sm.threads),
    sm.output.table,
    sm.output.figure,
    sm.output.info,
)
