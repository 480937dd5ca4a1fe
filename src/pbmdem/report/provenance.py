"""Where the results come from: configuration hashes, the workflow's git commit, and the versions
of LIGGGHTS, Python, the libraries and the surrogate (docs/validation.md, "Report", Provenance).
"""

from __future__ import annotations

import importlib.metadata
import json
import platform
import subprocess
from collections import Counter
from datetime import UTC, datetime
from pathlib import Path

import pandas as pd

import pbmdem
from pbmdem.config.dem import EXECUTION_KEYS
from pbmdem.config.settings import sha256_of
from pbmdem.readers import read_json
from pbmdem.tables import RUNS

#: distributions whose versions are recorded (PyPI names)
LIBRARIES = ("numpy", "scipy", "pandas", "scikit-learn", "matplotlib", "skops", "pyyaml", "jsonschema", "snakemake")
NOT_GIT = "not a git checkout"
COLUMNS = ["quantity", "value", "source"]


def settings_mapping(mapping: dict) -> dict:
    """The completed configuration mapping without the execution settings (dem.mpi_ranks, dem.timeout)."""
    out = json.loads(json.dumps(mapping))
    for key in EXECUTION_KEYS:
        out.get("dem", {}).pop(key, None)
    return out


def liggghts_versions(runs_table: str | Path) -> str:
    """The LIGGGHTS version(s) of the DEM runs (the run table's `liggghts_version`), each with its number of runs."""
    runs = RUNS.read(runs_table, need=("point_id",))
    if "liggghts_version" not in runs.columns:
        return (
            f"not recorded in {runs_table} (DEM runs made before pbmdem recorded it; the first line of "
            "each run's log.liggghts names it)"
        )
    counts = Counter(runs["liggghts_version"].fillna("not recorded").astype(str))
    if not counts:
        return "no DEM run"
    return "; ".join(f"{version} ({n} of {sum(counts.values())} runs)" for version, n in counts.most_common())


