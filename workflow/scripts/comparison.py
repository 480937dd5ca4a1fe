"""Snakemake rule comparison: the comparison table of every validation speed."""

from pbmdem.atomic import write_csv
from pbmdem.joblog import log_job
from pbmdem.validation.comparison import compare

log_job(snakemake.log[0])  # noqa: F821
write_csv(
    snakemake.output.table,
    compare(
        snakemake.params.validation_dir,
        snakemake.params.rpms,  # noqa: F821
        snakemake.params.grid_rpm,
        snakemake.params.replicates,
    ),
)  # noqa: F821
