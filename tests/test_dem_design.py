"""The space-filling design of operating points and the grid that runs it."""

import copy
import math

import pytest

from pbmdem.config import Config, ConfigError
from pbmdem.dem.design import DesignSpace, design_names, design_points


def test_the_design_is_seeded_and_stays_in_its_space():
    space = DesignSpace()
    first = design_points(16, seed=7)
    assert first == design_points(16, seed=7)
    assert first != design_points(16, seed=8)
    for dist in first:
        assert space.rpm_range[0] - 5 <= dist["rpm"] <= space.rpm_range[1] + 5
        d, f = dist["diameters"], dist["number_fractions"]
        assert d == sorted(d) and len(set(d)) == 3
        assert space.d_min_range[0] - 5e-5 <= d[0] <= space.d_min_range[1] + 5e-5
        assert d[-1] <= space.d_max_limit + 5e-5
        assert space.min_span - 0.1 <= d[-1] / d[0] <= space.max_span + 0.1
        assert math.isclose(sum(f), 1.0, abs_tol=1e-9)
        assert min(f) >= space.min_fraction - 0.005


def test_the_design_fills_its_space():
    """Sobol points spread over each coordinate: the smallest diameters and spans of 16
    distributions, and their speeds, reach into every quarter of their (log) ranges."""
    space = DesignSpace()
    dists = design_points(16, seed=20141)
    for key, (lo, hi) in (("diameters", space.d_min_range), ("rpm", space.rpm_range)):
        lo, hi = math.log(lo), math.log(hi)
        values = [d[key][0] if key == "diameters" else d[key] for d in dists]
        quarters = {min(3, int(4 * (math.log(x) - lo) / (hi - lo))) for x in values}
        assert quarters == {0, 1, 2, 3}, key
    first = [d["number_fractions"][0] for d in dists]
    assert min(first) < 0.2 and max(first) > 0.5


def test_the_config_holds_the_documented_design(default_config):
    points = default_config.grid.design_points
    names = [p.distribution for p in points]
    assert names == design_names(len(names))
    for point, design in zip(points, design_points(len(points), seed=20141)):
        sizes = default_config.size_distributions[point.distribution]
        assert point.rpm == design["rpm"]
        assert list(sizes.diameters) == pytest.approx(design["diameters"])
        assert list(sizes.number_fractions) == pytest.approx(design["number_fractions"])


def test_the_default_grid_spans_150_to_1200_rpm_with_its_design_points_once_each(default_config):
    cfg = default_config
    grid = cfg.grid
    points = grid.points()
    for rpm in grid.impeller_rpm:
        for name in grid.size_distributions:
            assert (rpm, name) in points
    for point in grid.design_points:
        assert (point.rpm, point.distribution) in points
        assert [p for p in points if p[1] == point.distribution] == [(point.rpm, point.distribution)]
        assert cfg.point_replicates(point.distribution) == grid.design_replicates == 1
    assert min(grid.impeller_rpm) == 150 and max(grid.impeller_rpm) == 1200 and len(grid.impeller_rpm) >= 4
    assert cfg.point_replicates("fine") == cfg.dem_replicates
    for point in grid.extra_points:
        assert cfg.point_replicates(point.distribution) == cfg.dem_replicates
    assert grid.count() == len(points)
    assert cfg.validation.sweep.start == 150


def test_an_undefined_design_distribution_is_refused(default_config):
    mapping = copy.deepcopy(default_config.to_dict())
    mapping["grid"]["design_points"].append({"rpm": 300.0, "distribution": "sf99"})
    with pytest.raises(ConfigError, match=r"grid\.design_points\[8\]\.distribution: 'sf99' is not defined"):
        Config.from_mapping(mapping)
