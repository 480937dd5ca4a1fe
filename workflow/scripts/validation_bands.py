"""Snakemake rule validation_bands: the PBM-DEM replicate band of one speed and the other models in it."""

from pbmdem.atomic import write_csv
from pbmdem.joblog import log_job
from pbmdem.validation.comparison import bands_of
from pbmdem.validation.results import load_speed

log_job(snakemake.log[0])  # noqa: F821
speed = load_speed(
    snakemake.params.validation_dir,
    snakemake.wildcards.rpm,  # noqa: F821
    snakemake.params.replicates,
)  # noqa: F821
write_csv(snakemake.output.bands, bands_of(speed))  # noqa: F821
