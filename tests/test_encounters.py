"""Encounters on hand-made trajectories with known answers (no engine needed): a pair that
chatters without separating is one encounter, a pair that separates beyond the gap and comes back
is two, and the impact velocity is the known approach speed."""

from __future__ import annotations

import numpy as np
import pytest

from pbmdem.config import Bowl, Impeller
from pbmdem.dem.collisions import window_starts
from pbmdem.dem.dumps import Snapshots
from pbmdem.dem.encounters import Trajectories, bowl_gap, impeller_gap, pair_events, wall_events

R = 1.0e-3  # particle radius (m): diameter 2 mm, encounter gap 0.25 x 2 mm = 0.5 mm
DT = 1.0e-5  # s per step


def record(gaps: np.ndarray, speeds: np.ndarray, position_every: int = 1):
    """Two particles (ids 7 and 3) on the x axis with the given surface gap (m) and velocity of
    particle 3 (m/s, particle 7 at rest) at every step; returns contact snapshots at every step
    and position snapshots every `position_every` steps."""
    steps = np.arange(len(gaps))
    x3 = 2 * R + gaps
    rows, counts = [], []
    for g in gaps:
        if g < 0:
            rows.append([7.0, 3.0, -g])  # id1, id2, overlap (LIGGGHTS may list them in any order)
        counts.append(1 if g < 0 else 0)
    data = np.array(rows).reshape(-1, 3)
    snaps = Snapshots(steps=steps, offsets=np.concatenate([[0], np.cumsum(counts)]), data=data)
    keep = steps % position_every == 0
    pos = np.zeros((keep.sum(), 2, 3))
    vel = np.zeros((keep.sum(), 2, 3))
    pos[:, 0, 0] = x3[keep]  # ids are sorted: row 0 = id 3 (moving), row 1 = id 7 at the origin
    vel[:, 0, 0] = speeds[keep]
    traj = Trajectories(steps=steps[keep], ids=np.array([3, 7]), pos=pos, vel=vel)
    return snaps, traj


def approach_then(gaps_after: list[float], start_gap=2e-3, v=0.1, steps_in=30):
    """Particle 3 approaches from `start_gap` at speed v, then follows `gaps_after`."""
    approach = start_gap - v * DT * np.arange(steps_in)
    approach = approach[approach >= 0]
    gaps = np.concatenate([approach, gaps_after])
    speeds = np.concatenate([np.full(len(approach), -v), np.zeros(len(gaps_after))])
    return gaps, speeds


def classify(snaps, traj, window_start=0, stride=1):
    s = window_starts(snaps, window_start, stride=stride)
    ev = pair_events(
        traj,
        s.first,
        s.second,
        np.full(len(s.first), R),
        np.full(len(s.first), R),
        s.step,
        s.prev_step,
        gap_fraction=0.25,
        stride=stride,
    )
    return s, ev


def test_chattering_pair_is_one_encounter_with_known_velocity():
    # approach at 0.1 m/s from a 2 mm gap, then touch and separate by 0.02 mm three times
    chatter = [-1e-5, -1e-5, 2e-5, 2e-5, -1e-5, 2e-5, -1e-5, -1e-5, 1e-5, -1e-5]
    gaps, speeds = approach_then(chatter, steps_in=2001)
    snaps, traj = record(gaps, speeds)
    s, ev = classify(snaps, traj)
    assert len(s.step) == 4  # four contacts begin (the raw count) ...
    assert ev.encounter.sum() == 1  # ... but only the first is an encounter
    assert ev.encounter[np.argmin(s.step)]
    assert ev.velocity[ev.encounter][0] == pytest.approx(0.1, rel=1e-12)


def test_pair_that_separates_beyond_the_gap_and_returns_is_two_encounters():
    away = list(np.linspace(0, 1.0e-3, 20)) + list(np.linspace(1.0e-3, 0, 20))  # 1 mm > 0.5 mm gap
    gaps, speeds = approach_then([-1e-5, -1e-5] + away[1:-1] + [-1e-5, -1e-5], steps_in=2001)
    snaps, traj = record(gaps, speeds)
    s, ev = classify(snaps, traj)
    assert len(s.step) == 2 and ev.encounter.sum() == 2


def test_separation_below_the_gap_is_a_retouch():
    near = list(np.linspace(0, 0.4e-3, 20)) + list(np.linspace(0.4e-3, 0, 20))  # 0.4 mm < 0.5 mm
    gaps, speeds = approach_then([-1e-5] + near[1:-1] + [-1e-5], steps_in=2001)
    snaps, traj = record(gaps, speeds)
    s, ev = classify(snaps, traj)
    assert len(s.step) == 2 and ev.encounter.sum() == 1


