"""LIGGGHTS dump files of a DEM run, read vectorised and checked.

A dump (`dump local` of contacts, `dump custom` of particles) is read once as bytes; frame headers
are located with one regular-expression scan and all entry rows are handed in one piece to
pandas' C reader. A truncated, inconsistent or non-finite dump is a DumpFormatError naming the
file, the frame and the row.
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.readers import first_index

_HEADER = re.compile(
    rb"ITEM: TIMESTEP\n(\d+)\nITEM: NUMBER OF (?:ENTRIES|ATOMS)\n(\d+)\n"
    rb"ITEM: BOX BOUNDS[^\n]*\n[^\n]*\n[^\n]*\n[^\n]*\nITEM: (?:ENTRIES|ATOMS)[^\n]*\n"
)


class DumpFormatError(ValueError):
    """A dump file is malformed or truncated."""


@dataclass
class Snapshots:
    """All frames of a local dump: `steps[k]` and the rows `data[offsets[k]:offsets[k+1]]`."""

    steps: np.ndarray
    offsets: np.ndarray
    data: np.ndarray  # (rows, columns) float64

    @property
    def frames(self) -> int:
        return len(self.steps)

    def frame_index(self) -> np.ndarray:
        """Frame number of every row."""
        return np.repeat(np.arange(self.frames), np.diff(self.offsets))


def read_dump(path: str | Path, columns: int, ids: tuple[int, ...] = ()) -> Snapshots:
    """Read a LIGGGHTS `dump local` (or `dump custom`) text file with `columns` values per row;
    the 0-based columns `ids` hold particle ids (positive integers: anything else is corruption)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise DumpFormatError(f"dump file {path} does not exist (did LIGGGHTS reach the sampling phase?)") from None
    if not raw.strip():
        return Snapshots(np.zeros(0, np.int64), np.zeros(1, np.int64), np.zeros((0, columns)))
    headers = list(_HEADER.finditer(raw))
    if not headers or headers[0].start() != 0:
        raise DumpFormatError(f"{path}: does not start with a LIGGGHTS dump header ('ITEM: TIMESTEP')")
    steps = np.array([int(m.group(1)) for m in headers], dtype=np.int64)
    counts = np.array([int(m.group(2)) for m in headers], dtype=np.int64)
    bodies = [
        raw[m.end() : (headers[k + 1].start() if k + 1 < len(headers) else len(raw))] for k, m in enumerate(headers)
    ]
    body = b"".join(bodies)
    total = int(counts.sum())
    if total == 0:
        data = np.zeros((0, columns))
    else:
        try:
            frame = pd.read_csv(
                io.BytesIO(body),
                sep=" ",
                header=None,
                usecols=range(columns),
                dtype=np.float64,
                engine="c",
                skip_blank_lines=True,
            )
        except (ValueError, pd.errors.ParserError) as exc:
            raise DumpFormatError(
                f"corrupt dump: {find_damage(path) or f'{path}: malformed entry rows ({exc})'}"
            ) from None
        data = frame.to_numpy()
    # a short last row (fewer fields than columns) is truncation; a literal 'nan' is caught below
    short_last = bool(total) and len(body.rstrip().rsplit(b"\n", 1)[-1].split()) < columns
    if len(data) != total or short_last:
        raise DumpFormatError(
            f"corrupt dump: {find_damage(path) or path}: headers announce {total} rows in {len(steps)} frames, "
            f"found {len(data)} complete rows"
        )
    offsets = np.concatenate([[0], np.cumsum(counts)])
    # 'nan' or 'inf' in any column (ids, overlaps, positions) would silently change the counts
    bad = ~np.isfinite(data)
    if (at := first_index(bad)) is not None:
        row, col = at
        frame = int(np.searchsorted(offsets, row, side="right") - 1)
        raise DumpFormatError(
            f"{path}: non-finite value {float(data[row, col])!r} in column {col + 1} of "
            f"entry row {row - offsets[frame] + 1} "
            f"of the frame at step {steps[frame]} ({int(bad.sum())} non-finite value(s) in all); every value of a "
            "dump must be a finite number"
        )
    for col in ids:
        values = data[:, col]
        impossible = (values < 1) | (values != np.round(values))
        if (row := first_index(impossible)) is not None:
            frame = int(np.searchsorted(offsets, row, side="right") - 1)
            at = headers[frame].end()
            for _ in range(row - int(offsets[frame])):
                at = raw.index(b"\n", at) + 1
            line = raw.count(b"\n", 0, at) + 1
            raise DumpFormatError(
                f"corrupt dump: {path}: line {line} (byte {at}), frame {frame + 1} "
                f"(step {steps[frame]}): column {col + 1} = {values[row]:g} is not a particle id (a positive "
                f"integer); {int(impossible.sum())} such value(s) in all"
            )
    # each frame's rows must be as many as its header says; a short last frame is truncation
    last_lines = bodies[-1].count(b"\n")
    if last_lines < counts[-1]:
        raise DumpFormatError(f"{path}: last frame (step {steps[-1]}) is truncated: {last_lines} of {counts[-1]} rows")
    return Snapshots(steps=steps, offsets=offsets, data=data)


