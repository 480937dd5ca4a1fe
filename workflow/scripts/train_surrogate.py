"""Snakemake script of rule train_surrogate (thin: all logic is in pbmdem.surrogate)."""

from pbmdem.config import SurrogateTraining
from pbmdem.joblog import log_job
from pbmdem.surrogate.train import train_and_report

# each CV fold and hyperparameter candidate is logged as it finishes: job log and terminal
log_job(snakemake.log[0])  # noqa: F821

training = SurrogateTraining.from_dict(snakemake.params.training)  # noqa: F821
train_and_report(
    snakemake.input.table,  # noqa: F821
    model_path=snakemake.output.model,  # noqa: F821
    metadata_path=snakemake.output.metadata,  # noqa: F821
    metrics_path=snakemake.output.metrics,  # noqa: F821
    parity_path=snakemake.output.parity,  # noqa: F821
    settings=training.surrogate.to_dict(),
    impeller_radius=training.granulator.impeller.tip_radius,
    n_jobs=snakemake.threads,  # noqa: F821
    velocity_table=snakemake.input.velocity,  # noqa: F821
    wall_table=snakemake.input.walls,  # noqa: F821
    wall_velocity_table=snakemake.input.wall_velocities,  # noqa: F821
    pbm_samples=snakemake.params.pbm_samples,  # noqa: F821
)
