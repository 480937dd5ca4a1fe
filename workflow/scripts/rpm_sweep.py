"""Snakemake rule rpm_sweep: PBM-ANN over a fine range of impeller speeds (thin)."""
import logging

from pbmdem import coupling

# one line per interval and per speed (wall times, out-of-domain counts): job log and terminal
logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s",
                    handlers=[logging.FileHandler(snakemake.log[0]), logging.StreamHandler()])  # noqa: F821
logging.captureWarnings(True)
coupling.rpm_sweep(snakemake.params.config, snakemake.input.model,  # noqa: F821
                   snakemake.output.table, snakemake.output.plot)  # noqa: F821