def find_damage(path: str | Path, expected_steps=None) -> str | None:
    """Where the dump `path` stops being a well-formed LIGGGHTS dump, or None if it is one.

    Every line is checked against the structure LIGGGHTS writes (TIMESTEP, step, NUMBER OF
    ENTRIES/ATOMS, count, BOX BOUNDS and its three lines, the ENTRIES/ATOMS header with its column
    names, then exactly `count` rows of as many finite numbers); steps must increase. With
    `expected_steps` (the planned frame steps) a frame at an unplanned step, or a missing frame,
    is damage too. The answer names the line, the byte offset and the frame. Slow (one Python
    pass over the lines): for explaining a dump already found inconsistent, not for reading one."""
    path = Path(path)
    raw = path.read_bytes()
    planned = None if expected_steps is None else [int(x) for x in expected_steps]
    offset, line_no, frame, step, previous = 0, 0, 0, None, None
    lines = raw.split(b"\n")
    if lines and lines[-1] == b"":
        lines.pop()
    state, remaining, width = "item", 0, 0

    def where(message: str, line: bytes) -> str:
        at = f"frame {frame} (step {step})" if step is not None else f"frame {frame}"
        after = "" if previous is None else f", after the frame at step {previous}"
        return f"{path}: line {line_no} (byte {offset}), {at}{after}: {message}; found {line[:60]!r}"

    for line in lines:
        line_no += 1
        if state == "item":
            if line != b"ITEM: TIMESTEP":
                return where("'ITEM: TIMESTEP' expected (a frame header)", line)
            frame, previous, step = frame + 1, step, None
            state = "step"
        elif state == "step":
            if not line.strip().isdigit():
                return where("a time step (an integer) expected", line)
            step = int(line)
            if previous is not None and step <= previous:
                return where(f"time step {step} does not follow {previous}", line)
            if planned is not None:
                if frame > len(planned):
                    return where(f"more frames than the {len(planned)} planned", line)
                if step != planned[frame - 1]:
                    return where(f"frame {frame} should be at step {planned[frame - 1]} (a frame is missing)", line)
            state = "count_item"
        elif state == "count_item":
            if line not in (b"ITEM: NUMBER OF ENTRIES", b"ITEM: NUMBER OF ATOMS"):
                return where("'ITEM: NUMBER OF ENTRIES' expected", line)
            state = "count"
        elif state == "count":
            if not line.strip().isdigit():
                return where("a row count (an integer) expected", line)
            remaining, state = int(line), "box_item"
        elif state == "box_item":
            if not line.startswith(b"ITEM: BOX BOUNDS"):
                return where("'ITEM: BOX BOUNDS' expected", line)
            state, box = "box", 0
        elif state == "box":
            if not _numbers(line, (2, 3)):
                return where("a line of box bounds (2 or 3 finite numbers) expected", line)
            box += 1
            state = "box" if box < 3 else "rows_item"
        elif state == "rows_item":
            if not (line.startswith(b"ITEM: ENTRIES") or line.startswith(b"ITEM: ATOMS")):
                return where("'ITEM: ENTRIES' or 'ITEM: ATOMS' expected", line)
            width = len(line.split()) - 2
            state = "rows" if remaining else "item"
        elif state == "rows":
            if not _numbers(line, (width,)):
                return where(f"an entry row of {width} finite numbers expected", line)
            remaining -= 1
            state = "rows" if remaining else "item"
        offset += len(line) + 1
    if state != "item":
        return where(f"truncated: the file ends inside a frame ({state.replace('_', ' ')} expected)", b"<end of file>")
    if planned is not None and frame < len(planned):
        return where(f"the file ends after {frame} of {len(planned)} planned frames", b"<end of file>")
    return None


def _numbers(line: bytes, widths: tuple[int, ...]) -> bool:
    words = line.split()
    if len(words) not in widths:
        return False
    try:
        return all(np.isfinite(float(w)) for w in words)
    except ValueError:
        return False


def read_classes(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Particle ids and 0-based size classes (atom type - 1) from the class-map dump's first frame."""
    snaps = read_dump(path, 3, ids=(0,))
    if snaps.frames == 0:
        raise DumpFormatError(f"{path}: no particle frame (no particles inserted?)")
    rows = snaps.data[snaps.offsets[0] : snaps.offsets[1]]
    return rows[:, 0].astype(np.int64), rows[:, 1].astype(np.int64) - 1


def class_lookup(ids: np.ndarray, classes: np.ndarray) -> np.ndarray:
    lookup = np.full(int(ids.max()) + 1, -1, np.int64)
    lookup[ids] = classes
    return lookup


def read_trajectories(path: str | Path, n_particles: int):
    """Position snapshots (`dump custom ... id x y z vx vy vz`, sorted by id) as Trajectories."""
    from .encounters import Trajectories

    snaps = read_dump(path, 7, ids=(0,))
    counts = np.diff(snaps.offsets)
    if snaps.frames == 0 or (counts != n_particles).any():
        raise DumpFormatError(
            f"{path}: every position snapshot must list the {n_particles} particles; "
            f"found {sorted(set(counts.tolist()))} rows per snapshot"
        )
    data = snaps.data.reshape(snaps.frames, n_particles, 7)
    ids = data[0, :, 0].astype(np.int64)
    if (np.diff(ids) <= 0).any() or not (data[:, :, 0] == data[0:1, :, 0]).all():
        raise DumpFormatError(
            f"{path}: particle ids are not sorted identically in every snapshot (the deck must use dump_modify sort id)"
        )
    return Trajectories(steps=snaps.steps, ids=ids, pos=data[:, :, 1:4], vel=data[:, :, 4:7])
