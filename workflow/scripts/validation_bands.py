"""Snakemake rule validation_bands: the PBM-DEM replicate band of one speed and the other models in it."""

from pbmdem.atomic import write_csv
from pbmdem.joblog import rule_job
from pbmdem.validation.comparison import bands_of
from pbmdem.validation.results import load_speed

sm = snakemake  # noqa: F821
with rule_job(sm.log[0]):
    speed = load_speed(sm.params.validation_dir, sm.wildcards.rpm, sm.params.replicates)
    write_csv(sm.output.bands, bands_of(speed))
