"""Logging of one workflow job: its Snakemake log file and the terminal, warnings included.

Every rule script calls `log_job(snakemake.log[0])` first, so that progress lines (DEM steps, CV
folds, coupling intervals) and every warning (out-of-domain predictions above all) reach both the
job's log under results/logs/ and the terminal that runs Snakemake."""

from __future__ import annotations

import logging
from os import PathLike

#: One line per record: time, level, the logger's module path, the message.
LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


def log_job(log_file: str | PathLike[str]) -> None:
    """Send INFO and above, and Python warnings, to `log_file` (overwritten) and to stderr."""
    logging.basicConfig(
        level=logging.INFO,
        format=LOG_FORMAT,
        handlers=[logging.FileHandler(log_file, mode="w"), logging.StreamHandler()],
        force=True,
    )
    logging.captureWarnings(True)
