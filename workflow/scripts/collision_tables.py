"""Snakemake rule collision_tables: aggregate the per-point tables of the grid."""
from pbmdem.collisions import aggregate
from pbmdem.dem import run_table

aggregate(snakemake.input.tables, snakemake.output.table)
aggregate(snakemake.input.walls, snakemake.output.walls)
run_table(snakemake.input.summaries, snakemake.output.runs)
