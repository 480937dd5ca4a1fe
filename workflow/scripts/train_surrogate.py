"""Snakemake script of rule train_surrogate (thin: all logic is in pbmdem.surrogate)."""

import logging

from pbmdem.surrogate.train import train_and_report

logging.basicConfig(filename=snakemake.log[0], filemode="w", level=logging.INFO,  # noqa: F821
                    format="%(asctime)s %(levelname)s %(name)s: %(message)s")
logging.captureWarnings(True)

train_and_report(
    snakemake.input.table,  # noqa: F821
    model_path=snakemake.output.model,  # noqa: F821
    metadata_path=snakemake.output.metadata,  # noqa: F821
    metrics_path=snakemake.output.metrics,  # noqa: F821
    parity_path=snakemake.output.parity,  # noqa: F821
    settings=snakemake.params.settings,  # noqa: F821
    impeller_radius=float(snakemake.params.impeller_radius),  # noqa: F821
    n_jobs=snakemake.threads,  # noqa: F821
    velocity_table=snakemake.input.velocity,  # noqa: F821
)
