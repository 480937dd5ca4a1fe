"""One workflow job: its Snakemake log file and the terminal, warnings and errors included.

Every rule script calls `log_job(snakemake.log[0])` first, so that progress lines (DEM steps, CV
folds, coupling intervals) and every warning (out-of-domain predictions above all) reach both the
job's log under results/logs/ and the terminal that runs Snakemake, and so that an error of
pbmdem's own that ends the script (bad input, a table or a model refused: the classes pbmdem
defines, such as `pbmdem.readers.InputFileError`, `pbmdem.config.ConfigError`,
`pbmdem.pbm.errors.PBMError`, `pbmdem.coupling.loop.CouplingError`) reaches both as its message
alone, which names the file or key, the row, the column, the value and what is allowed, and the
job exits with status 1. Any other exception is a fault of pbmdem and keeps its traceback, in the
log too."""

from __future__ import annotations

import logging
import sys
from os import PathLike

#: One line per record: time, level, the logger's module path, the message.
LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"

log = logging.getLogger(__name__)


def log_job(log_file: str | PathLike[str]) -> None:
    """Send INFO and above, and Python warnings, to `log_file` (overwritten) and to stderr; an
    uncaught error of pbmdem's own (`own_error`) is logged as its message alone (`report_error`)."""
    logging.basicConfig(
        level=logging.INFO,
        format=LOG_FORMAT,
        handlers=[logging.FileHandler(log_file, mode="w"), logging.StreamHandler()],
        force=True,
    )
    logging.captureWarnings(True)
    sys.excepthook = report_error


def own_error(exc: BaseException) -> bool:
    """True for an exception of a class pbmdem defines (or derives): a refused input, table,
    setting or model, whose message says what is wrong. Built-in and third-party exceptions are not."""
    return any(cls.__module__.split(".")[0] == "pbmdem" for cls in type(exc).__mro__)


def report_error(kind, exc, tb) -> None:
    """`sys.excepthook` of a job: an error of pbmdem's own as an ERROR record of its message alone;
    any other exception (a fault of pbmdem) as an ERROR record with its traceback, both to the
    job's log and the terminal; an interrupt as Python prints it. Python then ends the process
    with status 1."""
    if not issubclass(kind, Exception):
        sys.__excepthook__(kind, exc, tb)
        return
    if own_error(exc):
        log.error("%s", exc)
    else:
        log.error("a fault of pbmdem, not of its input (please report it):", exc_info=(kind, exc, tb))
    for handler in logging.getLogger().handlers:
        handler.flush()
