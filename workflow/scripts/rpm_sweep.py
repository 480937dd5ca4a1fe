"""Snakemake rule rpm_sweep: PBM-ANN over a fine range of impeller speeds (thin)."""

import logging

from pbmdem.config import CoupledLoop, Sweep
from pbmdem.coupling.sweep import rpm_sweep

# one line per interval and per speed (wall times, out-of-domain counts): job log and terminal
logging.basicConfig(
    level=logging.INFO,
    format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    handlers=[logging.FileHandler(snakemake.log[0]), logging.StreamHandler()],
)  # noqa: F821
logging.captureWarnings(True)
rpm_sweep(
    CoupledLoop.from_dict(snakemake.params.loop),
    Sweep.from_dict(snakemake.params.sweep),  # noqa: F821
    snakemake.input.model,
    snakemake.output.table,
    snakemake.output.plot,
)  # noqa: F821
