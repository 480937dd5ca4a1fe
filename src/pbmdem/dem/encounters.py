"""Encounters (contacts that begin between granules that were apart) and their impact speeds, for
particle pairs and particle-wall contacts, from the position snapshots (docs/dem.md, "Collisions
and encounters").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pbmdem.config import Bowl, Impeller

from .geometry import blade_box


@dataclass
class Trajectories:
    """Positions and velocities of all particles at the position snapshots.

    steps: (F,) step numbers; ids: (N,) particle ids (sorted); pos, vel: (F, N, 3) in m and m/s.
    """

    steps: np.ndarray
    ids: np.ndarray
    pos: np.ndarray
    vel: np.ndarray

    def index_of(self, ids: np.ndarray) -> np.ndarray:
        """Row of each particle id in the arrays (raises if an id is unknown)."""
        idx = np.searchsorted(self.ids, ids)
        idx = np.clip(idx, 0, len(self.ids) - 1)
        if len(ids) and not np.array_equal(self.ids[idx], ids):
            bad = np.asarray(ids)[self.ids[idx] != ids][0]
            raise ValueError(f"particle id {bad} of a contact is missing from the position snapshots")
        return idx


@dataclass
class Events:
    """Contacts that begin, with what the look-back found.

    encounter: bool per event; velocity: impact speed (m/s, valid where encounter);
    lag_steps: steps between the contact start and the snapshot where the gap was first found
    above the threshold looking back (valid where encounter); undetermined: the look-back reached
    the start of the history without a previous contact nor a large enough gap.
    """

    step: np.ndarray
    encounter: np.ndarray
    velocity: np.ndarray
    lag_steps: np.ndarray
    undetermined: np.ndarray


def _lookback(traj: Trajectories, event_step, prev_step, gap_fn, stride: int = 1) -> Events:
    """Generic look-back over the position snapshots strictly between `prev_step` and
    `event_step` of every event, newest first; `gap_fn(frame_idx, event_idx)` returns the gap
    (m) minus the event's threshold and the approach speed at those snapshots."""
    event_step, prev_step = np.asarray(event_step, np.int64), np.asarray(prev_step, np.int64)
    steps = traj.steps[::stride]
    frame_map = np.arange(len(traj.steps))[::stride]
    n = len(event_step)
    hi = np.searchsorted(steps, event_step, side="left") - 1  # last snapshot before the contact
    lo = np.searchsorted(steps, prev_step, side="right")  # first snapshot after the previous contact
    encounter = np.zeros(n, bool)
    velocity = np.full(n, np.nan)
    lag = np.full(n, -1, np.int64)
    has_frame = hi >= np.maximum(lo, 0)
    if n:
        # the approach velocity is read at the last snapshot before the contact began
        idx = np.flatnonzero(hi >= 0)
        _, v = gap_fn(frame_map[hi[idx]], idx)
        velocity[idx] = v
    undecided = np.flatnonzero(has_frame)
    cursor = hi.copy()
    while undecided.size:
        f = cursor[undecided]
        excess, _ = gap_fn(frame_map[f], undecided)
        found = excess > 0.0
        encounter[undecided[found]] = True
        lag[undecided[found]] = event_step[undecided[found]] - steps[f[found]]
        cursor[undecided] -= 1
        keep = ~found & (cursor[undecided] >= np.maximum(lo[undecided], 0))
        undecided = undecided[keep]
    undetermined = ~encounter & (prev_step < steps[0]) if len(steps) else np.zeros(n, bool)
    return Events(event_step, encounter, np.clip(velocity, 0.0, None), lag, undetermined)


def pair_events(
    traj: Trajectories, a, b, radius_a, radius_b, event_step, prev_step, gap_fraction: float, stride: int = 1
) -> Events:
    """Classify particle-particle contacts that begin at `event_step` (previous contact of the
    same pair at `prev_step`, or -1 for none in the record)."""
    ia, ib = traj.index_of(np.asarray(a, np.int64)), traj.index_of(np.asarray(b, np.int64))
    ra, rb = np.asarray(radius_a, float), np.asarray(radius_b, float)
    threshold = gap_fraction * 2.0 * np.minimum(ra, rb)

    def gap_fn(frames, ev):
        d = traj.pos[frames, ib[ev]] - traj.pos[frames, ia[ev]]
        dist = np.linalg.norm(d, axis=-1)
        n = d / np.where(dist > 0, dist, 1.0)[:, None]
        dv = traj.vel[frames, ib[ev]] - traj.vel[frames, ia[ev]]
        approach = -np.einsum("ij,ij->i", dv, n)
        return dist - ra[ev] - rb[ev] - threshold[ev], approach

    return _lookback(traj, event_step, prev_step, gap_fn, stride)


