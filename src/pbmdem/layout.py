"""The results folder's layout: the one place that knows where every stage writes what.

The Snakemake rules (rules/common.smk), the command line and the library (the validation's
readers, the runtime estimate, the run viewer) take their paths from here. Paths are relative
text (Snakemake wants paths relative to its working directory) under `root` (default
``results``); an argument left at its default is the rule's wildcard (``{rpm}``, ``{dist}``,
``{rep}``), so that the same function names one file and a rule's output pattern.

    <root>/dem/rpm<rpm>_<dist>/rep<k>/     one DEM run (dem_run); the grid's tables in <root>/dem/
    <root>/dem/beds/<dist>/rep<k>/          the settled bed every speed's run starts from (dem_bed)
    <root>/surrogate/                       the surrogate (model.skops, model.json, metrics, parity)
    <root>/pbm/<kernel>/rpm<rpm>_<dist>/    one PBM batch (pbm_run)
    <root>/validation/rpm<rpm>/             one validation speed: pbm_dem/rep<k>/, pbm_ann/,
                                            pbm_constant/, bands.csv (validation_run)
    <root>/validation/feed_check/           the feed check: pbm_dem/rep<k>/, pbm_ann.csv (feed_check_run);
                                            its table <root>/validation/feed_check.csv
    <root>/design/                          the design space and the calibration check (design)
    <root>/report/                          the report's figures and tables
    <root>/logs/                            one log per job
"""

from __future__ import annotations

import re
from pathlib import PurePosixPath

RESULTS = "results"
#: the files every validation run writes into its folder (the coupled loops also intervals.csv)
RUN_FILES = ("summary.csv", "bins.csv", "final_bins.csv", "timing.json")
#: the validation's models, as folder names
METHODS = ("pbm_dem", "pbm_ann", "pbm_constant")


def dem(name: str = "", root: str = RESULTS) -> str:
    """<root>/dem/<name>: the DEM grid's tables and figures."""
    return f"{root}/dem/{name}".rstrip("/")


def dem_run(rpm="{rpm}", dist="{dist}", rep="{rep}", root: str = RESULTS) -> str:
    """The folder of one DEM run: <root>/dem/rpm<rpm>_<dist>/rep<rep>."""
    return f"{root}/dem/rpm{rpm}_{dist}/rep{rep}"


def dem_bed(dist="{dist}", rep="{rep}", root: str = RESULTS) -> str:
    """The folder of one settled bed: <root>/dem/beds/<dist>/rep<rep>."""
    return f"{root}/dem/beds/{dist}/rep{rep}"


def surrogate(name: str, root: str = RESULTS) -> str:
    """<root>/surrogate/<name>."""
    return f"{root}/surrogate/{name}"


MODEL = surrogate("model.skops")


def pbm_run(kernel: str, rpm="{rpm}", dist="{dist}", root: str = RESULTS) -> str:
    """The folder of one PBM batch: <root>/pbm/<kernel>/rpm<rpm>_<dist>."""
    return f"{root}/pbm/{kernel}/rpm{rpm}_{dist}"


def validation(name: str = "", root: str = RESULTS) -> str:
    """<root>/validation/<name>: the validation's folder (its speeds, sweep, studies, proposals)."""
    return f"{root}/validation/{name}".rstrip("/")


def speed(rpm="{rpm}", validation_dir=None) -> str:
    """The folder of one validation speed: <validation_dir>/rpm<rpm> (default validation_dir:
    <results>/validation)."""
    return f"{validation() if validation_dir is None else validation_dir}/rpm{rpm}"


def validation_run(method: str, rpm="{rpm}", rep=None, validation_dir=None) -> str:
    """The folder of one validation run: <speed>/<method> (pbm_ann, pbm_constant), or
    <speed>/pbm_dem/rep<rep> for a PBM-DEM replicate."""
    if method not in METHODS:
        raise ValueError(f"validation method {method!r}; allowed: {list(METHODS)}")
    folder = f"{speed(rpm, validation_dir)}/{method}"
    return folder if rep is None else f"{folder}/rep{rep}"


def validation_dir_of(path) -> str:
    """The validation folder that holds `path`, any file below one speed's folder (the inverse of
    `speed`): rules derive it from their input files, so that it also holds where a storage
    plugin maps the inputs elsewhere."""
    parts = PurePosixPath(str(path)).parts
    at = [k for k, part in enumerate(parts) if re.fullmatch(r"rpm[0-9]+(\.[0-9]+)?", part)]
    if not at:
        raise ValueError(f"{path} is not below a validation speed's folder (rpm<rpm>/)")
    return str(PurePosixPath(*parts[: at[-1]]))


def feed_check(name: str = "", root: str = RESULTS) -> str:
    """<root>/validation/feed_check/<name>: the runs of the feed check (the feed and speed of
    validation.feed_check)."""
    return validation(f"feed_check/{name}", root).rstrip("/")


def feed_check_run(rep="{rep}", root: str = RESULTS) -> str:
    """The folder of one PBM-DEM loop of the feed check: <root>/validation/feed_check/pbm_dem/rep<rep>."""
    return feed_check(f"pbm_dem/rep{rep}", root)


def design(name: str = "", root: str = RESULTS) -> str:
    """<root>/design/<name>: the design space and the check of the calibration (docs/design.md)."""
    return f"{root}/design/{name}".rstrip("/")


def report(name: str = "", root: str = RESULTS) -> str:
    """<root>/report/<name>."""
    return f"{root}/report/{name}".rstrip("/")


def log(name: str, root: str = RESULTS) -> str:
    """<root>/logs/<name>: one job's log."""
    return f"{root}/logs/{name}"
