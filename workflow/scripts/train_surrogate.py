"""Snakemake script of rule train_surrogate (thin: all logic is in pbmdem.surrogate)."""

from pbmdem.config import SurrogateTraining
from pbmdem.joblog import rule_job
from pbmdem.surrogate.train import train_and_report

sm = snakemake  # noqa: F821
# each CV fold and hyperparameter candidate is logged as it finishes: job log and terminal
with rule_job(sm.log[0]):
    training = SurrogateTraining.from_dict(sm.params.training)
    train_and_report(
        sm.input.table,
        model_path=sm.output.model,
        metadata_path=sm.output.metadata,
        metrics_path=sm.output.metrics,
        parity_path=sm.output.parity,
        settings=training.surrogate.to_dict(),
        impeller_radius=training.granulator.impeller.tip_radius,
        n_jobs=sm.threads,
        velocity_table=sm.input.velocity,
        wall_table=sm.input.walls,
        wall_velocity_table=sm.input.wall_velocities,
    )
