"""Job logs: progress and warnings of a rule script reach its log file, and every script sets it up."""

from __future__ import annotations

import logging
import warnings
from pathlib import Path

from pbmdem.joblog import log_job

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
    text = log_file.read_text()
    assert "an earlier attempt" not in text
    assert "INFO pbmdem.test: interval 1 of 4" in text
    assert "WARNING py.warnings:" in text and "outside the training domain" in text


def test_every_rule_script_that_logs_uses_log_job():
    """A script that logs (or whose library calls log) sets up its job log through log_job."""
    for script in sorted(SCRIPTS.glob("*.py")):
        text = script.read_text()
        assert "basicConfig" not in text, f"{script.name} configures logging itself; use pbmdem.joblog.log_job"
