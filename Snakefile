# pbmdem: multi-scale PBM-DEM model of high-shear wet granulation.
# Reproduce everything with `snakemake --cores 2`; a tiny configuration for tests is in
# config/test.yaml. All logic is in src/pbmdem; rules only name inputs, outputs and params.
from snakemake.utils import min_version, validate

min_version("8.0")


configfile: "config/config.yaml"


validate(config, "workflow/schemas/config.schema.yaml")

from pbmdem.config import check_config

check_config(config)


include: "rules/common.smk"
include: "rules/dem.smk"
include: "rules/surrogate.smk"
include: "rules/pbm.smk"
include: "rules/validation.smk"


rule all:
    default_target: True
    input:
        all_targets(),
