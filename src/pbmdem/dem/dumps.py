"""LIGGGHTS dump files of a DEM run, read vectorised and checked.

A text dump (`dump local` of contacts, `dump custom` of particles) is read once as bytes; frame
headers are located with one regular-expression scan and all entry rows are handed in one piece to
pandas' C reader. A binary dump (`dump custom` to a file named `*.bin`, the position snapshots) is
walked frame by frame and its doubles are viewed in place. A truncated, inconsistent or non-finite
dump is a DumpFormatError naming the file, the frame and the row.
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.readers import first_index

from .encounters import Trajectories

_HEADER = re.compile(
    rb"ITEM: TIMESTEP\n(\d+)\nITEM: NUMBER OF (?:ENTRIES|ATOMS)\n(\d+)\n"
    rb"ITEM: BOX BOUNDS[^\n]*\n[^\n]*\n[^\n]*\n[^\n]*\nITEM: (?:ENTRIES|ATOMS)[^\n]*\n"
)


#: Header of one frame of a binary LIGGGHTS 3.8 dump (LAMMPS' binary format of its time, before the
#: magic string of later versions): time step, rows, triclinic flag, the six boundary flags, the six
#: box bounds, values per row and the number of chunks that follow. Each chunk is an int32 count of
#: values and as many float64 values, rows one after the other (one chunk per MPI rank).
BINARY_HEADER = np.dtype(
    [
        ("step", "<i8"),
        ("rows", "<i8"),
        ("triclinic", "<i4"),
        ("boundary", "<i4", (6,)),
        ("box", "<f8", (6,)),
        ("size_one", "<i4"),
        ("chunks", "<i4"),
    ]
)
BINARY_SUFFIX = ".bin"


class DumpFormatError(ValueError):
    """A dump file is malformed or truncated."""


@dataclass
class BinaryFrame:
    step: int
    rows: int
    size_one: int
    chunks: list[tuple[int, int]]  # (byte offset of the first value, number of values)


def binary_frames(raw: bytes, path: str | Path, width: int | None = None) -> tuple[list[BinaryFrame], str | None]:
    """The well-formed frames at the start of the binary dump `raw` (read from `path`) and where
    it stops being one (None if it never does): a header or chunk cut short, a count that cannot
    be (negative rows, values not `rows` x values per row, a width other than `width`), a step
    that does not increase."""
    frames: list[BinaryFrame] = []
    at, size = 0, len(raw)

    def damage(message: str) -> str:
        previous = f", after the frame at step {frames[-1].step}" if frames else ""
        return f"{path}: byte {at}, frame {len(frames) + 1}{previous}: {message}"

    while at < size:
        if size - at < BINARY_HEADER.itemsize:
            return frames, damage(f"truncated: {size - at} bytes left of a {BINARY_HEADER.itemsize}-byte frame header")
        head = np.frombuffer(raw, BINARY_HEADER, 1, at)[0]
        step, rows = int(head["step"]), int(head["rows"])
        size_one, n_chunks = int(head["size_one"]), int(head["chunks"])
        if rows < 0 or size_one < 1 or n_chunks < 1 or head["triclinic"] not in (0, 1):
            return frames, damage(f"not a frame header (step {step}, rows {rows}, width {size_one}, chunks {n_chunks})")
        if width is not None and size_one != width:
            return frames, damage(f"rows of {size_one} values, {width} expected")
        if frames and step <= frames[-1].step:
            return frames, damage(f"time step {step} does not follow {frames[-1].step}")
        header_end = at + BINARY_HEADER.itemsize + (3 * 8 if head["triclinic"] else 0)
        chunks, cursor, values = [], header_end, 0
        for _ in range(n_chunks):
            if size - cursor < 4:
                return frames, damage(f"truncated: the file ends inside the frame at step {step} (a chunk count)")
            n = int(np.frombuffer(raw, "<i4", 1, cursor)[0])
            if n < 0 or cursor + 4 + 8 * n > size:
                return frames, damage(f"truncated: the frame at step {step} announces {n} values, the file ends first")
            chunks.append((cursor + 4, n))
            cursor += 4 + 8 * n
            values += n
        if values != rows * size_one:
            announced = f"its header announces {rows} rows of {size_one}"
            return frames, damage(f"the frame at step {step} holds {values} values, {announced}")
        frames.append(BinaryFrame(step, rows, size_one, chunks))
        at = cursor
    return frames, None


def _binary_row_byte(frame: BinaryFrame, row: int) -> int:
    """Byte offset of the `row`-th row (0-based) of a binary frame."""
    value = row * frame.size_one
    for start, n in frame.chunks:
        if value < n:
            return start + 8 * value
        value -= n
    return frame.chunks[-1][0] + 8 * frame.chunks[-1][1]


def _read_binary(raw: bytes, path: Path, columns: int, ids: tuple[int, ...]) -> Snapshots:
    """A binary LIGGGHTS `dump custom` file (`raw`, read from `path`), checked like a text dump."""
    frames, damage = binary_frames(raw, path, width=columns)
    if damage is not None:
        raise DumpFormatError(f"corrupt dump: {damage}")
    steps = np.array([f.step for f in frames], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum([f.rows for f in frames])]).astype(np.int64)
    parts = [np.frombuffer(raw, "<f8", n, start) for f in frames for start, n in f.chunks]
    data = (np.concatenate(parts) if parts else np.zeros(0)).reshape(-1, columns)

    def where(frame: int, row: int) -> str:
        return (
            f"byte {_binary_row_byte(frames[frame], row)}, frame {frame + 1} (step {steps[frame]}), entry row {row + 1}"
        )

    _check_values(path, steps, offsets, data, ids, where)
    return Snapshots(steps=steps, offsets=offsets, data=data)


def _check_values(path: Path, steps: np.ndarray, offsets: np.ndarray, data: np.ndarray, ids, where) -> None:
    """Every value finite and every id column a positive integer, or a DumpFormatError naming
    the place (`where(frame, row in frame)`), the column and how many such values there are."""
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
            raise DumpFormatError(
                f"corrupt dump: {path}: {where(frame, row - int(offsets[frame]))}: column {col + 1} = "
                f"{values[row]:g} is not a particle id (a positive integer); "
                f"{int(impossible.sum())} such value(s) in all"
            )


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
    the 0-based columns `ids` hold particle ids (positive integers: anything else is corruption).
    A file named `*.bin` is read as a binary dump."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise DumpFormatError(f"dump file {path} does not exist (did LIGGGHTS reach the sampling phase?)") from None
    if path.suffix == BINARY_SUFFIX:
        return _read_binary(raw, path, columns, ids)
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

    def where(frame: int, row: int) -> str:
        at = headers[frame].end()
        for _ in range(row):
            at = raw.index(b"\n", at) + 1
        line = raw.count(b"\n", 0, at) + 1
        return f"line {line} (byte {at}), frame {frame + 1} (step {steps[frame]})"

    # 'nan' or 'inf' in any column (ids, overlaps, positions) would silently change the counts
    _check_values(path, steps, offsets, data, ids, where)
    # each frame's rows must be as many as its header says; a short last frame is truncation
    last_lines = bodies[-1].count(b"\n")
    if last_lines < counts[-1]:
        raise DumpFormatError(f"{path}: last frame (step {steps[-1]}) is truncated: {last_lines} of {counts[-1]} rows")
    return Snapshots(steps=steps, offsets=offsets, data=data)


def find_damage(path: str | Path) -> str | None:
    """Where the dump `path` stops being a well-formed LIGGGHTS dump (its line, byte offset and
    frame), or None. Slow, one Python pass over the lines: for explaining a dump already found
    inconsistent, not for reading one."""
    path = Path(path)
    raw = path.read_bytes()
    if path.suffix == BINARY_SUFFIX:
        return _find_binary_damage(raw, path)
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
    return None


def _find_binary_damage(raw: bytes, path: Path) -> str | None:
    """find_damage for a binary dump: its structure and finite values."""
    frames, damage = binary_frames(raw, path)
    if damage is not None:
        return damage
    for k, frame in enumerate(frames):
        for start, n in frame.chunks:
            values = np.frombuffer(raw, "<f8", n, start)
            if (bad := first_index(~np.isfinite(values))) is not None:
                return (
                    f"{path}: byte {start + 8 * bad}, frame {k + 1} (step {frame.step}): non-finite value "
                    f"{float(values[bad])!r}"
                )
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


def read_trajectories(path: str | Path, n_particles: int):
    """Position snapshots (`dump custom ... id x y z vx vy vz`, sorted by id; text or binary) as Trajectories."""
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
