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


def read_dump(path: str | Path, columns: int) -> Snapshots:
    """Read a LIGGGHTS `dump local` (or `dump custom`) text file with `columns` values per row."""
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
            raise DumpFormatError(f"{path}: malformed entry rows ({exc})") from None
        data = frame.to_numpy()
    # a short last row (fewer fields than columns) is truncation; a literal 'nan' is caught below
    short_last = bool(total) and len(body.rstrip().rsplit(b"\n", 1)[-1].split()) < columns
    if len(data) != total or short_last:
        raise DumpFormatError(
            f"{path}: truncated or inconsistent: headers announce {total} rows in {len(steps)} frames, "
            f"found {len(data)} complete rows (the run was probably interrupted)"
        )
    offsets = np.concatenate([[0], np.cumsum(counts)])
    # 'nan' or 'inf' in any column (ids, overlaps, positions) would silently change the counts
    bad = ~np.isfinite(data)
    if bad.any():
        row, col = (int(x) for x in np.argwhere(bad)[0])
        frame = int(np.searchsorted(offsets, row, side="right") - 1)
        raise DumpFormatError(
            f"{path}: non-finite value {float(data[row, col])!r} in column {col + 1} of "
            f"entry row {row - offsets[frame] + 1} "
            f"of the frame at step {steps[frame]} ({int(bad.sum())} non-finite value(s) in all); every value of a "
            "dump must be a finite number"
        )
    # each frame's rows must be as many as its header says; a short last frame is truncation
    last_lines = bodies[-1].count(b"\n")
    if last_lines < counts[-1]:
        raise DumpFormatError(f"{path}: last frame (step {steps[-1]}) is truncated: {last_lines} of {counts[-1]} rows")
    return Snapshots(steps=steps, offsets=offsets, data=data)


def read_classes(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Particle ids and 0-based size classes (atom type - 1) from the class-map dump's first frame."""
    snaps = read_dump(path, 3)
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

    snaps = read_dump(path, 7)
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
