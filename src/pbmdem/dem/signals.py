"""The engine's process: SIGINT/SIGTERM remembered and passed on to it, killed with every process it
started, waited for with a timeout and progress updates (`pbmdem.dem.engine.run`)."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import threading
import time
from pathlib import Path

#: seconds after a SIGINT/SIGTERM before it is passed on to a LIGGGHTS that is still running, and
#: after which LIGGGHTS (with every process it started) is killed: a cancelled job ends well within
#: a cluster's KillWait (SLURM's default 30 s; 10 s on the test cluster of scripts/slurm_cluster.sh),
#: before SLURM's SIGKILL, which misses processes that were re-parented to init.
SIGNAL_GRACE = 2.0
SIGNAL_KILL = 5.0


def descendants(pid: int) -> list[int]:
    """PIDs of every process below `pid` (children first), from /proc (empty where unreadable)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        fields = text[text.rfind(")") + 2 :].split()
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    out, todo = [], [pid]
    while todo:
        kids = children.get(todo.pop(), [])
        out += kids
        todo += kids
    return out


def kill_tree(proc: subprocess.Popen) -> None:
    """SIGKILL `proc` and every process it started (an MPI launcher's ranks too), by PID."""
    for pid in [*descendants(proc.pid), proc.pid]:
        try:
            os.kill(pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass


class PassSignals:
    """While LIGGGHTS runs (in the main thread), SIGINT/SIGTERM are remembered, passed on to it
    after `grace` s if it still runs, and it is killed SIGNAL_KILL s after the first (`deadline`)
    (docs/dem.md, "A run": an exit code 0 is not taken as success)."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, proc: subprocess.Popen, grace: float = SIGNAL_GRACE):
        self.proc, self.grace, self.received, self.saved = proc, grace, [], {}
        self.deadline: float | None = None

    def _forward(self, signum):
        if self.proc.poll() is None:
            self.proc.send_signal(signum)

    def _handler(self, signum, frame):
        self.received.append(signal.Signals(signum).name)
        if self.deadline is None:
            self.deadline = time.perf_counter() + SIGNAL_KILL
        if self.proc.poll() is None:
            timer = threading.Timer(self.grace, self._forward, args=(signum,))
            timer.daemon = True
            timer.start()

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in self.SIGNALS:
                self.saved[sig] = signal.signal(sig, self._handler)
        return self

    def __exit__(self, *exc):
        for sig, old in self.saved.items():
            signal.signal(sig, old)


def wait(proc: subprocess.Popen, t0: float, timeout, poll: float, progress, signals: PassSignals):
    """``(stdout, stderr, returncode)`` of ``proc`` (started at ``t0``) once it ended, with
    ``progress.update()`` every ``poll`` seconds meanwhile. Kills it (returncode -9, the reason as
    stderr) after ``timeout`` s or at the deadline of a received signal; on any exception (e.g.
    KeyboardInterrupt) kills it and re-raises, so that the engine is never left running."""
    try:
        while True:
            left = None if timeout is None else timeout - (time.perf_counter() - t0)
            try:
                stdout, stderr = proc.communicate(timeout=poll if left is None else max(0.0, min(poll, left)))
                return stdout, stderr, proc.returncode
            except subprocess.TimeoutExpired:
                if left is not None and left <= poll:
                    kill_tree(proc)
                    stdout, _ = proc.communicate()
                    return stdout, f"timed out after {timeout} s", -9
                if signals.deadline is not None and time.perf_counter() >= signals.deadline:
                    kill_tree(proc)  # a cancelled job must end before the cluster's KillWait
                    stdout, _ = proc.communicate()
                    return stdout, f"killed: still running {SIGNAL_KILL:g} s after {signals.received[0]}", -9
                if progress is not None:
                    progress.update()
    except BaseException:  # e.g. KeyboardInterrupt: do not leave the engine running
        kill_tree(proc)
        proc.communicate()
        raise
    finally:
        if progress is not None:
            progress.close()


def children_cpu() -> float:
    """User + system CPU seconds of this process's finished, waited-for children."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime
