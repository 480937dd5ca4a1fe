"""Snakemake script of rules pbm_constant and pbm_table (thin: all logic is in pbmdem.pbm)."""

import logging
from pathlib import Path

from pbmdem.config import PbmBatch
from pbmdem.joblog import rule_job
from pbmdem.pbm.impact_breakage import impact_selection
from pbmdem.pbm.kernels import TableFrequency
from pbmdem.pbm.setup import run_batch
from pbmdem.pbm.wall_table import WallTable

sm = snakemake  # noqa: F821
with rule_job(sm.log[0]):
    batch = PbmBatch.from_dict(sm.params.batch)
    kernel = sm.params.kernel
    rpm = float(sm.wildcards.rpm)
    source = selection = None  # the constant kernel of pbm.aggregation (and breakage's constant rate)
    if kernel == "table":
        # DEM collision table (encounter frequencies) and its impact-velocity table, this feed's rows,
        # and the wall tables for breakage from impacts
        source = TableFrequency.from_csv(
            sm.input.table,
            distribution=batch.distribution,
            velocity_path=sm.input.velocities,
            walls=WallTable.from_csv(sm.input.walls, sm.input.wall_velocities, batch.distribution),
            extrapolation=batch.pbm.aggregation.table_extrapolation,
        )
        selection = impact_selection(batch.pbm, source)
    result = run_batch(batch, source, rpm, selection=selection)
    result.info["kernel_source"] = kernel
    paths = result.save(Path(sm.output.summary).parent)
    logging.info(
        "PBM %s kernel rpm %g %s: %d steps, %.3f s; wrote %s",
        kernel,
        rpm,
        batch.distribution,
        result.info["steps"],
        result.info["wall_time_s"],
        sorted(str(p) for p in paths.values()),
    )
