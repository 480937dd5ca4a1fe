"""Snakemake rule speed_response: encounter rate vs impeller speed and the flow-development check."""

from pbmdem.atomic import write_csv
from pbmdem.dem.speed_response import flow_development, plot_impact_velocities, plot_speed_response, speed_response
from pbmdem.joblog import rule_job
from pbmdem.tables import GRID_VELOCITIES, RUN_PAIRS, RUNS

sm = snakemake  # noqa: F821
with rule_job(sm.log[0]):
    response = speed_response(RUN_PAIRS.read(sm.input.replicates, "per-replicate collision table"))
    write_csv(sm.output.table, response)
    write_csv(sm.output.flow, flow_development(RUNS.read(sm.input.runs)))
    plot_speed_response(response, sm.output.plot)
    plot_impact_velocities(GRID_VELOCITIES.read(sm.input.velocities), sm.output.velocity_plot)
