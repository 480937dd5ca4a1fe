"""Snakemake rule rpm_sweep: PBM-ANN over a fine range of impeller speeds (thin)."""
import logging

from pbmdem import coupling

logging.basicConfig(filename=snakemake.log[0], level=logging.INFO)  # noqa: F821
logging.captureWarnings(True)
coupling.rpm_sweep(snakemake.params.config, snakemake.input.model,  # noqa: F821
                   snakemake.output.table, snakemake.output.plot)  # noqa: F821
