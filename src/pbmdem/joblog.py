"""One workflow job: its Snakemake log file and the terminal, warnings included, and its errors.

Every rule script runs its body inside `rule_job(snakemake.log[0])`, so that progress lines (DEM
steps, CV folds, coupling intervals) and every warning (out-of-domain predictions above all) reach
both the job's log under results/logs/ and the terminal that runs Snakemake, and so that an error
of pbmdem's own (bad input, a table or a model refused: the classes `pbmdem` defines, such as
`pbmdem.readers.InputFileError`, `pbmdem.config.ConfigError`, `pbmdem.pbm.errors.PBMError`,
`pbmdem.coupling.loop.CouplingError`) reaches both as its message alone, which names the file or
key, the row, the column, the value and what is allowed; the job then exits with status 1. Any
other exception is a fault of pbmdem and keeps its traceback."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from os import PathLike

#: One line per record: time, level, the logger's module path, the message.
LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"

#: The exit status of a job stopped by an error of pbmdem's own.
ERROR_STATUS = 1

log = logging.getLogger(__name__)


def log_job(log_file: str | PathLike[str]) -> None:
    """Send INFO and above, and Python warnings, to `log_file` (overwritten) and to stderr."""
    logging.basicConfig(
        level=logging.INFO,
        format=LOG_FORMAT,
        handlers=[logging.FileHandler(log_file, mode="w"), logging.StreamHandler()],
        force=True,
    )
    logging.captureWarnings(True)


def own_error(exc: BaseException) -> bool:
    """True for an exception of a class pbmdem defines (or derives): a refused input, table,
    setting or model, whose message says what is wrong. Built-in and third-party exceptions are not."""
    return any(cls.__module__.split(".")[0] == "pbmdem" for cls in type(exc).__mro__)


@contextmanager
def rule_job(log_file: str | PathLike[str]) -> Iterator[None]:
    """The body of a rule script: its log set up (`log_job`), and an error of pbmdem's own
    (`own_error`) logged as its message alone (the job's log and the terminal, no traceback),
    then the process ended with status `ERROR_STATUS`. Other exceptions pass unchanged."""
    log_job(log_file)
    try:
        yield
    except Exception as exc:
        if not own_error(exc):
            raise
        log.error("%s", exc)
        for handler in logging.getLogger().handlers:
            handler.flush()
        raise SystemExit(ERROR_STATUS) from None
