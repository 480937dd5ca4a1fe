"""Snakemake rule rpm_sweep: PBM-ANN over a fine range of impeller speeds (thin)."""

from pbmdem.config import CoupledLoop, Sweep
from pbmdem.coupling.sweep import rpm_sweep
from pbmdem.joblog import log_job

# one line per interval and per speed (wall times, out-of-domain counts): job log and terminal
log_job(snakemake.log[0])  # noqa: F821
rpm_sweep(
    CoupledLoop.from_dict(snakemake.params.loop),
    Sweep.from_dict(snakemake.params.sweep),  # noqa: F821
    snakemake.input.model,
    snakemake.output.table,
    snakemake.output.plot,
)  # noqa: F821
