"""Snakemake rule speed_response: encounter rate vs impeller speed and the flow-development check."""

from pbmdem.atomic import write_csv
from pbmdem.dem.speed_response import flow_development, plot_impact_velocities, plot_speed_response, speed_response
from pbmdem.readers import read_table

response = speed_response(read_table(snakemake.input.replicates, "per-replicate collision table"))  # noqa: F821
write_csv(snakemake.output.table, response)  # noqa: F821
write_csv(snakemake.output.flow, flow_development(read_table(snakemake.input.runs, "DEM run table")))  # noqa: F821
plot_speed_response(response, snakemake.output.plot)  # noqa: F821
plot_impact_velocities(
    read_table(snakemake.input.velocities, "impact-velocity table"),  # noqa: F821
    snakemake.output.velocity_plot,
)  # noqa: F821
