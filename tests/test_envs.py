"""The per-stage conda environments in envs/ name every package their rules import.

Each rule's script is run up to its imports (and the pbmdem modules its code path loads lazily)
in a fresh interpreter in which every third-party package that the environment does not list
refuses to import. A package missing from an env file then fails here instead of on a user's
cluster.
"""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
import yaml

# conda package name -> import name, for the packages pbmdem uses
IMPORT_NAME = {
    "numpy": "numpy",
    "scipy": "scipy",
    "pandas": "pandas",
    "scikit-learn": "sklearn",
    "skops": "skops",
    "matplotlib-base": "matplotlib",
    "pyyaml": "yaml",
    "jsonschema": "jsonschema",
    "pydantic": "pydantic",
    "meshio": "meshio",
    "pyvista": "pyvista",
    "numba": "numba",
    "salib": "SALib",
    "jinja2": "jinja2",
}
# packages that come with the ones listed (conda installs their dependencies too)
IMPLIED = {
    "jsonschema": ["referencing", "jsonschema_specifications", "rpds", "attrs"],
    "numba": ["llvmlite"],
    "pydantic": ["pydantic_core", "annotated_types", "typing_extensions", "typing_inspection"],
    "salib": ["multiprocess", "dill"],
    "jinja2": ["markupsafe"],
}

# what each stage's rules load, including imports made inside functions on the rule's path
STAGE_MODULES = {
    "dem": [
        "pbmdem.dem",
        "pbmdem.dem.run",
        "pbmdem.dem.collisions",
        "pbmdem.dem.viewer",
        "pbmdem.dem.geometry",
        "pbmdem.dem.deck",
        "pbmdem.dem.engine",
        "pbmdem.dem.speed_response",
    ],
    "pbm": ["pbmdem.pbm", "pbmdem.pbm.setup", "pbmdem.pbm.results", "pbmdem.pbm.kernels"],
    "surrogate": ["pbmdem.surrogate", "pbmdem.surrogate.train", "pbmdem.surrogate.plots"],
    "validation": [
        "pbmdem.coupling",
        "pbmdem.coupling.sweep",
        "pbmdem.report",
        "pbmdem.report.outputs",
        "pbmdem.report.figures",
        "pbmdem.report.frequencies",
        "pbmdem.report.display",
        "pbmdem.report.provenance",
        "pbmdem.report.statements",
        "pbmdem.report.tables",
        "pbmdem.report.words",
        "pbmdem.report.findings",
        "pbmdem.report.breakage",
        "pbmdem.report.sensitivity",
        "pbmdem.report.lumping",
        "pbmdem.report.training",
        "pbmdem.validation.results",
        "pbmdem.surrogate",
        "pbmdem.pbm.setup",
        "pbmdem.dem",
        "pbmdem.dem.collisions",
        "pbmdem.dem.viewer",
        "pbmdem.design.outputs",
        "pbmdem.design.sensitivity",
        "SALib.sample.sobol",
        "SALib.analyze.sobol",
    ],
}

# building a PBM model imports its compiled rates (numba), in the stages that build models
for _stage in ("pbm", "validation"):
    STAGE_MODULES[_stage] = [*STAGE_MODULES[_stage], "pbmdem.pbm._compiled"]

BLOCKER = """
import importlib.abc, sys
ALLOWED = set({allowed!r})
GUARDED = set({guarded!r})
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        top = name.split(".")[0]
        if top in GUARDED and top not in ALLOWED:
            raise ImportError(f"{{top}} is not in the environment")
        return None
sys.meta_path.insert(0, Block())
import importlib
for module in {modules!r}:
    importlib.import_module(module)
print("ok")
"""


def env_packages(root, name):
    env = yaml.safe_load((root / "envs" / f"{name}.yaml").read_text())
    names = [d.split("=")[0] for d in env["dependencies"] if isinstance(d, str)]
    allowed = []
    for n in names:
        if n in IMPORT_NAME:
            allowed.append(IMPORT_NAME[n])
            allowed += IMPLIED.get(n, [])
    return allowed


def test_every_rule_names_an_existing_env(root):
    for smk in (root / "rules").glob("*.smk"):
        for env in re.findall(r'conda:\s*\n\s*"\.\./envs/([a-z_]+)\.yaml"', smk.read_text()):
            assert (root / "envs" / f"{env}.yaml").exists(), (smk.name, env)
            assert env in STAGE_MODULES, env
    assert sorted(p.stem for p in (root / "envs").glob("*.yaml")) == sorted(STAGE_MODULES)


@pytest.mark.parametrize("stage", sorted(STAGE_MODULES))
def test_env_is_sufficient_for_its_rules(root, stage):
    guarded = sorted(set(IMPORT_NAME.values()) | {m for v in IMPLIED.values() for m in v} | {"vtk"})
    code = BLOCKER.format(allowed=env_packages(root, stage), guarded=guarded, modules=STAGE_MODULES[stage])
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=300,
        env={"PYTHONPATH": str(root / "src"), "PATH": "/usr/bin:/bin"},
    )
    assert proc.returncode == 0 and proc.stdout.strip().endswith("ok"), proc.stderr[-3000:]


def test_the_blocker_really_blocks(root):
    code = BLOCKER.format(allowed=["numpy"], guarded=["numpy", "pandas"], modules=["pbmdem.dem.collisions"])
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=300,
        env={"PYTHONPATH": str(root / "src"), "PATH": "/usr/bin:/bin"},
    )
    assert proc.returncode != 0 and "pandas is not in the environment" in proc.stderr


def test_every_rule_that_runs_liggghts_gets_the_mpi_launcher_in_the_slurm_profile(root):
    """A rule with LIGGGHTS ranks as its `tasks` runs LIGGGHTS (an MPI program): inside a SLURM job
    it must be started by the job's launcher (the profile's `mpi`), or Open MPI aborts in MPI_Init
    (a rule added without its profile entry failed this way under the cluster test)."""
    import re

    import yaml

    rules = {}
    for smk in sorted((root / "rules").glob("*.smk")):
        for block in re.split(r"\n(?=rule )", smk.read_text()):
            name = re.match(r"rule (\w+):", block)
            if name and "tasks=DEM_RANKS" in block:
                rules[name.group(1)] = smk.name
    assert {"dem_bed", "dem_point", "pbm_dem_coupled"} <= set(rules), rules
    profile = yaml.safe_load((root / "profiles" / "slurm" / "config.yaml").read_text())
    for rule, where in rules.items():
        resources = profile["set-resources"].get(rule, {})
        assert "mpi" in resources and resources.get("tasks", 0) >= 1, (
            f"rule {rule} ({where}) has no mpi in profiles/slurm"
        )
        assert profile["set-threads"].get(rule) == 1, f"rule {rule} ({where}): set-threads 1 (ranks are tasks)"
