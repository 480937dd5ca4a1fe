"""Snakemake rule comparison: the comparison table of every validation speed."""

from pbmdem.atomic import write_csv
from pbmdem.joblog import rule_job
from pbmdem.validation.comparison import compare

sm = snakemake  # noqa: F821
with rule_job(sm.log[0]):
    write_csv(
        sm.output.table,
        compare(sm.params.validation_dir, sm.params.rpms, sm.params.grid_rpm, sm.params.replicates),
    )
