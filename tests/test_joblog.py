"""Job logs: progress and warnings of a rule script reach its log file, and every script sets it up;
an error of pbmdem's own reaches the log and the terminal as its message, without a traceback."""

from __future__ import annotations

import ast
import logging
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import pytest

from pbmdem.joblog import log_job, own_error
from pbmdem.pbm.errors import PBMInputError
from pbmdem.readers import InputFileError

SCRIPTS = Path(__file__).resolve().parents[1] / "workflow" / "scripts"


def test_log_job_writes_records_and_warnings_to_the_file(tmp_path):
    log_file = tmp_path / "job.log"
    log_file.write_text("an earlier attempt\n")
    try:
        log_job(log_file)
        logging.getLogger("pbmdem.test").info("interval 1 of 4")
        warnings.warn("3 samples outside the training domain", UserWarning, stacklevel=1)
    finally:
        for handler in logging.getLogger().handlers:
            handler.flush()
        logging.captureWarnings(False)
        logging.basicConfig(force=True, handlers=[logging.NullHandler()])
        sys.excepthook = sys.__excepthook__
    text = log_file.read_text()
    assert "an earlier attempt" not in text
    assert "INFO pbmdem.test: interval 1 of 4" in text
    assert "WARNING py.warnings:" in text and "outside the training domain" in text


def test_every_rule_script_that_logs_uses_log_job():
    """A script that logs (or whose library calls log) sets up its job log through log_job."""
    for script in sorted(SCRIPTS.glob("*.py")):
        text = script.read_text()
        assert "basicConfig" not in text, f"{script.name} configures logging itself; use pbmdem.joblog.log_job"


def _job(tmp_path, body: str) -> tuple[subprocess.CompletedProcess, str]:
    """A rule script's body after `log_job`, in a process of its own: (process, log text)."""
    log_file = tmp_path / "job.log"
    script = tmp_path / "script.py"
    script.write_text(f"from pbmdem.joblog import log_job\nlog_job({str(log_file)!r})\n" + textwrap.dedent(body))
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    return proc, log_file.read_text()


def test_an_error_of_pbmdem_reaches_log_and_terminal_as_its_message_alone(tmp_path):
    message = "DEM collision table t.csv: row 3, column 'encounter_frequency_per_pair' = -1.0: a number >= 0"
    proc, text = _job(
        tmp_path,
        f"""
        import logging
        from pbmdem.readers import InputFileError
        logging.getLogger("pbmdem.test").info("reading the tables")
        raise InputFileError({message!r})
        """,
    )
    assert proc.returncode == 1
    for out in (proc.stderr, text):
        assert message in out and "ERROR" in out
        assert "Traceback" not in out and 'File "' not in out
    assert "INFO pbmdem.test: reading the tables" in text
    assert proc.stdout == ""


@pytest.mark.parametrize(
    "error",
    [
        "pbmdem.config.ConfigError('config key pbm.breakage.yield_strength = 0: allowed > 0')",
        "pbmdem.pbm.errors.PBMInputError('breakage selection exponent = -1.0; allowed: >= 0')",
        "pbmdem.coupling.loop.CouplingError('interval 3: the DEM run failed')",
        "pbmdem.surrogate.persistence.TamperedModelError('model.skops: sha256 differs from model.json')",
    ],
)
def test_every_error_class_of_pbmdem_is_its_own(tmp_path, error):
    proc, text = _job(
        tmp_path,
        f"import pbmdem.config, pbmdem.pbm.errors, pbmdem.coupling.loop, pbmdem.surrogate.persistence\nraise {error}\n",
    )
    assert proc.returncode == 1 and "Traceback" not in proc.stderr + text
    assert error.split("'")[1] in proc.stderr and error.split("'")[1] in text


def test_a_fault_that_is_not_an_input_error_keeps_its_traceback(tmp_path):
    # a bug (an exception pbmdem does not raise on purpose) must stay visible with where it happened
    proc, text = _job(tmp_path, "import numpy as np\nnp.zeros(2) @ np.zeros(3)\n")
    assert proc.returncode == 1
    for out in (proc.stderr, text):
        assert "a fault of pbmdem" in out and "Traceback (most recent call last)" in out and "ValueError" in out
    assert not own_error(ValueError("x")) and not own_error(KeyError("x"))
    assert own_error(InputFileError("x")) and own_error(PBMInputError("x"))


def test_every_rule_script_sets_up_its_job_log_before_anything_else():
    """The module level of a rule script: its docstring, imports, `sm = snakemake` and comments,
    then `log_job(<the rule's log>)` before any statement that could fail (every rule has a log)."""
    for script in sorted(SCRIPTS.glob("*.py")):
        tree = ast.parse(script.read_text())
        body = [node for node in tree.body if not isinstance(node, (ast.Import, ast.ImportFrom))]
        if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
            body = body[1:]  # the docstring
        if body and ast.unparse(body[0]) == "sm = snakemake":
            body = body[1:]
        assert body and ast.unparse(body[0]) in ("log_job(sm.log[0])", "log_job(snakemake.log[0])"), script.name
