"""Snakemake rule speed_response: encounter rate vs impeller speed and the flow-development check."""

from pbmdem.atomic import write_csv
from pbmdem.dem.speed_response import flow_development, plot_impact_velocities, plot_speed_response, speed_response
from pbmdem.joblog import log_job
from pbmdem.tables import GRID_VELOCITIES, RUN_PAIRS, RUNS

log_job(snakemake.log[0])  # noqa: F821
response = speed_response(RUN_PAIRS.read(snakemake.input.replicates, "per-replicate collision table"))  # noqa: F821
write_csv(snakemake.output.table, response)  # noqa: F821
write_csv(snakemake.output.flow, flow_development(RUNS.read(snakemake.input.runs)))  # noqa: F821
plot_speed_response(response, snakemake.output.plot)  # noqa: F821
plot_impact_velocities(
    GRID_VELOCITIES.read(snakemake.input.velocities),  # noqa: F821
    snakemake.output.velocity_plot,
)  # noqa: F821
