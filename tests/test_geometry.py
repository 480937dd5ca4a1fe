"""Bowl and impeller meshes: closed, outward-oriented, inside the bowl, readable by meshio."""

import math

import meshio
import numpy as np
import pytest

from pbmdem.dem import geometry


def test_bowl_is_a_closed_cylinder(default_config):
    bowl = default_config.granulator.bowl
    pts, tris = geometry.bowl_mesh(bowl)
    volume = geometry.check_closed_surface(pts, tris)
    n = bowl.segments
    polygon_area = 0.5 * n * bowl.radius**2 * math.sin(2 * math.pi / n)
    assert volume == pytest.approx(polygon_area * bowl.height, rel=1e-12)  # positive: outward normals


def test_impeller_parts_are_closed_and_inside(default_config):
    bowl = default_config.granulator.bowl
    imp = default_config.granulator.impeller
    pts, tris = geometry.impeller_mesh(imp)
    volume = geometry.check_closed_surface(pts, tris)
    blades = imp.blades * imp.blade_length * imp.blade_height * imp.blade_thickness
    assert volume > blades  # blades plus hub (overlapping closed parts add up)
    assert np.hypot(pts[:, 0], pts[:, 1]).max() < bowl.radius
    assert pts[:, 2].min() == pytest.approx(imp.clearance)
    assert pts[:, 2].max() == pytest.approx(imp.top)


def test_pitched_blades_stay_closed(default_config):
    imp = default_config.granulator.impeller
    imp = imp.replace(pitch_deg=30.0)
    pts, tris = geometry.impeller_mesh(imp)
    assert geometry.check_closed_surface(pts, tris) > 0
    assert pts[:, 2].max() == pytest.approx(imp.top)


def test_open_surface_is_detected(default_config):
    pts, tris = geometry.bowl_mesh(default_config.granulator.bowl)
    with pytest.raises(ValueError, match="not closed"):
        geometry.check_closed_surface(pts, tris[:-1])


def test_stl_files_round_trip(tmp_path, default_config):
    paths = geometry.write_granulator(default_config.granulator, tmp_path)
    for name, path in paths.items():
        mesh = meshio.read(path)
        assert path.read_text().startswith("solid")  # ASCII STL, as LIGGGHTS reads it
        tris = mesh.cells_dict["triangle"]
        assert len(tris) > 10, name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bowl.stl", "impeller.stl"]
