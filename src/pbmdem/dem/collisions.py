"""Collision and encounter tables of one DEM run from its contact and position snapshots (docs/dem.md,
"Collisions and encounters"), and the grid's: every run's stacked, their replicate means with
standard errors, the run table (columns: docs/architecture.md, "Collision tables"). New contacts
are found for all frames at once by sorting (pair, frame) keys.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.atomic import write_csv
from pbmdem.frequency import pair_counts, upper_pairs
from pbmdem.impact import N_VELOCITY_BINS, VELOCITY_EDGES, WALLS, velocity_bin
from pbmdem.readers import read_json
from pbmdem.tables import KEYS, RUN_TABLES, SE_COLUMNS

from . import encounters
from .dumps import DumpFormatError, Snapshots, read_classes, read_dump, read_trajectories


def contact_starts(frame: np.ndarray, key: np.ndarray, stride: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Contacts that begin at their frame, and the frame of the same pair's previous contact.

    `frame` is the frame number of each row, `key` a unique integer per contact pair. With
    `stride` s only frames 0, s, 2s, ... are used (to measure convergence with the interval);
    rows of other frames are never counted. A row begins a contact when its frame is not the
    first used frame and the same key was absent from the previous used frame. A key listed
    twice in one frame (several triangles of a mesh touching one particle) counts once.
    Returns (mask of rows that begin a contact, previous contact frame per row or -1).
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
    first_frame = 0  # the first snapshot of the record: contacts present there did not begin in it
    begins_u = ~duplicate & ~continuing & (f_u > first_frame)
    prev_u = np.where(same_key, np.concatenate([[-1], f_u[:-1]]) * stride, -1)
    rows = order[np.flatnonzero(mask_used)]
    begins = np.zeros(len(frame), bool)
    begins[rows] = begins_u
    prev = np.full(len(frame), -1, np.int64)
    prev[rows] = prev_u
    return begins, prev


@dataclass
class Starts:
    """Contacts that begin inside the sampling window: the two partners (particle ids, or wall
    index and particle id), the step and the previous contact's step (-1 when none)."""

    first: np.ndarray
    second: np.ndarray
    step: np.ndarray
    prev_step: np.ndarray


def window_starts(snaps: Snapshots, window_start: int, wall: bool = False, stride: int = 1) -> Starts:
    """Contacts beginning at contact snapshots after `window_start` (a step) in a pair dump
    (id1, id2, overlap) or a wall dump (mesh id, particle id, overlap)."""
    empty = np.zeros(0, np.int64)
    if len(snaps.data) == 0:
        return Starts(empty, empty, empty, empty)
    touching = snaps.data[:, 2] > 0.0
    a = snaps.data[touching, 0].astype(np.int64)
    b = snaps.data[touching, 1].astype(np.int64)
    frame = snaps.frame_index()[touching]
    if not wall:
        a, b = np.minimum(a, b), np.maximum(a, b)
    key = a * (int(b.max()) + 1) + b
    begins, prev = contact_starts(frame, key, stride)
    begins &= snaps.steps[frame] > window_start
    prev_step = np.where(prev >= 0, snaps.steps[np.maximum(prev, 0)], -1)
    return Starts(a[begins], b[begins], snaps.steps[frame[begins]], prev_step[begins])


def _median_by(group: np.ndarray, values: np.ndarray, size: int) -> np.ndarray:
    out = np.full(size, np.nan)
    for g in np.unique(group):
        out[g] = float(np.median(values[group == g]))
    return out


@dataclass
class Tally:
    """Per class pair (or per wall and class): raw contact starts, encounters, their impact-speed
    histogram on pbmdem.impact.VELOCITY_EDGES and median impact speed."""

    raw: np.ndarray
    encounters: np.ndarray
    histogram: np.ndarray
    median_velocity: np.ndarray


def _tally(group: np.ndarray, events, shape: tuple[int, ...]) -> Tally:
    size = int(np.prod(shape))
    raw = np.bincount(group, minlength=size)
    g, v = group[events.encounter], events.velocity[events.encounter]
    enc = np.bincount(g, minlength=size)
    hist = np.bincount(g * N_VELOCITY_BINS + velocity_bin(v), minlength=size * N_VELOCITY_BINS)
    return Tally(
        raw.reshape(shape),
        enc.reshape(shape),
        hist.reshape(*shape, N_VELOCITY_BINS),
        _median_by(g, v, size).reshape(shape),
    )


