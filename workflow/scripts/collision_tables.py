"""Snakemake rule collision_tables: replicate means and standard errors of the grid's tables."""
from pbmdem.atomic import write_csv
from pbmdem.collisions import aggregate, read_tables
from pbmdem.dem import run_table

aggregate(snakemake.input.tables, snakemake.output.table)
aggregate(snakemake.input.walls, snakemake.output.walls, kind="walls")
aggregate(snakemake.input.velocities, snakemake.output.velocities, kind="velocities")
write_csv(snakemake.output.replicates, read_tables(snakemake.input.tables))
run_table(snakemake.input.summaries, snakemake.output.runs)
