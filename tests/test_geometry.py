"""Bowl and impeller meshes: closed, outward-oriented, inside the bowl, readable by meshio."""

import math

import meshio
import numpy as np
import pytest

from pbmdem.dem import geometry


def check_closed_surface(points: np.ndarray, triangles: np.ndarray) -> float:
    """Return the enclosed volume; raise if some edge is not shared by exactly two triangles
    traversed in opposite directions (i.e. the surface is not closed and consistently oriented)."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    fwd = {tuple(e) for e in edges.tolist()}
    if len(fwd) != len(edges):
        raise ValueError("a directed edge is used twice: inconsistent triangle orientation")
    missing = [e for e in fwd if (e[1], e[0]) not in fwd]
    if missing:
        raise ValueError(f"surface is not closed: {len(missing)} edges have no opposite twin, e.g. {missing[0]}")
    a, b, c = (points[triangles[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def test_bowl_is_a_closed_cylinder(default_config):
    bowl = default_config.granulator.bowl
    pts, tris = geometry.bowl_mesh(bowl)
    volume = check_closed_surface(pts, tris)
    n = bowl.segments
    polygon_area = 0.5 * n * bowl.radius**2 * math.sin(2 * math.pi / n)
    assert volume == pytest.approx(polygon_area * bowl.height, rel=1e-12)  # positive: outward normals


def test_impeller_parts_are_closed_and_inside(default_config):
    bowl = default_config.granulator.bowl
    imp = default_config.granulator.impeller
    pts, tris = geometry.impeller_mesh(imp)
    volume = check_closed_surface(pts, tris)
    blades = imp.blades * imp.blade_length * imp.blade_height * imp.blade_thickness
    assert volume > blades  # blades plus hub (overlapping closed parts add up)
    assert np.hypot(pts[:, 0], pts[:, 1]).max() < bowl.radius
    assert pts[:, 2].min() == pytest.approx(imp.clearance)
    assert pts[:, 2].max() == pytest.approx(imp.top)


def test_pitched_blades_stay_closed(default_config):
    imp = default_config.granulator.impeller
    imp = imp.replace(pitch_deg=30.0)
    pts, tris = geometry.impeller_mesh(imp)
    assert check_closed_surface(pts, tris) > 0
    assert pts[:, 2].max() == pytest.approx(imp.top)


def test_open_surface_is_detected(default_config):
    pts, tris = geometry.bowl_mesh(default_config.granulator.bowl)
    with pytest.raises(ValueError, match="not closed"):
        check_closed_surface(pts, tris[:-1])


def test_stl_files_round_trip(tmp_path, default_config):
    paths = geometry.write_granulator(default_config.granulator, tmp_path)
    for name, path in paths.items():
        mesh = meshio.read(path)
        assert path.read_text().startswith("solid")  # ASCII STL, as LIGGGHTS reads it
        tris = mesh.cells_dict["triangle"]
        assert len(tris) > 10, name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bowl.stl", "impeller.stl"]