def _counted(tally: Tally, at, count: np.ndarray, sampling_time: float, per: tuple[str, str]) -> dict:
    """The columns of a run table (docs/architecture.md) from the contact starts and encounters of
    the entries `at` of `tally` over the sampling window: their frequencies in total and per pair
    or particle (`per`: the two columns' names; NaN where `count`, the pairs or particles, is 0)."""
    coll, enc = tally.raw[at], tally.encounters[at]
    with np.errstate(divide="ignore", invalid="ignore"):
        per_count = [np.where(count > 0, x / (count * sampling_time), np.nan) for x in (coll, enc)]
    return {
        "collisions": coll,
        "sampling_time": sampling_time,
        "frequency": coll / sampling_time,
        per[0]: per_count[0],
        "encounters": enc,
        per[1]: per_count[1],
        "impact_velocity_median": tally.median_velocity[at],
    }


def pair_table(tally: Tally, n: np.ndarray, diameters, sampling_time: float, meta: dict) -> pd.DataFrame:
    """Tidy table with one row per unordered class pair (see docs/architecture.md)."""
    i, j = upper_pairs(len(n))
    d = np.asarray(diameters, float)
    per = ("frequency_per_pair", "encounter_frequency_per_pair")
    return pd.DataFrame(
        {
            **meta,
            "class_i": i,
            "class_j": j,
            "d_i": d[i],
            "d_j": d[j],
            "n_i": n[i],
            "n_j": n[j],
            "n_total": int(n.sum()),
            **_counted(tally, (i, j), pair_counts(n)[i, j], sampling_time, per),
        }
    )


def wall_table(tally: Tally, n: np.ndarray, diameters, sampling_time: float, meta: dict) -> pd.DataFrame:
    """Tidy table with one row per wall and class (see docs/architecture.md)."""
    w, c = np.repeat(np.arange(len(WALLS)), len(n)), np.tile(np.arange(len(n)), len(WALLS))
    per = ("frequency_per_particle", "encounter_frequency_per_particle")
    return pd.DataFrame(
        {
            **meta,
            "class_i": c,
            "d_i": np.asarray(diameters, float)[c],
            "n_i": n[c],
            "n_total": int(n.sum()),
            "wall": np.asarray(WALLS)[w],
            **_counted(tally, (w, c), n[c], sampling_time, per),
        }
    )


def _per_bin(meta: dict, keys: dict, counts: np.ndarray) -> pd.DataFrame:
    """A velocity table in long format (docs/architecture.md): one row per entry of the `keys`
    columns and impact-velocity bin [v_lo, v_hi), with its encounters `counts` (entries, bins)."""
    rows = len(counts)
    return pd.DataFrame(
        {
            **meta,
            **{name: np.repeat(values, N_VELOCITY_BINS) for name, values in keys.items()},
            "v_lo": np.tile(VELOCITY_EDGES[:-1], rows),
            "v_hi": np.tile(VELOCITY_EDGES[1:], rows),
            "encounters": counts.ravel(),
        }
    )


def velocity_table(tally: Tally, meta: dict) -> pd.DataFrame:
    """Encounters per class pair and impact-velocity bin."""
    i, j = upper_pairs(tally.raw.shape[0])
    return _per_bin(meta, {"class_i": i, "class_j": j}, tally.histogram[i, j])


def wall_velocity_table(tally: Tally, meta: dict) -> pd.DataFrame:
    """Wall encounters per wall, class and impact-velocity bin."""
    walls, k = tally.raw.shape
    w, c = np.repeat(np.arange(walls), k), np.tile(np.arange(k), walls)
    return _per_bin(meta, {"wall": np.asarray(WALLS)[w], "class_i": c}, tally.histogram[w, c])


@dataclass
class RunTables:
    pairs: pd.DataFrame
    walls: pd.DataFrame
    velocities: pd.DataFrame
    wall_velocities: pd.DataFrame
    diagnostics: dict = field(default_factory=dict)


