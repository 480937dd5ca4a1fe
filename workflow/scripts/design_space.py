"""Snakemake rule design_space: PBM-ANN over speed x binder rate x a third factor (thin)."""

from pbmdem.config import CoupledLoop, DesignSpace
from pbmdem.design.outputs import write_design_space
from pbmdem.joblog import log_job

sm = snakemake  # noqa: F821
log_job(sm.log[0])
write_design_space(
    CoupledLoop.from_dict(sm.params.loop),
    sm.input.model,
    # as many processes as the job's threads (the results do not depend on it)
    DesignSpace.from_dict(sm.params.design).replace(n_jobs=sm.threads),
    sm.output.table,
    sm.output.maps,
    sm.output.info,
)