def test_window_and_history():
    """Contacts before the window are history only; a pair that never left the gap during the
    whole record and has no earlier contact is undetermined, not an encounter."""
    gaps = np.concatenate([np.full(50, 1e-4), [-1e-5, -1e-5]])  # hovering 0.1 mm apart, then touch
    snaps, traj = record(gaps, np.zeros(len(gaps)))
    s, ev = classify(snaps, traj)
    assert len(s.step) == 1 and not ev.encounter.any() and ev.undetermined.all()
    s, ev = classify(snaps, traj, window_start=int(snaps.steps[-1]))
    assert len(s.step) == 0


def test_coarser_position_snapshots_keep_the_count():
    away = list(np.linspace(0, 1.0e-3, 40)) + list(np.linspace(1.0e-3, 0, 40))
    gaps, speeds = approach_then([-1e-5, -1e-5] + away[1:-1] + [-1e-5, -1e-5], steps_in=2001)
    snaps, traj = record(gaps, speeds, position_every=4)
    s, ev = classify(snaps, traj)
    assert ev.encounter.sum() == 2
    s2, ev2 = classify(snaps, traj, stride=2)
    assert ev2.encounter.sum() == 2


def test_wall_gaps_and_impeller_velocity():
    bowl = Bowl(diameter=0.06, height=0.05, segments=48)
    pos = np.array([[0.029, 0.0, 0.02], [0.0, 0.01, 0.0015], [0.0, 0.0, 0.0485]])
    gap, normal = bowl_gap(pos, np.full(3, 1e-3), bowl)
    np.testing.assert_allclose(gap, [0.0, 0.0005, 0.0005], atol=1e-12)
    np.testing.assert_allclose(normal, [[1, 0, 0], [0, 0, -1], [0, 0, 1]], atol=1e-12)
    imp = Impeller(
        blades=1,
        blade_length=0.02,
        blade_height=0.01,
        blade_thickness=0.002,
        clearance=0.001,
        pitch_deg=0.0,
        hub_diameter=0.004,
    )
    # a particle 1 mm in front of the blade (turned by 90 degrees, so it lies along +y)
    p = np.array([[-0.0030, 0.015, 0.006]])  # blade face at x = -0.001 after the turn
    g, towards = impeller_gap(p, np.array([5e-4]), imp, np.array([np.pi / 2]))
    assert g[0] == pytest.approx(0.0015, abs=1e-12)
    np.testing.assert_allclose(towards[0], [1, 0, 0], atol=1e-12)
    # a resting particle hit by the blade: its approach speed is the blade's omega x r
    omega = 100.0
    traj = Trajectories(
        steps=np.array([0, 1]), ids=np.array([1]), pos=np.repeat(p[None], 2, 0), vel=np.zeros((2, 1, 3))
    )
    ev = wall_events(traj, [1], [1], [5e-4], [2], [-1], 0.25, bowl, imp, lambda s: np.full(len(s), np.pi / 2), omega)
    assert ev.encounter[0]
    assert ev.velocity[0] == pytest.approx(omega * 0.015, rel=1e-9)  # the face moves at omega x r towards it


def test_oblique_pair_impacts_at_its_normal_approach_speed_not_its_relative_speed():
    """Issue 25, 7a: particle 3 slides past particle 7 at (-0.1, 0.3, 0) m/s and touches it when
    their line of centres is the x axis. The impact speed is the normal approach speed (about
    0.1 m/s, exactly -v.n at the last position snapshot before the contact), not the full relative
    speed (0.316 m/s)."""
    v = np.array([-0.1, 0.3, 0.0])
    touch = 2001  # first step in contact
    steps = np.arange(touch + 3)
    rel = np.array([2 * R, 0.0, 0.0]) + np.outer((steps - touch + 1) * DT, v)  # |rel| = 2R just before `touch`
    pos = np.zeros((len(steps), 2, 3))
    vel = np.zeros((len(steps), 2, 3))
    pos[:, 0] = rel  # row 0 = id 3 (moving), row 1 = id 7 at rest at the origin
    vel[:, 0] = v
    traj = Trajectories(steps=steps, ids=np.array([3, 7]), pos=pos, vel=vel)
    counts = (steps >= touch).astype(int)
    data = np.array([[7.0, 3.0, 1e-6]] * int(counts.sum()))
    snaps = Snapshots(steps=steps, offsets=np.concatenate([[0], np.cumsum(counts)]), data=data)
    s, ev = classify(snaps, traj)
    assert len(s.step) == 1 and ev.encounter.all()
    before = rel[touch - 1]
    normal = before / np.linalg.norm(before)
    expected = -float(v @ normal)  # the normal approach speed at the last snapshot before the contact
    assert ev.velocity[0] == pytest.approx(expected, rel=1e-12)
    assert expected == pytest.approx(0.1, rel=1e-2)
    assert np.linalg.norm(v) == pytest.approx(0.316, rel=1e-2)  # what the full relative speed would give
