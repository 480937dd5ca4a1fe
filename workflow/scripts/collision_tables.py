"""Snakemake rule collision_tables: replicate means and standard errors of the grid's tables."""

from pbmdem.atomic import write_csv
from pbmdem.dem.collisions import aggregate, read_tables, run_table
from pbmdem.joblog import log_job

log_job(snakemake.log[0])  # noqa: F821
aggregate(snakemake.input.tables, snakemake.output.table)  # noqa: F821
aggregate(snakemake.input.walls, snakemake.output.walls, kind="walls")  # noqa: F821
aggregate(snakemake.input.velocities, snakemake.output.velocities, kind="velocities")  # noqa: F821
aggregate(snakemake.input.wall_velocities, snakemake.output.wall_velocities, kind="wall_velocities")  # noqa: F821
write_csv(snakemake.output.replicates, read_tables(snakemake.input.tables, "pairs"))  # noqa: F821
run_table(snakemake.input.summaries, snakemake.output.runs)  # noqa: F821
