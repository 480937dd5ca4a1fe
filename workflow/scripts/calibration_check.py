"""Snakemake rule calibration_check: calibration on data of known parameters (thin)."""

from pbmdem.config import Calibration, CoupledLoop
from pbmdem.design.outputs import write_calibration_check
from pbmdem.joblog import log_job

sm = snakemake  # noqa: F821
log_job(sm.log[0])
write_calibration_check(
    CoupledLoop.from_dict(sm.params.loop),
    sm.input.model,
    sm.params.validation_dir,
    sm.params.rpms,
    sm.params.replicates,
    Calibration.from_dict(sm.params.calibration),
    sm.threads,
    dict(sm.output.items()),
)
