"""Snakemake rule collision_tables: replicate means and standard errors of the grid's tables."""

from pbmdem.atomic import write_csv
from pbmdem.dem.grid_tables import aggregate, read_tables, run_table
from pbmdem.joblog import rule_job

sm = snakemake  # noqa: F821
with rule_job(sm.log[0]):
    aggregate(sm.input.tables, sm.output.table)
    aggregate(sm.input.walls, sm.output.walls, kind="walls")
    aggregate(sm.input.velocities, sm.output.velocities, kind="velocities")
    aggregate(sm.input.wall_velocities, sm.output.wall_velocities, kind="wall_velocities")
    write_csv(sm.output.replicates, read_tables(sm.input.tables, "pairs"))
    run_table(sm.input.summaries, sm.output.runs)
