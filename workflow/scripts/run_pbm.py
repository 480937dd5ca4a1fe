"""Snakemake script of rules pbm_constant and pbm_table (thin: all logic is in pbmdem.pbm)."""

import logging
from pathlib import Path

from pbmdem.config import PbmBatch
from pbmdem.joblog import log_job
from pbmdem.pbm.impact_breakage import impact_selection
from pbmdem.pbm.kernels import TableFrequency
from pbmdem.pbm.setup import run_batch
from pbmdem.pbm.wall_table import WallTable

log_job(snakemake.log[0])  # noqa: F821

batch = PbmBatch.from_dict(snakemake.params.batch)  # noqa: F821
kernel = snakemake.params.kernel  # noqa: F821
rpm = float(snakemake.wildcards.rpm)  # noqa: F821
source = selection = None  # the constant kernel of pbm.aggregation (and breakage's constant rate)
if kernel == "table":
    # DEM collision table (encounter frequencies) and its impact-velocity table, this feed's rows,
    # and the wall tables for breakage from impacts
    source = TableFrequency.from_csv(
        snakemake.input.table,
        distribution=batch.distribution,  # noqa: F821
        velocity_path=snakemake.input.velocities,  # noqa: F821
        walls=WallTable.from_csv(snakemake.input.walls, snakemake.input.wall_velocities, batch.distribution),  # noqa: F821
        extrapolation=batch.pbm.aggregation.table_extrapolation,
    )
    selection = impact_selection(batch.pbm, source)
result = run_batch(batch, source, rpm, selection=selection)
result.info["kernel_source"] = kernel
paths = result.save(Path(snakemake.output.summary).parent)  # noqa: F821
logging.info(
    "PBM %s kernel rpm %g %s: %d steps, %.3f s; wrote %s",
    kernel,
    rpm,
    batch.distribution,
    result.info["steps"],
    result.info["wall_time_s"],
    sorted(str(p) for p in paths.values()),
)
