"""Snakemake rule pair_samples: the surrogate's pair encounter frequency on the PBM-DEM loops' samples."""

from pbmdem.atomic import write_csv
from pbmdem.joblog import log_job
from pbmdem.surrogate import load_surrogate
from pbmdem.validation.pair_samples import loop_samples, pair_sample_table

log_job(snakemake.log[0])  # noqa: F821
samples = loop_samples(snakemake.params.validation_dir, snakemake.params.rpms, snakemake.params.replicates)  # noqa: F821
write_csv(snakemake.output.table, pair_sample_table(load_surrogate(snakemake.input.model), samples))  # noqa: F821
