"""Granulator geometry as STL meshes (meshio, ASCII): a closed cylindrical bowl on the z axis, bottom at
z = 0, and a bladed impeller turning about it; every part closed with outward normals (docs/dem.md,
"The granulator").
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

from pbmdem.atomic import atomic_path
from pbmdem.config import Bowl, Granulator, Impeller


def _disc_fan(center: np.ndarray, ring: np.ndarray, upward: bool) -> np.ndarray:
    """Triangles of a flat disc from a centre vertex index and a ring of vertex indices."""
    nxt = np.roll(ring, -1)
    c = np.full_like(ring, center)
    if upward:
        return np.stack([c, ring, nxt], axis=1)
    return np.stack([c, nxt, ring], axis=1)


def _cylinder(radius: float, z0: float, z1: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Closed n-sided prism about the z axis from z0 to z1 (side, floor, lid), normals outward."""
    theta = 2.0 * np.pi * np.arange(n) / n
    x, y = radius * np.cos(theta), radius * np.sin(theta)
    points = np.vstack([np.column_stack([x, y, np.full(n, z0)]), np.column_stack([x, y, np.full(n, z1)])])
    points = np.vstack([points, [[0.0, 0.0, z0]], [[0.0, 0.0, z1]]])
    ib, it = np.arange(n), np.arange(n, 2 * n)
    jb, jt = np.roll(ib, -1), np.roll(it, -1)
    side = np.vstack([np.stack([ib, jb, jt], axis=1), np.stack([ib, jt, it], axis=1)])
    floor = _disc_fan(2 * n, ib, upward=False)  # outward = -z
    lid = _disc_fan(2 * n + 1, it, upward=True)  # outward = +z
    return points, np.vstack([side, floor, lid]).astype(np.int64)


def bowl_mesh(bowl: Bowl) -> tuple[np.ndarray, np.ndarray]:
    """The closed bowl (LIGGGHTS ignores the normals; consistent ones let the mesh be checked)."""
    return _cylinder(bowl.radius, 0.0, bowl.height, int(bowl.segments))


def _box(half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box centred at the origin with outward-oriented triangles."""
    square = ((-1, -1), (1, -1), (1, 1), (-1, 1))
    pts = np.array([(x, y, z) for z in (-1, 1) for x, y in square]) * half
    tris = np.array(
        [
            [0, 2, 1],
            [0, 3, 2],  # bottom (-z)
            [4, 5, 6],
            [4, 6, 7],  # top (+z)
            [0, 1, 5],
            [0, 5, 4],  # -y
            [1, 2, 6],
            [1, 6, 5],  # +x
            [2, 3, 7],
            [2, 7, 6],  # +y
            [3, 0, 4],
            [3, 4, 7],
        ]  # -x
    )
    return pts, tris


def _rotation(axis: str, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "z":
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    raise ValueError(axis)


def blade_box(imp: Impeller) -> tuple[np.ndarray, np.ndarray]:
    """Centre and half extents (m) of blade 0 before its pitch: a plate along x from half the hub
    radius (inside the hub, so that no two blades share a face, which LIGGGHTS rejects) to the
    tip, its underside `clearance` above the floor."""
    r0 = 0.25 * imp.hub_diameter
    span = imp.blade_length - r0
    half = np.array([0.5 * span, 0.5 * imp.blade_thickness, 0.5 * imp.blade_height])
    return np.array([r0 + 0.5 * span, 0.0, imp.clearance + 0.5 * imp.blade_height]), half


def impeller_mesh(imp: Impeller) -> tuple[np.ndarray, np.ndarray]:
    """Hub (a closed prism) plus `blades` closed boxes (`blade_box`), blade k turned by
    2 pi k / blades about z and tilted by `pitch_deg` about its own radial axis."""
    parts_pts, parts_tris, offset = [], [], 0
    centre, half = blade_box(imp)
    for k in range(imp.blades):
        pts, tris = _box(half)
        pts = pts @ _rotation("x", np.radians(imp.pitch_deg)).T
        pts[:, 0] += centre[0]
        pts = pts @ _rotation("z", 2.0 * np.pi * k / imp.blades).T
        pts[:, 2] += centre[2]
        parts_pts.append(pts)
        parts_tris.append(tris + offset)
        offset += len(pts)
    # hub: a 12-sided closed prism from the bottom clearance to the blade top
    hub_pts, hub_tris = _cylinder(0.5 * imp.hub_diameter, imp.clearance, imp.clearance + imp.blade_height, 12)
    parts_pts.append(hub_pts)
    parts_tris.append(hub_tris + offset)
    return np.vstack(parts_pts), np.vstack(parts_tris).astype(np.int64)


def write_stl(path: str | Path, points: np.ndarray, triangles: np.ndarray) -> Path:
    """Write an ASCII STL atomically (LIGGGHTS reads ASCII STL)."""
    path = Path(path)
    mesh = meshio.Mesh(points=np.asarray(points, float), cells=[("triangle", np.asarray(triangles))])
    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="stl", binary=False)
    return path


def write_granulator(granulator: Granulator, outdir: str | Path) -> dict[str, Path]:
    """Write bowl.stl and impeller.stl of the granulator into `outdir`."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    bowl, imp = granulator.bowl, granulator.impeller
    return {
        "bowl": write_stl(outdir / "bowl.stl", *bowl_mesh(bowl)),
        "impeller": write_stl(outdir / "impeller.stl", *impeller_mesh(imp)),
    }
