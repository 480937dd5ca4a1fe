"""Snakemake rule dem_bed: insert and settle the bed of one size distribution and replicate."""

import logging
import os

from pbmdem.config import DemExecution, DemPoint
from pbmdem.dem.plan import plan_bed
from pbmdem.dem.run import settle_bed
from pbmdem.joblog import log_job

log_job(snakemake.log[0])  # noqa: F821
point = DemPoint.from_dict(snakemake.params.point)  # noqa: F821
execution = DemExecution.of_job(snakemake.config, snakemake.resources)  # noqa: F821
if snakemake.resources.get("mpi"):  # noqa: F821
    os.environ["PBMDEM_MPI_LAUNCHER"] = str(snakemake.resources.mpi)  # noqa: F821
bed = plan_bed(point, replicate=int(snakemake.wildcards.rep))  # noqa: F821
record = settle_bed(bed, snakemake.params.bed_dir, execution)  # noqa: F821
logging.info("settled bed %s: %.1f s of LIGGGHTS", bed.bed_id, record["liggghts_wall_time_s"])
