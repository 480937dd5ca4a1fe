"""Collision-frequency tables from LIGGGHTS contact snapshots.

The DEM deck dumps, every `collision_interval` steps of the sampling window, all particle-particle
contacts (`compute pair/gran/local id delta`: id1, id2, overlap) and all particle-mesh contacts
(`compute wall/gran/local id delta`: mesh id, particle id, overlap). A **collision is a contact
that begins**: a pair with positive overlap at one snapshot that was not in contact at the
previous snapshot. Pairs already touching at the first snapshot are not counted; rows with
overlap <= 0 (liquid-bridge models list separated pairs too) are not contacts.

Parsing is vectorised: the file is read once as bytes, frame headers are located with one
regular-expression scan, all entry rows are handed in one piece to pandas' C reader, and new
contacts are found for all frames at once by sorting (pair, frame) keys.
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.atomic import write_csv

WALL_NAMES = ("bowl", "impeller")  # mesh ids 0 and 1, in the order of the deck's fix wall/gran

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
    bodies = [raw[m.end(): (headers[k + 1].start() if k + 1 < len(headers) else len(raw))]
              for k, m in enumerate(headers)]
    body = b"".join(bodies)
    total = int(counts.sum())
    if total == 0:
        data = np.zeros((0, columns))
    else:
        try:
            frame = pd.read_csv(io.BytesIO(body), sep=" ", header=None, usecols=range(columns),
                                dtype=np.float64, engine="c", skip_blank_lines=True)
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
            f"{path}: non-finite value {float(data[row, col])!r} in column {col + 1} of entry row {row - offsets[frame] + 1} "
            f"of the frame at step {steps[frame]} ({int(bad.sum())} non-finite value(s) in all); every value of a "
            "dump must be a finite number")
    # each frame's rows must be as many as its header says; a short last frame is truncation
    last_lines = bodies[-1].count(b"\n")
    if last_lines < counts[-1]:
        raise DumpFormatError(f"{path}: last frame (step {steps[-1]}) is truncated: "
                              f"{last_lines} of {counts[-1]} rows")
    return Snapshots(steps=steps, offsets=offsets, data=data)


def new_contacts(frame: np.ndarray, key: np.ndarray, stride: int = 1) -> np.ndarray:
    """Boolean mask of rows that are contacts beginning at their frame.

    `frame` is the frame number of each row, `key` a unique integer per contact pair. With
    `stride` s only frames 0, s, 2s, ... are used (to measure convergence with the interval);
    rows of other frames are never counted. A row counts when its frame is not the first used
    frame and the same key was absent from the previous used frame. A key listed twice in one
    frame (several triangles of a mesh touching one particle) counts once.
    """
    frame = np.asarray(frame, np.int64)
    key = np.asarray(key, np.int64)
    used = frame % stride == 0
    f = frame // stride
    order = np.lexsort((f, key))
    mask_used = used[order]
    k_u, f_u = key[order][mask_used], f[order][mask_used]
    same_key = np.concatenate([[False], k_u[1:] == k_u[:-1]])
    duplicate = same_key & np.concatenate([[False], f_u[1:] == f_u[:-1]])
    continuing = same_key & np.concatenate([[False], f_u[1:] == f_u[:-1] + 1])
    first_frame = 0  # the first snapshot of the window: contacts present there did not begin in it
    begins_sorted = np.zeros(len(order), bool)
    begins_sorted[np.flatnonzero(mask_used)] = ~duplicate & ~continuing & (f_u > first_frame)
    result = np.zeros(len(order), bool)
    result[order] = begins_sorted
    return result


@dataclass
class RunTables:
    pairs: pd.DataFrame
    walls: pd.DataFrame
    diagnostics: dict = field(default_factory=dict)


def read_classes(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Particle ids and 0-based size classes (atom type - 1) from the class-map dump's first frame."""
    snaps = read_dump(path, 3)
    if snaps.frames == 0:
        raise DumpFormatError(f"{path}: no particle frame (no particles inserted?)")
    rows = snaps.data[snaps.offsets[0]:snaps.offsets[1]]
    return rows[:, 0].astype(np.int64), rows[:, 1].astype(np.int64) - 1


def _class_lookup(ids: np.ndarray, classes: np.ndarray) -> np.ndarray:
    lookup = np.full(int(ids.max()) + 1, -1, np.int64)
    lookup[ids] = classes
    return lookup


def count_pair_collisions(pairs: Snapshots, class_of: np.ndarray, n_classes: int, stride: int = 1) -> np.ndarray:
    """(K, K) upper-triangular matrix of new particle-particle contacts per class pair."""
    counts = np.zeros((n_classes, n_classes), np.int64)
    if len(pairs.data) == 0:
        return counts
    touching = pairs.data[:, 2] > 0.0
    a = pairs.data[touching, 0].astype(np.int64)
    b = pairs.data[touching, 1].astype(np.int64)
    frame = pairs.frame_index()[touching]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * (int(hi.max()) + 1) + hi
    begins = new_contacts(frame, key, stride)
    ci, cj = class_of[lo[begins]], class_of[hi[begins]]
    if (ci < 0).any() or (cj < 0).any():
        raise DumpFormatError("a contact names a particle id missing from the class map")
    i, j = np.minimum(ci, cj), np.maximum(ci, cj)
    counts += np.bincount(i * n_classes + j, minlength=n_classes * n_classes).reshape(n_classes, n_classes)
    return counts


