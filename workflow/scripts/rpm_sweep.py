"""Snakemake rule rpm_sweep: PBM-ANN over a fine range of impeller speeds (thin)."""

from pbmdem.config import CoupledLoop, Sweep
from pbmdem.coupling.sweep import rpm_sweep
from pbmdem.joblog import rule_job

sm = snakemake  # noqa: F821
# one line per interval and per speed (wall times, out-of-domain counts): job log and terminal
with rule_job(sm.log[0]):
    rpm_sweep(
        CoupledLoop.from_dict(sm.params.loop),
        Sweep.from_dict(sm.params.sweep),
        sm.input.model,
        sm.output.table,
        sm.output.plot,
    )
