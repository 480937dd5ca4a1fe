"""Snakemake rule comparison: the comparison table of every validation speed."""

from pbmdem.atomic import write_csv
from pbmdem.validation.comparison import compare

write_csv(
    snakemake.output.table,
    compare(
        snakemake.params.validation_dir,
        snakemake.params.rpms,  # noqa: F821
        snakemake.params.grid_rpm,
        snakemake.params.replicates,
    ),
)  # noqa: F821