class RunAnalysis:
    """Contact starts and encounters of one finished run of `plan` (a DemPlan whose class map
    `check_finished` found as planned)."""

    def __init__(self, post_dir: str | Path, plan):
        post_dir = Path(post_dir)
        self.plan, self.n_classes = plan, len(plan.diameters)
        ids, classes = read_classes(post_dir / "classes.dump")
        self.class_of = np.full(int(ids.max()) + 1, -1, np.int64)  # particle id -> class, -1: none
        self.class_of[ids] = classes
        self.n = np.bincount(classes, minlength=self.n_classes)
        self.radius_of_class = 0.5 * np.asarray(plan.diameters, float)
        self.pairs = read_dump(post_dir / "pairs.dump", 3, ids=(0, 1))
        self.walls = read_dump(post_dir / "walls.dump", 3, ids=(1,))
        self.traj = read_trajectories(post_dir / "positions.bin", plan.n_particles)
        window = self.pairs.steps[self.pairs.steps >= plan.window_start_step]
        if len(window) < 2:
            raise DumpFormatError(f"{plan.point_id}: fewer than two contact snapshots in the sampling window")
        self.window_start = int(window[0])  # contacts beginning after this snapshot are counted
        self.sampling_time = float(window[-1] - window[0]) * plan.timestep

    def angle_of_step(self, steps):
        """Impeller angle (rad): the rotation starts with the spin-up phase."""
        return self.plan.omega * (np.asarray(steps, float) - self.plan.settle_steps) * self.plan.timestep

    def pair_events(self, stride: int = 1):
        s = window_starts(self.pairs, self.window_start, stride=stride)
        ca, cb = self.class_of[s.first], self.class_of[s.second]
        if (ca < 0).any() or (cb < 0).any():
            raise DumpFormatError(f"{self.plan.point_id}: a contact names a particle id missing from the class map")
        ev = encounters.pair_events(
            self.traj,
            s.first,
            s.second,
            self.radius_of_class[ca],
            self.radius_of_class[cb],
            s.step,
            s.prev_step,
            self.plan.encounter_gap_fraction,
            stride=stride,
        )
        i, j = np.minimum(ca, cb), np.maximum(ca, cb)
        return ev, i * self.n_classes + j

    def wall_events(self, stride: int = 1):
        s = window_starts(self.walls, self.window_start, wall=True, stride=stride)
        c = self.class_of[s.second]
        if (c < 0).any():
            raise DumpFormatError(
                f"{self.plan.point_id}: a wall contact names a particle id missing from the class map"
            )
        ev = encounters.wall_events(
            self.traj,
            s.first,
            s.second,
            self.radius_of_class[c],
            s.step,
            s.prev_step,
            self.plan.encounter_gap_fraction,
            self.plan.granulator.bowl,
            self.plan.granulator.impeller,
            self.angle_of_step,
            self.plan.omega,
            stride=stride,
        )
        return ev, s.first * self.n_classes + c

    def tables(self) -> RunTables:
        K = self.n_classes
        plan = self.plan
        # the run's columns, first in every table, in this order
        meta = {key: getattr(plan, key) for key in ("point_id", "rpm", "distribution", "replicate")}
        ev, group = self.pair_events()
        pair_tally = _tally(group, ev, (K, K))
        wev, wgroup = self.wall_events()
        wall_tally = _tally(wgroup, wev, (len(WALLS), K))
        ev2, group2 = self.pair_events(stride=2)
        raw, raw2 = int(pair_tally.raw.sum()), int(np.bincount(group2, minlength=K * K).sum())
        enc, enc2 = int(ev.encounter.sum()), int(ev2.encounter.sum())
        mid = self.window_start + 0.5 * self.sampling_time / plan.timestep
        history = {
            f"encounters_history_{f:g}": int((ev.encounter & (ev.lag_steps <= f * plan.history_steps)).sum())
            for f in (0.125, 0.25, 0.5, 1.0)
        }
        diagnostics = {
            "snapshots": int(self.pairs.frames),
            "position_snapshots": int(len(self.traj.steps)),
            "contact_rows": int(len(self.pairs.data)),
            "mean_contacts_per_snapshot": float(len(self.pairs.data) / max(self.pairs.frames, 1)),
            "collisions_every_snapshot": raw,
            "collisions_every_second_snapshot": raw2,
            "convergence_change_when_interval_doubled": (raw2 - raw) / raw if raw else float("nan"),
            "encounters_every_snapshot": enc,
            "encounters_every_second_snapshot": enc2,
            "encounter_change_when_interval_doubled": (enc2 - enc) / enc if enc else float("nan"),
            "encounters_undetermined": int(ev.undetermined.sum()),
            "encounters_first_half": int((ev.encounter & (ev.step <= mid)).sum()),
            "encounters_second_half": int((ev.encounter & (ev.step > mid)).sum()),
            **history,
            "wall_encounters_bowl": int(wall_tally.encounters[0].sum()),
            "wall_encounters_impeller": int(wall_tally.encounters[1].sum()),
            "particles_per_class": self.n.tolist(),
        }
        return RunTables(
            pairs=pair_table(pair_tally, self.n, plan.diameters, self.sampling_time, meta),
            walls=wall_table(wall_tally, self.n, plan.diameters, self.sampling_time, meta),
            velocities=velocity_table(pair_tally, meta),
            wall_velocities=wall_velocity_table(wall_tally, meta),
            diagnostics=diagnostics,
        )


