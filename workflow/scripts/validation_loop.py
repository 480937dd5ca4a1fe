"""Snakemake rules pbm_dem_coupled / pbm_ann_coupled / pbm_constant_calibrated (thin)."""
import logging

from pbmdem import coupling

# interval lines (DEM and PBM wall time, out-of-domain count) and DEM progress: job log and terminal
logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s",
                    handlers=[logging.FileHandler(snakemake.log[0]), logging.StreamHandler()])  # noqa: F821
logging.captureWarnings(True)
cfg = snakemake.params.config  # noqa: F821
rpm = float(snakemake.wildcards.rpm)  # noqa: F821
coupling.run_method(snakemake.params.method, cfg, rpm, snakemake.params.outdir,  # noqa: F821
                    model_path=snakemake.input.get("model"))  # noqa: F821