def bowl_gap(pos: np.ndarray, radius: np.ndarray, bowl: Bowl):
    """Surface gap (m) of particles to the closed bowl and the bowl's outward normal at the
    nearest face (pointing from the particle towards the wall)."""
    rho = np.hypot(pos[:, 0], pos[:, 1])
    side = bowl.radius - rho - radius
    bottom = pos[:, 2] - radius
    lid = bowl.height - pos[:, 2] - radius
    gaps = np.stack([side, bottom, lid], axis=1)
    which = np.argmin(gaps, axis=1)
    radial = np.column_stack([pos[:, 0], pos[:, 1], np.zeros(len(pos))]) / np.where(rho > 0, rho, 1.0)[:, None]
    normals = np.where(
        (which == 0)[:, None], radial, np.where((which == 1)[:, None], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0])
    )
    return gaps[np.arange(len(pos)), which], normals


def _rot_z(points: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.column_stack([c * points[:, 0] - s * points[:, 1], s * points[:, 0] + c * points[:, 1], points[:, 2]])


def impeller_gap(pos: np.ndarray, radius: np.ndarray, imp: Impeller, angle: np.ndarray):
    """Surface gap (m) of particles to the impeller turned by `angle` (rad, per particle) and
    the unit vector from the particle centre towards the nearest impeller point."""
    centre, half = blade_box(imp)
    pitch = np.radians(imp.pitch_deg)
    cp, sp = np.cos(pitch), np.sin(pitch)
    best = np.full(len(pos), np.inf)
    towards = np.zeros_like(pos)
    for k in range(imp.blades):
        theta = angle + 2.0 * np.pi * k / imp.blades
        local = _rot_z(pos, -theta) - centre
        # undo the pitch (a rotation about the blade's radial x axis)
        local = np.column_stack(
            [local[:, 0], cp * local[:, 1] + sp * local[:, 2], -sp * local[:, 1] + cp * local[:, 2]]
        )
        nearest = np.clip(local, -half, half)
        diff = nearest - local
        dist = np.linalg.norm(diff, axis=1)
        diff = np.column_stack([diff[:, 0], cp * diff[:, 1] - sp * diff[:, 2], sp * diff[:, 1] + cp * diff[:, 2]])
        diff = _rot_z(diff, theta)
        better = dist < best
        best[better] = dist[better]
        towards[better] = diff[better] / np.where(dist[better] > 0, dist[better], 1.0)[:, None]
    # hub: a cylinder of the blade height
    rho = np.hypot(pos[:, 0], pos[:, 1])
    z0, z1 = imp.clearance, imp.clearance + imp.blade_height
    dr = np.maximum(rho - 0.5 * imp.hub_diameter, 0.0)
    dz = np.maximum(np.maximum(z0 - pos[:, 2], pos[:, 2] - z1), 0.0)
    hub = np.hypot(dr, dz)
    better = hub < best
    if better.any():
        radial = -np.column_stack([pos[:, 0], pos[:, 1], np.zeros(len(pos))]) / np.where(rho > 0, rho, 1.0)[:, None]
        vertical = np.column_stack(
            [np.zeros(len(pos)), np.zeros(len(pos)), np.sign(np.clip(pos[:, 2], z0, z1) - pos[:, 2])]
        )
        vec = radial * dr[:, None] + vertical * dz[:, None]
        norm = np.linalg.norm(vec, axis=1)
        vec = vec / np.where(norm > 0, norm, 1.0)[:, None]
        best[better] = hub[better]
        towards[better] = vec[better]
    return best - radius, towards


def wall_events(
    traj: Trajectories,
    wall: np.ndarray,
    pid,
    radius,
    event_step,
    prev_step,
    gap_fraction: float,
    bowl: Bowl,
    imp: Impeller,
    angle_of_step,
    omega: float,
    stride: int = 1,
) -> Events:
    """Classify particle-wall contacts (wall 0 = bowl, 1 = impeller) that begin at `event_step`.
    `angle_of_step(steps)` gives the impeller's rotation angle (rad); `omega` its angular speed
    (rad/s, signed about +z). The gap threshold is gap_fraction x the particle diameter."""
    ip = traj.index_of(np.asarray(pid, np.int64))
    r = np.asarray(radius, float)
    wall = np.asarray(wall, np.int64)
    threshold = gap_fraction * 2.0 * r

    def gap_fn(frames, ev):
        p = traj.pos[frames, ip[ev]]
        v = traj.vel[frames, ip[ev]]
        gap = np.empty(len(ev))
        approach = np.empty(len(ev))
        is_bowl = wall[ev] == 0
        if is_bowl.any():
            g, n = bowl_gap(p[is_bowl], r[ev][is_bowl], bowl)
            gap[is_bowl] = g
            approach[is_bowl] = np.einsum("ij,ij->i", v[is_bowl], n)
        imp_rows = ~is_bowl
        if imp_rows.any():
            pi = p[imp_rows]
            g, n = impeller_gap(pi, r[ev][imp_rows], imp, angle_of_step(traj.steps[frames][imp_rows]))
            wall_v = np.column_stack([-omega * pi[:, 1], omega * pi[:, 0], np.zeros(len(pi))])
            gap[imp_rows] = g
            approach[imp_rows] = np.einsum("ij,ij->i", v[imp_rows] - wall_v, n)
        return gap - threshold[ev], approach

    return _lookback(traj, event_step, prev_step, gap_fn, stride)
