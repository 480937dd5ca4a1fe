"""Snakemake script of rules pbm_constant and pbm_table (thin: all logic is in pbmdem.pbm)."""

import logging
from pathlib import Path

from pbmdem.pbm import run_pbm
from pbmdem.pbm.cli import make_source

logging.basicConfig(filename=snakemake.log[0], filemode="w", level=logging.INFO,  # noqa: F821
                    format="%(asctime)s %(levelname)s %(name)s: %(message)s")
logging.captureWarnings(True)

kernel = snakemake.params.kernel  # noqa: F821
config = snakemake.params.config  # noqa: F821
dist = snakemake.params.dist  # noqa: F821
if kernel == "table":
    # DEM collision table (encounter frequencies) and its impact-velocity table
    source = make_source("table", config, snakemake.input.table, distribution=dist,  # noqa: F821
                         velocity_table=snakemake.input.velocities)  # noqa: F821
else:
    source = None  # ConstantFrequency(pbm.aggregation.constant_frequency)
result = run_pbm(config, source, snakemake.params.rpm, dist)  # noqa: F821
result.info["kernel_source"] = kernel
paths = result.save(Path(snakemake.output.summary).parent)  # noqa: F821
logging.info("PBM %s kernel rpm %s %s: %d steps, %.3f s; wrote %s", kernel, snakemake.params.rpm,  # noqa: F821
             dist, result.info["steps"], result.info["wall_time_s"], sorted(str(p) for p in paths.values()))