def count_wall_collisions(walls: Snapshots, class_of: np.ndarray, n_classes: int, stride: int = 1) -> np.ndarray:
    """(len(WALL_NAMES), K) new particle-wall contacts per wall and class."""
    counts = np.zeros((len(WALL_NAMES), n_classes), np.int64)
    if len(walls.data) == 0:
        return counts
    touching = walls.data[:, 2] > 0.0
    mesh = walls.data[touching, 0].astype(np.int64)
    pid = walls.data[touching, 1].astype(np.int64)
    frame = walls.frame_index()[touching]
    key = mesh * (int(pid.max()) + 1) + pid
    begins = new_contacts(frame, key, stride)
    m, c = mesh[begins], class_of[pid[begins]]
    counts += np.bincount(m * n_classes + c, minlength=len(WALL_NAMES) * n_classes).reshape(-1, n_classes)
    return counts


def pair_table(counts: np.ndarray, n: np.ndarray, diameters, sampling_time: float, meta: dict) -> pd.DataFrame:
    """Tidy table with one row per unordered class pair (see docs/architecture.md)."""
    k = len(n)
    i, j = np.triu_indices(k)
    pairs = np.where(i == j, n[i] * (n[i] - 1) / 2.0, n[i].astype(float) * n[j])
    d = np.asarray(diameters, float)
    coll = counts[i, j]
    with np.errstate(divide="ignore", invalid="ignore"):
        per_pair = np.where(pairs > 0, coll / (pairs * sampling_time), np.nan)
    return pd.DataFrame({
        "point_id": meta["point_id"], "rpm": meta["rpm"], "distribution": meta["distribution"],
        "class_i": i, "class_j": j, "d_i": d[i], "d_j": d[j], "n_i": n[i], "n_j": n[j],
        "n_total": int(n.sum()), "collisions": coll, "sampling_time": sampling_time,
        "frequency": coll / sampling_time, "frequency_per_pair": per_pair,
    })


def wall_table(counts: np.ndarray, n: np.ndarray, diameters, sampling_time: float, meta: dict) -> pd.DataFrame:
    rows = []
    for w, wall in enumerate(WALL_NAMES):
        for c in range(len(n)):
            rows.append({
                "point_id": meta["point_id"], "rpm": meta["rpm"], "distribution": meta["distribution"],
                "class_i": c, "d_i": float(diameters[c]), "n_i": int(n[c]), "n_total": int(n.sum()),
                "wall": wall, "collisions": int(counts[w, c]), "sampling_time": sampling_time,
                "frequency": counts[w, c] / sampling_time,
                "frequency_per_particle": counts[w, c] / (n[c] * sampling_time) if n[c] else np.nan,
            })
    return pd.DataFrame(rows)


def tabulate_run(post_dir: str | Path, plan) -> RunTables:
    """Collision tables of one finished run (`plan` is the run's `pbmdem.dem.DemPlan`)."""
    post_dir = Path(post_dir)
    ids, classes = read_classes(post_dir / "classes.dump")
    n_classes = len(plan.diameters)
    if len(ids) != plan.n_particles:
        raise DumpFormatError(
            f"{plan.point_id}: {len(ids)} particles in the granulator at the start of sampling, "
            f"{plan.n_particles} planned: insertion did not place them all (lower dem.bed_height, "
            "or give the bowl more height / the settling phase more time)"
        )
    if classes.min() < 0 or classes.max() >= n_classes:
        raise DumpFormatError(f"{plan.point_id}: atom types outside 1..{n_classes} in the class map")
    class_of = _class_lookup(ids, classes)
    n = np.bincount(classes, minlength=n_classes)
    pairs = read_dump(post_dir / "pairs.dump", 3)
    walls = read_dump(post_dir / "walls.dump", 3)
    if pairs.frames < 2:
        raise DumpFormatError(f"{plan.point_id}: fewer than two contact snapshots; sampling window too short")
    sampling_time = float(pairs.steps[-1] - pairs.steps[0]) * plan.timestep
    meta = {"point_id": plan.point_id, "rpm": plan.rpm, "distribution": plan.distribution}
    counts = count_pair_collisions(pairs, class_of, n_classes)
    counts2 = count_pair_collisions(pairs, class_of, n_classes, stride=2)
    total, total2 = int(counts.sum()), int(counts2.sum())
    diagnostics = {
        "snapshots": int(pairs.frames), "contact_rows": int(len(pairs.data)),
        "mean_contacts_per_snapshot": float(len(pairs.data) / max(pairs.frames, 1)),
        "collisions_every_snapshot": total, "collisions_every_second_snapshot": total2,
        "convergence_change_when_interval_doubled": (total2 - total) / total if total else float("nan"),
        "particles_per_class": n.tolist(),
    }
    return RunTables(
        pairs=pair_table(counts, n, plan.diameters, sampling_time, meta),
        walls=wall_table(count_wall_collisions(walls, class_of, n_classes), n, plan.diameters,
                         sampling_time, meta),
        diagnostics=diagnostics,
    )


def write_tables(tables: RunTables, run_dir: str | Path) -> None:
    run_dir = Path(run_dir)
    write_csv(run_dir / "wall_collisions.csv", tables.walls)
    write_csv(run_dir / "collisions.csv", tables.pairs)  # last: its presence marks a finished run


def aggregate(tables: list[str | Path], out: str | Path) -> pd.DataFrame:
    """Concatenate per-point tables into one grid table (sorted, written atomically)."""
    from pbmdem.readers import read_table

    frames = [read_table(p, "collision table", columns=("point_id",)) for p in tables]
    if not frames:
        raise ValueError("no collision tables to aggregate")
    grid = pd.concat(frames, ignore_index=True)
    keys = [c for c in ("rpm", "distribution", "class_i", "class_j", "wall") if c in grid.columns]
    grid = grid.sort_values(keys, kind="stable").reset_index(drop=True)
    write_csv(out, grid)
    return grid
