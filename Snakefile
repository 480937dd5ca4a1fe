# pbmdem: multi-scale PBM-DEM model of high-shear wet granulation.
# Reproduce everything with `snakemake --cores 2`; a tiny configuration for tests is in
# config/test.yaml. All logic is in src/pbmdem; rules only name inputs, outputs and params.
import os
import sys

from snakemake.utils import min_version

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


# The settings layer of pbmdem, the same path as the pbmdem command line: duplicate keys in the
# config files refused, the schema checked once with its defaults filled in, the checks a schema
# cannot express, every error listed tidily (key, value, allowed). CFG is the typed config;
# `config` is completed in place so that rule scripts read the same values.
from pbmdem.config import Config, ConfigError, load_yaml
from pbmdem.dem.plan import check_workflow_plans

try:
    for _path in workflow.configfiles:
        load_yaml(_path, "config file")
    CFG = Config.from_mapping(config)
    # every DEM run the workflow would start is planned and held to dem.limits before the DAG
    check_workflow_plans(CFG)
except ConfigError as _exc:
    print(f"pbmdem: error: {_exc}", file=sys.stderr)
    sys.exit(1)
config.update(CFG.to_dict())


include: "rules/common.smk"


# A dry run (-n) ends with an estimate of the DEM work it scheduled (grid runs and PBM-DEM
# coupling intervals) from the measured throughput of the finished runs (results/dem/runs.csv) or
# the reference machine's: the number to size a cluster job by. Printed at exit, after the job table.
if dry_run_requested(sys.argv[1:]):
    import atexit

    atexit.register(print_runtime_estimate)


wildcard_constraints:
    rpm=r"[0-9]+(\.[0-9]+)?",
    dist=r"[A-Za-z][A-Za-z0-9_-]*",
    rep=r"[0-9]+",


include: "rules/dem.smk"
include: "rules/surrogate.smk"
include: "rules/pbm.smk"
include: "rules/validation.smk"
include: "rules/design.smk"
include: "rules/report.smk"


rule all:
    default_target: True
    input:
        all_targets(),
