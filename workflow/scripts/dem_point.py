"""Snakemake rule dem_point: run LIGGGHTS for one operating point and tabulate its collisions."""
import logging

from pbmdem.dem import run_operating_point

logging.basicConfig(filename=snakemake.log[0], level=logging.INFO)
summary = run_operating_point(
    snakemake.params.point,
    float(snakemake.wildcards.rpm),
    snakemake.wildcards.dist,
    snakemake.params.run_dir,
    replicate=int(snakemake.wildcards.rep),
)
logging.info("finished %s", summary)
