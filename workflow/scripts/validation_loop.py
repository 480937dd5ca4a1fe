"""Snakemake rules pbm_dem_coupled / pbm_ann_coupled / pbm_constant_calibrated (thin)."""
import logging

import os

from pbmdem import coupling
from pbmdem.dem import with_execution

# interval lines (DEM and PBM wall time, out-of-domain count) and DEM progress: job log and terminal
logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s",
                    handlers=[logging.FileHandler(snakemake.log[0]), logging.StreamHandler()])  # noqa: F821
logging.captureWarnings(True)
# params hold what fixes the result; ranks and timeout come from the live config and the job
cfg = with_execution(snakemake.params.config, snakemake.config, snakemake.resources)  # noqa: F821
if snakemake.resources.get("mpi"):  # noqa: F821
    os.environ["PBMDEM_MPI_LAUNCHER"] = str(snakemake.resources.mpi)  # noqa: F821
rpm = float(snakemake.wildcards.rpm)  # noqa: F821
coupling.run_method(snakemake.params.method, cfg, rpm, snakemake.params.outdir,  # noqa: F821
                    model_path=snakemake.input.get("model"))  # noqa: F821
