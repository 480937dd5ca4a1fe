# pbmdem: multi-scale PBM-DEM model of high-shear wet granulation.
# Reproduce everything with `snakemake --cores 2`; a tiny configuration for tests is in
# config/test.yaml. All logic is in src/pbmdem; rules only name inputs, outputs and params.
import os
import sys

from snakemake.utils import min_version, validate

min_version("8.0")

# pbmdem is importable by the rule scripts whatever environment runs them (the project's venv,
# a conda environment from envs/, or a cluster job): src/ goes on the module path.
_SRC = os.path.join(workflow.basedir, "src")
sys.path.insert(0, _SRC)
os.environ.update(PYTHONPATH=os.pathsep.join(p for p in (_SRC, os.environ.get("PYTHONPATH")) if p))


# The default configuration, unless one is given with --configfile/--config (Snakemake would
# otherwise merge the two, e.g. the default grid's distributions into the tiny test bowl).
if not config:

    configfile: "config/config.yaml"


# The same tidy list of every error (key, value, allowed) as the pbmdem CLI, and duplicate keys
# in the config files refused (YAML would silently keep the last one); then Snakemake's own
# validation, which only fills in the schema's defaults once the config is known to be valid.
from pbmdem.config import ConfigError, load_yaml
from pbmdem.config import validate as validate_config

try:
    for _path in workflow.configfiles:
        load_yaml(_path, "config file")
    validate_config(config)
except ConfigError as _exc:
    print(f"pbmdem: error: {_exc}", file=sys.stderr)
    sys.exit(1)
validate(config, "workflow/schemas/config.schema.yaml")


include: "rules/common.smk"


wildcard_constraints:
    rpm=r"[0-9]+(\.[0-9]+)?",
    dist=r"[A-Za-z][A-Za-z0-9_-]*",
    rep=r"[0-9]+",


include: "rules/dem.smk"
include: "rules/surrogate.smk"
include: "rules/pbm.smk"
include: "rules/validation.smk"


rule all:
    default_target: True
    input:
        all_targets(),
