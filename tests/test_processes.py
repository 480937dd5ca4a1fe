"""The suite leaves no process behind (issue 25, items 5 and 6): the session-end check of
conftest.py finds what a test left running, also a process re-parented to init, and ends it."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import psutil
from conftest import end_processes, leftover_processes


def test_an_orphaned_process_under_the_test_folder_is_found_and_ended(tmp_path):
    # a grandchild whose parent exits at once: re-parented to init, no longer a descendant of pytest
    pid_file = tmp_path / "pid"
    code = (
        "import subprocess, sys; "
        "p = subprocess.Popen(['sleep', '300'], cwd=sys.argv[1], start_new_session=True); "
        "open(sys.argv[2], 'w').write(str(p.pid))"
    )
    subprocess.run([sys.executable, "-c", code, str(tmp_path), str(pid_file)], check=True, timeout=30)
    orphan = psutil.Process(int(pid_file.read_text()))
    try:
        assert orphan.ppid() != psutil.Process().pid
        found = leftover_processes(tmp_path)
        assert orphan.pid in [p.pid for p in found]
        end_processes(found)
        time.sleep(0.1)
        assert not orphan.is_running() or orphan.status() == psutil.STATUS_ZOMBIE
        assert leftover_processes(tmp_path) == []
    finally:
        if orphan.is_running():
            orphan.kill()


def test_a_child_of_pytest_is_found_wherever_it_runs(tmp_path):
    child = subprocess.Popen(["sleep", "300"], cwd="/")
    try:
        assert child.pid in [p.pid for p in leftover_processes(tmp_path, children_of=os.getpid())]
    finally:
        child.kill()
        child.wait()
    assert child.pid not in [p.pid for p in leftover_processes(tmp_path, children_of=os.getpid())]
