"""Snakemake rule dem_point: run LIGGGHTS for one operating point and tabulate its collisions."""

import logging
import os

from pbmdem.config import DemExecution, DemPoint
from pbmdem.dem import plan_point, run_point
from pbmdem.joblog import log_job

# progress lines (phase, step of total, particles, elapsed, remaining) go to the job log and the terminal
log_job(snakemake.log[0])  # noqa: F821
# params hold what fixes the result; ranks and timeout come from the config and the job's resources
point = DemPoint.from_dict(snakemake.params.point)  # noqa: F821
execution = DemExecution.of_job(snakemake.config, snakemake.resources)  # noqa: F821
if snakemake.resources.get("mpi"):  # noqa: F821
    os.environ["PBMDEM_MPI_LAUNCHER"] = str(snakemake.resources.mpi)  # noqa: F821
plan = plan_point(point, float(snakemake.wildcards.rpm), replicate=int(snakemake.wildcards.rep))  # noqa: F821
summary = run_point(plan, snakemake.params.run_dir, execution, bed_dir=snakemake.params.bed_dir)  # noqa: F821
logging.info("finished %s", summary)
