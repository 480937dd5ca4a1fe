"""Snakemake rule dem_point: run LIGGGHTS for one operating point and tabulate its collisions."""

import logging
import os

from pbmdem.config import DemExecution, DemPoint
from pbmdem.dem import run_operating_point
from pbmdem.joblog import rule_job

sm = snakemake  # noqa: F821
# progress lines (phase, step of total, particles, elapsed, remaining) go to the job log and the terminal
with rule_job(sm.log[0]):
    # params hold what fixes the result; ranks and timeout come from the config and the job's resources
    point = DemPoint.from_dict(sm.params.point)
    execution = DemExecution.of_job(sm.config, sm.resources)
    if sm.resources.get("mpi"):
        os.environ["PBMDEM_MPI_LAUNCHER"] = str(sm.resources.mpi)
    summary = run_operating_point(
        point,
        float(sm.wildcards.rpm),
        sm.params.run_dir,
        execution,
        replicate=int(sm.wildcards.rep),
        bed_dir=sm.params.bed_dir,
    )
    logging.info("finished %s", summary)
