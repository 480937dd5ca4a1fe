"""Snakemake rule dem_point: run LIGGGHTS for one operating point and tabulate its collisions."""
import logging

from pbmdem.dem import run_operating_point

# progress lines (phase, step of total, particles, elapsed, remaining) go to the job log and the terminal
logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s",
                    handlers=[logging.FileHandler(snakemake.log[0]), logging.StreamHandler()])  # noqa: F821
summary = run_operating_point(
    snakemake.params.point,
    float(snakemake.wildcards.rpm),
    snakemake.wildcards.dist,
    snakemake.params.run_dir,
    replicate=int(snakemake.wildcards.rep),
)
logging.info("finished %s", summary)
