"""Snakemake rules pbm_dem_coupled / pbm_ann_coupled / pbm_constant_calibrated (thin)."""

import os
from pathlib import Path

from pbmdem import coupling
from pbmdem.atomic import write_csv, write_json
from pbmdem.config import CoupledLoop, DemExecution
from pbmdem.joblog import log_job

# interval lines (DEM and PBM wall time, out-of-domain count) and DEM progress: job log and terminal
log_job(snakemake.log[0])  # noqa: F821
loop = CoupledLoop.from_dict(snakemake.params.loop)  # noqa: F821
rpm = float(snakemake.wildcards.rpm)  # noqa: F821
outdir = snakemake.params.outdir  # noqa: F821
method = snakemake.params.method  # noqa: F821
if method == "dem":
    if snakemake.resources.get("mpi"):  # noqa: F821
        os.environ["PBMDEM_MPI_LAUNCHER"] = str(snakemake.resources.mpi)  # noqa: F821
    execution = DemExecution.of_job(snakemake.config, snakemake.resources)  # noqa: F821
    # the grid's run of the feed at this speed and its settled bed, where the grid has them
    grid_dem = snakemake.params.grid_dem  # noqa: F821
    replicate = int(snakemake.wildcards.rep)  # noqa: F821
    coupling.pbm_dem(loop, rpm, outdir, execution, replicate, grid_dem.get("grid_run"), grid_dem.get("bed"))
elif method == "ann":
    outcome = coupling.pbm_ann(loop, snakemake.input.model, rpm, outdir)  # noqa: F821
    # the speed of one batch as a benchmark measures it (warm, median of several; the loop above
    # was the first batch of this process): the comparison's speed ratio
    warm = coupling.warm_batch_times(loop, snakemake.input.model, rpm)  # noqa: F821
    write_json(Path(outdir) / "timing.json", outcome.totals | warm)
    # the PBM-ANN band: once per ensemble member of the surrogate (not part of PBM-ANN's timing)
    write_csv(snakemake.output.members, coupling.pbm_ann_members(loop, snakemake.input.model, rpm))  # noqa: F821
else:
    coupling.pbm_constant(loop, snakemake.input.model, rpm, outdir)  # noqa: F821
