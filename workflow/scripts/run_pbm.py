"""Snakemake script of rule pbm_constant (thin: all logic is in pbmdem.pbm)."""

import logging
from pathlib import Path

from pbmdem.pbm import run_pbm

logging.basicConfig(filename=snakemake.log[0], filemode="w", level=logging.INFO,  # noqa: F821
                    format="%(asctime)s %(levelname)s %(name)s: %(message)s")
logging.captureWarnings(True)

result = run_pbm(snakemake.params.config, None, snakemake.params.rpm, snakemake.params.dist)  # noqa: F821
result.info["kernel_source"] = "constant"
paths = result.save(Path(snakemake.output.summary).parent)  # noqa: F821
logging.info("PBM constant kernel rpm %s %s: %d steps, %.3f s; wrote %s", snakemake.params.rpm,  # noqa: F821
             snakemake.params.dist, result.info["steps"], result.info["wall_time_s"],  # noqa: F821
             sorted(str(p) for p in paths.values()))