def _git(basedir: Path, *args: str) -> str | None:
    try:
        proc = subprocess.run(["git", "-C", str(basedir), *args], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return proc.stdout.strip() if proc.returncode == 0 else None


def git_commit(basedir: str | Path) -> tuple[str, str]:
    """(commit, state) of the git checkout holding `basedir`: state "clean" or "uncommitted changes
    to tracked files"; (NOT_GIT, "") if `basedir` is not in a git checkout (or git is missing)."""
    basedir = Path(basedir)
    commit = _git(basedir, "rev-parse", "HEAD")
    if not commit:
        return NOT_GIT, ""
    status = _git(basedir, "status", "--porcelain", "--untracked-files=no")
    state = "clean" if status == "" else ("uncommitted changes to tracked files" if status else "unknown")
    return commit, state


def library_versions() -> dict[str, str]:
    """Python, pbmdem (with the folder it was imported from) and the LIBRARIES installed in this environment."""
    out = {
        "Python": platform.python_version(),
        "pbmdem": f"{pbmdem.__version__} (imported from {Path(pbmdem.__file__).parent})",
    }
    for name in LIBRARIES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed in this environment"
    return out


HYPERPARAMETER_NAMES = {
    "hidden_layer_sizes": "hidden layers (neurons per layer)",
    "alpha": "L2 penalty alpha",
    "activation": "activation",
    "learning_rate_init": "initial learning rate",
}


def kernel_source(meta: dict) -> str:
    """The surrogate family PBM-ANN uses, why, and what was fitted, in words (from ``model.json``)."""
    state = meta.get("frequency_state") or {}
    if isinstance(state.get("best_params"), dict):
        fitted = "selected hyperparameters " + hyperparameters(state["best_params"])
    else:
        fitted = "fitted " + ("; ".join(map(str, state.get("fitted") or [])) or "not recorded")
    scores = meta.get("cv_scores") or {}
    selection = scores.get("selection") or "not recorded"
    out = f"Kernel source: {meta.get('family', 'not recorded')} ({selection}); {fitted}"
    speed = meta.get("velocity_family")
    if speed and speed != meta.get("family"):  # the impact-speed law of another family (model format 6)
        out += f"; impact-speed law: {speed} ({scores.get('speed_law_selection') or 'not recorded'})"
    tail = meta.get("speed_tail")
    if tail:  # model format 8: the pooled fast tail (docs/surrogate.md)
        out += (
            f"; pair impacts faster than {tail['from_m_s']:.3g} m/s: one tail for every pair and run, "
            f"P(V > v) falling as exp(-{tail['a']:.3g} (v / v_tip)^{tail['beta']:.2f}), the members' scale "
            f"spread by {tail['sd_ln_a_between_runs']:.2f} in ln a (the scatter between DEM beds)"
        )
    return out


def hyperparameters(params) -> str:
    """Selected hyperparameters in words: 'hidden layers (neurons per layer) 8 x 8, L2 penalty alpha 0.1'
    (per target when the metadata holds one mapping per target)."""
    if not isinstance(params, dict) or not params:
        return "not recorded"
    if all(isinstance(v, dict) for v in params.values()):
        return "; ".join(f"{target}: {hyperparameters(v)}" for target, v in params.items())

    def value(v):
        if isinstance(v, (list, tuple)):
            return " x ".join(str(x) for x in v)
        return f"{v:g}" if isinstance(v, float) else str(v)

    return ", ".join(
        f"{HYPERPARAMETER_NAMES.get(k.split('__')[-1], k.split('__')[-1].replace('_', ' '))} {value(v)}"
        for k, v in params.items()
    )


def provenance(
    config_sha256: str,
    settings: dict,
    basedir: str | Path,
    runs_table: str | Path,
    surrogate_metadata: str | Path | None = None,
    workdir: str | Path | None = None,
):
    """The provenance table (a DataFrame): quantity, value, source. `settings`: the completed
    configuration without the execution settings (`settings_mapping`)."""
    commit, state = git_commit(basedir)
    rows = [
        ("config sha256", config_sha256, "Config.sha256() of the configuration this table was written under"),
        (
            "settings sha256",
            sha256_of(settings),
            "the same without the execution settings " + ", ".join(f"dem.{k}" for k in EXECUTION_KEYS),
        ),
        ("git commit", commit, f"git rev-parse HEAD in {basedir}"),
    ]
    rows.append(("project", str(basedir), "the workflow's folder when this table was written"))
    if workdir is not None:
        rows.append(("working directory", str(workdir), "where Snakemake ran (a record; moving it reruns nothing)"))
    if commit != NOT_GIT:
        rows.append(("git working tree", state, "git status --porcelain --untracked-files=no"))
    rows.append(
        (
            "LIGGGHTS",
            liggghts_versions(runs_table),
            f"{runs_table}, column liggghts_version (the header line of each run's log.liggghts)",
        )
    )
    rows += [(name, version, "this job's environment") for name, version in library_versions().items()]
    rows.append(("platform", platform.platform(), "this job's machine"))
    if surrogate_metadata is not None:
        meta = read_json(surrogate_metadata, "surrogate metadata", keys=("model_sha256",))
        rows.append(("surrogate model sha256", str(meta["model_sha256"]), str(surrogate_metadata)))
        if "created_utc" in meta:
            rows.append(("surrogate trained (UTC)", str(meta["created_utc"]), str(surrogate_metadata)))
        rows.append(("surrogate kernel source", kernel_source(meta), str(surrogate_metadata)))
        if isinstance(meta.get("versions"), dict):
            rows.append(
                (
                    "surrogate trained with",
                    ", ".join(f"{k} {v}" for k, v in sorted(meta["versions"].items())),
                    str(surrogate_metadata),
                )
            )
    rows.append(("table written (UTC)", datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S"), "clock"))
    return pd.DataFrame(rows, columns=COLUMNS)
