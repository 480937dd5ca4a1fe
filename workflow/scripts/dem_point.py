"""Snakemake rule dem_point: run LIGGGHTS for one operating point and tabulate its collisions."""
import logging
import os

from pbmdem.dem import run_operating_point, with_execution

# progress lines (phase, step of total, particles, elapsed, remaining) go to the job log and the terminal
logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s",
                    handlers=[logging.FileHandler(snakemake.log[0]), logging.StreamHandler()])  # noqa: F821
# params hold what fixes the result; ranks and timeout come from the live config and the job
cfg = with_execution(snakemake.params.point, snakemake.config, snakemake.resources)  # noqa: F821
if snakemake.resources.get("mpi"):  # noqa: F821
    os.environ["PBMDEM_MPI_LAUNCHER"] = str(snakemake.resources.mpi)  # noqa: F821
summary = run_operating_point(
    cfg,
    float(snakemake.wildcards.rpm),
    snakemake.wildcards.dist,
    snakemake.params.run_dir,  # noqa: F821
    replicate=int(snakemake.wildcards.rep),  # noqa: F821
)
logging.info("finished %s", summary)
