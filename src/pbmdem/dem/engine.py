"""Run the external LIGGGHTS engine (binary `liggghts`, serially or under MPI) and judge a run
against its plan, not its exit code; every failure leaves a `crash.json` beside the log
(docs/dem.md, "A run": how a run fails, interruptions, unfinished and corrupt runs).
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pbmdem.atomic import write_json
from pbmdem.readers import InputFileError

from .dumps import BINARY_SUFFIX, DumpFormatError, binary_frames, find_damage, read_classes
from .signals import PassSignals, children_cpu, wait

_ERROR_LINE = re.compile(r"^(ERROR|ERROR on proc \d+).*$", re.MULTILINE)
_LOST = re.compile(r"Lost atoms|lost atoms", re.IGNORECASE)
_FORCED_RESTART = re.compile(r"Forced restart written")
_DUMP_FRAME = re.compile(rb"^ITEM: TIMESTEP\n(\d+)\n", re.MULTILINE)
#: the header line of a LIGGGHTS log, e.g. "LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0, compiled ...)"
_VERSION_LINE = re.compile(r"^LIGGGHTS \(Version (?P<version>.+)\)\s*$")


class LiggghtsError(RuntimeError):
    """LIGGGHTS failed; the message ends with the tail of its log."""


@dataclass
class LiggghtsRun:
    """A finished run: its log, wall time and CPU time (user + system) of LIGGGHTS and every
    process it started (its MPI ranks: on a shared machine the cost, where the wall time also
    counts the other users' load), s."""

    log: Path
    wall_time: float
    cpu_time: float


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
    """The command line of LIGGGHTS on `deck` with `ranks` MPI ranks (dem.mpi_ranks, checked by the config)."""
    base = [executable(), "-in", deck, "-log", "log.liggghts", "-echo", "none"]
    if ranks == 1:
        return base
    # inside a cluster job the job's own launcher (the rule's `mpi` resource, e.g. "srun --mpi=pmix")
    launcher = os.environ.get("PBMDEM_MPI_LAUNCHER", "").strip()
    if launcher:
        return [*shlex.split(launcher), "-n", str(ranks), *base]
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


def _forced_restarts(workdir: Path) -> list[dict]:
    """Remove the restart files LIGGGHTS writes when interrupted (they cannot resume a pbmdem run:
    the deck re-creates meshes and fixes); what was removed, for crash.json."""
    removed = []
    for path in sorted(workdir.glob("restart_forced_*")):
        step = re.search(r"(\d+)", path.name.rsplit("_", 1)[-1])
        step = int(step.group(1)) if step else None
        removed.append({"file": path.name, "bytes": path.stat().st_size, "step": step, "removed": True})
        path.unlink()
    return removed


def _write_crash(workdir: Path, problems: list[str], **details) -> None:
    write_json(
        workdir / "crash.json",
        {
            "problems": problems,
            **details,
            "forced_restart_files": _forced_restarts(workdir),
            "log_tail": tail(workdir / "log.liggghts", 40),
            "when": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        },
    )


def record_crash(workdir: Path, problems: list[str], **details) -> None:
    """Write `workdir/crash.json` and raise LiggghtsError naming the problems and the log's tail."""
    log = workdir / "log.liggghts"
    _write_crash(workdir, problems, **details)
    stderr = details.get("stderr_tail") or ""
    err = details.get("error_line")
    raise LiggghtsError(
        f"LIGGGHTS failed in {workdir} ({'; '.join(problems)}). Last lines of the log:\n{tail(log)}"
        + (f"\n{err}" if err and err not in tail(log) else "")
        + (f"\nstderr:\n{stderr[-2000:]}" if stderr.strip() else "")
        + f"\nNo tables were written; details in {workdir / 'crash.json'}."
    )


def run(
    deck: str | Path,
    workdir: str | Path,
    ranks: int = 1,
    timeout: float | None = None,
    progress=None,
    poll: float = 1.0,
) -> LiggghtsRun:
    """Run `deck` (a file in `workdir`) in `workdir`, `progress` (a ThermoProgress) updated every
    `poll` s; LiggghtsError (after writing `workdir/crash.json`) on any failure."""
    workdir = Path(workdir)
    deck_name = Path(deck).name
    cmd = command(deck_name, ranks)
    log = workdir / "log.liggghts"
    t0 = time.perf_counter()
    cpu0 = children_cpu()
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.Popen(
        cmd, cwd=workdir, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, errors="replace", env=env
    )
    with PassSignals(proc) as signals:
        stdout, stderr, returncode = wait(proc, t0, timeout, poll, progress, signals)
    wall = time.perf_counter() - t0
    cpu = children_cpu() - cpu0
    screen = workdir / "screen.liggghts"
    screen.write_text(stdout)
    log_text = log.read_text(errors="replace") if log.exists() else ""
    # an error can reach the screen but not the log (e.g. when MPI aborts while reporting it)
    log_text += "\n" + stdout
    problems = [f"interrupted by {', '.join(signals.received)}"] if signals.received else []
    if returncode != 0:
        problems.append(f"exit code {returncode}")
    err = _ERROR_LINE.search(log_text)
    if err:
        problems.append(f"log says: {err.group(0).strip()}")
    if _LOST.search(log_text):
        problems.append("particles were lost")
    if _FORCED_RESTART.search(log_text):
        problems.append("interrupted: LIGGGHTS wrote a forced restart (it received SIGINT or SIGTERM)")
    if problems:
        error_line = err.group(0).strip() if err else None
        details = {"command": cmd, "returncode": returncode, "wall_time_s": wall, "stderr_tail": stderr[-4000:]}
        record_crash(workdir, problems, **details, error_line=error_line)
    return LiggghtsRun(log=log, wall_time=wall, cpu_time=cpu)


def dump_steps(path: str | Path) -> list[int]:
    """Time steps of the frames of a LIGGGHTS dump file (empty if the file is missing); of a
    binary dump (`*.bin`), those of the well-formed frames before any damage."""
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        return []
    if Path(path).suffix == BINARY_SUFFIX:
        return [frame.step for frame in binary_frames(data, path)[0]]
    return [int(m.group(1)) for m in _DUMP_FRAME.finditer(data)]


#: the class-map dump of a run (liggghts_templates/granulator.in): id, atom type (class + 1), radius
CLASS_MAP = "post/classes.dump"


def check_finished(
    workdir: str | Path, total_steps: int, dumps: dict[str, tuple[int, int]], counts: list[int] | None = None
) -> None:
    """Judge a run against its plan: the log's last thermo step must be `total_steps`, each dump
    `name -> (frames, last step)` hold that many frames ending there and the class map (CLASS_MAP)
    the planned `counts` per class, if given. A log short of the plan is an unfinished run
    (LiggghtsError), a finished log with a dump off the plan a corrupt file (DumpFormatError
    naming the line, byte and frame); either writes crash.json."""
    workdir = Path(workdir)
    log = workdir / "log.liggghts"
    steps = thermo_table(log).get("Step", []) if log.exists() else []
    last = int(steps[-1]) if steps else None
    mismatched = {}
    for name, (frames, last_step) in dumps.items():
        found = dump_steps(workdir / name)
        if len(found) != frames or (found and found[-1] != last_step):
            mismatched[name] = (found, frames, last_step)
    if last != total_steps:
        problems = [f"unfinished: the log's last thermo step is {last}, the plan has {total_steps} steps"]
        problems += [
            f"unfinished: {name} holds {len(found)} frames up to step {found[-1] if found else None}, "
            f"the plan has {frames} up to step {last_step}"
            for name, (found, frames, last_step) in mismatched.items()
        ]
        record_crash(workdir, problems, last_thermo_step=last, planned_steps=total_steps)
    if mismatched:
        problems = [_corruption(workdir, name, *m) for name, m in mismatched.items()]
        _write_crash(workdir, problems, last_thermo_step=last, planned_steps=total_steps)
        raise DumpFormatError(
            f"corrupt run in {workdir}: LIGGGHTS finished (its log reaches the planned step {total_steps}), "
            f"but {'; '.join(problems)}. The file was damaged after the engine wrote it (check the disk "
            f"and what else writes there); no tables were written; details in {workdir / 'crash.json'}."
        )
    if counts is not None:
        check_class_counts(workdir, counts)


def check_class_counts(workdir: str | Path, counts: list[int]) -> None:
    """The particles per size class of the run's class map (CLASS_MAP) must be the planned
    `counts`; otherwise crash.json is written and LiggghtsError raised naming the folder and each
    class that differs (planned and inserted)."""
    workdir = Path(workdir)
    _, classes = read_classes(workdir / CLASS_MAP)
    if classes.size and (classes.min() < 0 or classes.max() >= len(counts)):
        found = sorted({int(c) + 1 for c in classes if not 0 <= c < len(counts)})
        inserted = None
        problems = [f"atom types {found} in {CLASS_MAP}: the plan has types 1..{len(counts)}"]
    else:
        inserted = [int(n) for n in np.bincount(classes, minlength=len(counts))]
        problems = [
            f"class {k}: {planned} particles planned, {got} inserted"
            for k, (planned, got) in enumerate(zip(counts, inserted))
            if planned != got
        ]
    if problems:
        problems[0] = f"the bed in {CLASS_MAP} is not the planned one: {problems[0]}"
        if inserted is not None and sum(inserted) < sum(counts):
            problems.append(
                f"insertion did not place them all ({sum(inserted)} of {sum(counts)}): lower dem.bed_height, "
                "or give the bowl more height / the settling phase more time"
            )
        record_crash(workdir, problems, planned_counts=[int(c) for c in counts], inserted_counts=inserted)


def _corruption(workdir: Path, name: str, found: list[int], frames: int, last_step: int) -> str:
    """Where the dump `name` of a finished run departs from its plan (line, byte, frame)."""
    damage = find_damage(workdir / name)
    if damage is not None:
        return f"corrupt: {damage}"
    gaps = [k for k in range(1, len(found)) if found[k] - found[k - 1] > min(b - a for a, b in zip(found, found[1:]))]
    at = f"; the first gap follows frame {gaps[0]} (step {found[gaps[0] - 1]})" if gaps else ""
    return (
        f"corrupt: {workdir / name} is well-formed but holds {len(found)} frames up to step "
        f"{found[-1] if found else None}, the plan has {frames} up to step {last_step}{at}"
    )


def version_of_log(log: str | Path) -> str:
    """The engine version from the header line "LIGGGHTS (Version ...)" of a LIGGGHTS log
    (InputFileError naming the log if it has no such line in its first lines)."""
    path = Path(log)
    try:
        with path.open(encoding="utf-8", errors="replace") as f:
            for _, line in zip(range(50), f):
                match = _VERSION_LINE.match(line.strip())
                if match:
                    return match.group("version").strip()
    except OSError as exc:
        raise InputFileError(f"LIGGGHTS log {path} cannot be read: {exc}") from None
    raise InputFileError(f"LIGGGHTS log {path}: no header line 'LIGGGHTS (Version ...)' in its first 50 lines")


def thermo_table(log: str | Path) -> dict[str, list[float]]:
    """Columns of every thermo block in a LIGGGHTS log (header line starting with 'Step')."""
    return thermo_columns(Path(log).read_text(errors="replace"))


def thermo_columns(text: str) -> dict[str, list[float]]:
    """Columns of every thermo block in the text of a LIGGGHTS log."""
    columns: dict[str, list[float]] = {}
    header: list[str] | None = None
    for line in text.splitlines():
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
