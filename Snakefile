# pbmdem: multi-scale PBM-DEM model of high-shear wet granulation.
# Reproduce everything with `snakemake --cores 2`; a tiny configuration for tests is in
# config/test.yaml. All logic is in src/pbmdem; rules only name inputs, outputs and params.
from snakemake.utils import min_version, validate

min_version("8.0")


# The default configuration, unless one is given with --configfile/--config (Snakemake would
# otherwise merge the two, e.g. the default grid's distributions into the tiny test bowl).
if not config:

    configfile: "config/config.yaml"


validate(config, "workflow/schemas/config.schema.yaml")

from pbmdem.config import check_config

check_config(config)


include: "rules/common.smk"


wildcard_constraints:
    rpm=r"[0-9]+(\.[0-9]+)?",
    dist=r"[A-Za-z][A-Za-z0-9_-]*",


include: "rules/dem.smk"
include: "rules/surrogate.smk"
include: "rules/pbm.smk"
include: "rules/validation.smk"


rule all:
    default_target: True
    input:
        all_targets(),
