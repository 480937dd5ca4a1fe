"""Snakemake rule dem_bed: insert and settle the bed of one size distribution and replicate."""

import logging
import os

from pbmdem.config import DemExecution, DemPoint
from pbmdem.dem.plan import plan_bed
from pbmdem.dem.run import settle_bed
from pbmdem.joblog import rule_job

sm = snakemake  # noqa: F821
with rule_job(sm.log[0]):
    point = DemPoint.from_dict(sm.params.point)
    execution = DemExecution.of_job(sm.config, sm.resources)
    if sm.resources.get("mpi"):
        os.environ["PBMDEM_MPI_LAUNCHER"] = str(sm.resources.mpi)
    bed = plan_bed(point, replicate=int(sm.wildcards.rep))
    record = settle_bed(point, bed, sm.params.bed_dir, execution)
    logging.info("settled bed %s: %.1f s of LIGGGHTS", bed.bed_id, record["liggghts_wall_time_s"])
