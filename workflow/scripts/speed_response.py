"""Snakemake rule speed_response: encounter rate vs impeller speed and the flow-development check."""
import pandas as pd

from pbmdem.atomic import write_csv
from pbmdem.encounter_study import flow_development, plot_impact_velocities, plot_speed_response, speed_response

response = speed_response(pd.read_csv(snakemake.input.replicates))
write_csv(snakemake.output.table, response)
write_csv(snakemake.output.flow, flow_development(pd.read_csv(snakemake.input.runs)))
plot_speed_response(response, snakemake.output.plot)
plot_impact_velocities(pd.read_csv(snakemake.input.velocities), snakemake.output.velocity_plot)
