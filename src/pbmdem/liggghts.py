"""Run the external LIGGGHTS engine and turn its failures into clear errors.

LIGGGHTS (Debian package `liggghts`, binary `liggghts`) is run as a separate program, serially
or under `mpirun -np N`. A run fails when the program exits non-zero, when its log contains an
`ERROR` line (LIGGGHTS sometimes exits 0 after an error), or when particles were lost. The error
message carries the last lines of the log; a `crash.json` beside the log records the failure so
that crashed runs are kept and explained rather than hidden.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

from pbmdem.atomic import write_json

_ERROR_LINE = re.compile(r"^(ERROR|ERROR on proc \d+).*$", re.MULTILINE)
_LOST = re.compile(r"Lost atoms|lost atoms", re.IGNORECASE)


class LiggghtsError(RuntimeError):
    """LIGGGHTS failed; the message ends with the tail of its log."""


@dataclass
class LiggghtsRun:
    log: Path
    wall_time: float
    returncode: int


def executable() -> str:
    exe = os.environ.get("PBMDEM_LIGGGHTS", "liggghts")
    path = shutil.which(exe)
    if path is None:
        raise LiggghtsError(
            f"LIGGGHTS executable {exe!r} not found on PATH; install it with "
            "'apt-get install --no-install-recommends liggghts' (or set PBMDEM_LIGGGHTS)"
        )
    return path


def command(deck: str, ranks: int = 1) -> list[str]:
    if not isinstance(ranks, int) or ranks < 1:
        raise ValueError(f"mpi_ranks = {ranks!r}: a positive integer is required")
    base = [executable(), "-in", deck, "-log", "log.liggghts", "-echo", "none"]
    if ranks == 1:
        return base
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        raise LiggghtsError("mpi_ranks > 1 needs mpirun (apt-get install openmpi-bin)")
    return [mpirun, "--allow-run-as-root", "--oversubscribe", "-np", str(ranks), *base]


def tail(path: Path, lines: int = 25) -> str:
    try:
        text = path.read_text(errors="replace").splitlines()
    except FileNotFoundError:
        return "(no log written)"
    return "\n".join(text[-lines:])


def run(deck: str | Path, workdir: str | Path, ranks: int = 1, timeout: float | None = None,
        progress=None, poll: float = 1.0) -> LiggghtsRun:
    """Run `deck` (a file in `workdir`) with the working directory `workdir`.

    `progress` (e.g. a `pbmdem.progress.ThermoProgress` on the log) gets `update()` every `poll`
    seconds while the engine runs and `close()` when it stopped. Raises LiggghtsError (after
    writing `workdir/crash.json`) on any failure.
    """
    workdir = Path(workdir)
    deck_name = Path(deck).name
    cmd = command(deck_name, ranks)
    log = workdir / "log.liggghts"
    t0 = time.perf_counter()
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.Popen(cmd, cwd=workdir, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            errors="replace", env=env)
    try:
        while True:
            left = None if timeout is None else timeout - (time.perf_counter() - t0)
            try:
                stdout, stderr = proc.communicate(timeout=poll if left is None else max(0.0, min(poll, left)))
                returncode = proc.returncode
                break
            except subprocess.TimeoutExpired:
                if left is not None and left <= poll:
                    proc.kill()
                    stdout, _ = proc.communicate()
                    returncode, stderr = -9, f"timed out after {timeout} s"
                    break
                if progress is not None:
                    progress.update()
    except BaseException:  # e.g. KeyboardInterrupt: do not leave the engine running
        proc.kill()
        proc.communicate()
        raise
    finally:
        if progress is not None:
            progress.close()
    wall = time.perf_counter() - t0
    screen = workdir / "screen.liggghts"
    screen.write_text(stdout)
    log_text = log.read_text(errors="replace") if log.exists() else ""
    # an error can reach the screen but not the log (e.g. when MPI aborts while reporting it)
    log_text += "\n" + stdout
    problems = []
    if returncode != 0:
        problems.append(f"exit code {returncode}")
    err = _ERROR_LINE.search(log_text)
    if err:
        problems.append(f"log says: {err.group(0).strip()}")
    if _LOST.search(log_text):
        problems.append("particles were lost")
    if problems:
        write_json(workdir / "crash.json", {
            "command": cmd, "returncode": returncode, "problems": problems,
            "wall_time_s": wall, "log_tail": tail(log, 40), "stderr_tail": stderr[-4000:],
            "when": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        })
        raise LiggghtsError(
            f"LIGGGHTS failed in {workdir} ({'; '.join(problems)}). Last lines of the log:\n{tail(log)}"
            + (f"\n{err.group(0).strip()}" if err and err.group(0) not in tail(log) else "")
            + (f"\nstderr:\n{stderr[-2000:]}" if stderr.strip() else "")
        )
    return LiggghtsRun(log=log, wall_time=wall, returncode=returncode)


def thermo_table(log: str | Path) -> dict[str, list[float]]:
    """Columns of every thermo block in a LIGGGHTS log (header line starting with 'Step')."""
    columns: dict[str, list[float]] = {}
    header: list[str] | None = None
    for line in Path(log).read_text(errors="replace").splitlines():
        words = line.split()
        if words[:1] == ["Step"]:
            header = words
            continue
        if header is None:
            continue
        if len(words) != len(header):
            if line.startswith("Loop time"):
                header = None
            continue
        try:
            values = [float(w) for w in words]
        except ValueError:
            continue
        for name, value in zip(header, values):
            columns.setdefault(name, []).append(value)
    return columns