def tabulate_run(post_dir: str | Path, plan) -> RunTables:
    """Collision and encounter tables of one finished run of `plan` (a DemPlan)."""
    return RunAnalysis(post_dir, plan).tables()


#: the tables of a run (file: field of RunTables) in the order they are written: collisions.csv
#: last, its presence marks a finished run (pbmdem.dem.run.FINISHED_MARKERS)
TABLE_FILES = {
    "wall_collisions.csv": "walls",
    "impact_velocity.csv": "velocities",
    "wall_impact_velocity.csv": "wall_velocities",
    "collisions.csv": "pairs",
}


def write_tables(tables: RunTables, run_dir: str | Path) -> None:
    for name, attribute in TABLE_FILES.items():
        write_csv(Path(run_dir) / name, getattr(tables, attribute))


def replicate_mean(frame: pd.DataFrame, keys: list[str]) -> pd.DataFrame:
    """Mean over the replicates of every column but `keys`, with `n_replicates` and the standard
    error `<column>_se` (sample sd / sqrt(n), NaN for one replicate) of the SE_COLUMNS."""
    values = [c for c in frame.columns if c not in keys and c != "replicate"]
    grouped = frame.groupby(keys, sort=True, dropna=False)
    out = grouped[values].mean()
    out["n_replicates"] = grouped["replicate"].nunique()
    for col in SE_COLUMNS:
        if col in values:
            out[f"{col}_se"] = grouped[col].std(ddof=1) / np.sqrt(out["n_replicates"])
    out = out.reset_index()
    first = [c for c in frame.columns if c in out.columns]
    return out[first + [c for c in out.columns if c not in first]]


def read_tables(tables: list[str | Path], kind: str = "pairs") -> pd.DataFrame:
    """The per-run tables of `kind` (pairs, walls or velocities) stacked into one frame (every
    replicate a row of its own), each checked against its contract (pbmdem.tables)."""
    frames = [RUN_TABLES[kind].read(p) for p in tables]
    if not frames:
        raise ValueError("no collision tables to aggregate")
    return _sorted(pd.concat(frames, ignore_index=True))


def _sorted(frame: pd.DataFrame) -> pd.DataFrame:
    sort = [c for c in ("rpm", "distribution", "replicate", "wall", "class_i", "class_j", "v_lo") if c in frame.columns]
    return frame.sort_values(sort, kind="stable").reset_index(drop=True)


def aggregate(tables: list[str | Path], out: str | Path, kind: str = "pairs") -> pd.DataFrame:
    """Replicate means of per-run tables (`kind`: pairs, walls or velocities), one row per point
    and class pair (or wall, or velocity bin), sorted and written atomically."""
    grid = _sorted(replicate_mean(read_tables(tables, kind), list(KEYS[kind])))
    write_csv(out, grid)
    return grid


def run_table(summaries: list[str | Path], out: str | Path):
    """One row per run with its size, cost and convergence figures (atomically written CSV)."""
    rows = [read_json(p, "DEM run summary") for p in summaries]
    frame = pd.DataFrame(rows).drop(columns="particles_per_class", errors="ignore")
    frame = frame.sort_values(["rpm", "distribution"]).reset_index(drop=True)
    write_csv(out, frame)
    return frame
