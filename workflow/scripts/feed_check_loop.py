"""Snakemake rule feed_check_dem: one PBM-DEM loop of the feed check's case (thin)."""

import os

from pbmdem import coupling
from pbmdem.config import CoupledLoop, DemExecution, SizeDistribution
from pbmdem.coupling.studies import feed_case, with_feed
from pbmdem.joblog import log_job

sm = snakemake  # noqa: F821
# interval lines (DEM and PBM wall time) and DEM progress: job log and terminal
log_job(sm.log[0])
feeds = {name: SizeDistribution.from_dict(sizes) for name, sizes in sm.params.feeds.items()}
loop = with_feed(CoupledLoop.from_dict(sm.params.loop), sm.params.feed, feed_case(feeds, sm.params.feed))
if sm.resources.get("mpi"):
    os.environ["PBMDEM_MPI_LAUNCHER"] = str(sm.resources.mpi)
execution = DemExecution.of_job(sm.config, sm.resources)
coupling.pbm_dem(loop, float(sm.params.rpm), sm.params.outdir, execution, replicate=int(sm.wildcards.rep))
