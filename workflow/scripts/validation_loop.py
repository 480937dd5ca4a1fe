"""Snakemake rules pbm_dem_coupled / pbm_ann_coupled / pbm_constant_calibrated (thin)."""

import os

from pbmdem import coupling
from pbmdem.atomic import write_csv
from pbmdem.config import CoupledLoop, DemExecution
from pbmdem.joblog import rule_job

sm = snakemake  # noqa: F821
# interval lines (DEM and PBM wall time, out-of-domain count) and DEM progress: job log and terminal
with rule_job(sm.log[0]):
    loop = CoupledLoop.from_dict(sm.params.loop)
    rpm = float(sm.wildcards.rpm)
    outdir = sm.params.outdir
    method = sm.params.method
    if method == "dem":
        if sm.resources.get("mpi"):
            os.environ["PBMDEM_MPI_LAUNCHER"] = str(sm.resources.mpi)
        execution = DemExecution.of_job(sm.config, sm.resources)
        coupling.pbm_dem(loop, rpm, outdir, execution, replicate=int(sm.wildcards.rep))
    elif method == "ann":
        coupling.pbm_ann(loop, sm.input.model, rpm, outdir)
        # the PBM-ANN band: once per ensemble member of the surrogate (not part of PBM-ANN's timing)
        write_csv(sm.output.members, coupling.pbm_ann_members(loop, sm.input.model, rpm))
    else:
        coupling.pbm_constant(loop, sm.input.model, rpm, outdir)
