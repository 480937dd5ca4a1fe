"""The space-filling design of operating points and the grid that runs it."""

import copy
import math

import pytest
from design_points import CORNER_NAME, DesignSpace, corner_point, design_names, design_points

from pbmdem.config import Config, ConfigError, SizeDistribution
from pbmdem.dem.plan import bed_particle_count, class_counts

#: the default bed's solid volume (m3): 18 mm x pi/4 (60 mm)^2 x 0.60 (granulator.bed_solid_volume)
BED = 0.018 * math.pi / 4.0 * 0.060**2 * 0.60


def _particles(point):
    """Particles per class of the design point in the default bed, unrounded: stricter than the DEM
    plan's whole-particle counts (`planned` in the corner's test), which round 49.6 up to 50."""
    d, f = point["diameters"], point["number_fractions"]
    mean_volume = sum(fk * math.pi / 6.0 * dk**3 for dk, fk in zip(d, f))
    return [fk * BED / mean_volume for fk in f]


def test_the_design_is_seeded_and_stays_in_its_space():
    space = DesignSpace()
    first = design_points(16, 7, BED)
    assert first == design_points(16, 7, BED)
    assert first != design_points(16, 8, BED)
    for dist in first:
        assert space.rpm_range[0] - 5 <= dist["rpm"] <= space.rpm_range[1] + 5
        d, f = dist["diameters"], dist["number_fractions"]
        assert d == sorted(d) and len(set(d)) == 3
        assert space.d_min_range[0] - 5e-5 <= d[0] <= space.d_min_range[1] + 5e-5
        assert d[-1] <= space.d_max_limit + 5e-5
        assert space.min_span - 0.1 <= d[-1] / d[0] <= space.max_span + 0.1
        assert math.isclose(sum(f), 1.0, abs_tol=1e-9)
        assert space.min_fraction - 5e-4 <= f[-1] == min(f)  # the largest class is the rarest
        assert min(_particles(dist)) >= space.min_class_particles


def test_the_design_fills_its_space():
    """Sobol points spread over each coordinate: the smallest diameters and spans of 16
    distributions, and their speeds, reach into every quarter of their (log) ranges; the largest
    class's fraction reaches below 5 % (where PBM-ANN's samples go) and up to about a third."""
    space = DesignSpace()
    dists = design_points(16, 20141, BED)
    for key, (lo, hi) in (("diameters", space.d_min_range), ("rpm", space.rpm_range)):
        lo, hi = math.log(lo), math.log(hi)
        values = [d[key][0] if key == "diameters" else d[key] for d in dists]
        quarters = {min(3, int(4 * (math.log(x) - lo) / (hi - lo))) for x in values}
        assert quarters == {0, 1, 2, 3}, key
    rare = [d["number_fractions"][-1] for d in dists]
    assert min(rare) < 0.05 and max(rare) > 0.25


def test_a_bed_too_small_for_rare_classes_is_refused():
    """With a bed of a few hundred particles no class can be 2 % and hold 50 of them."""
    with pytest.raises(ValueError, match=r"hold 50 particles in every class"):
        design_points(16, 20141, BED / 20.0, DesignSpace(min_fraction=0.02, d_min_range=(0.0030, 0.0032)))


def test_the_corner_holds_the_largest_granules_as_rare_classes_at_the_fastest_speed():
    space = DesignSpace()
    corner = corner_point(BED)
    d, f = corner["diameters"], corner["number_fractions"]
    assert corner["rpm"] == space.rpm_range[1]
    assert d[-1] == space.d_max_limit and d[0] < d[1] < d[2]
    assert d[-1] / d[0] <= space.max_span and space.d_min_range[0] <= d[0] <= space.d_min_range[1]
    assert math.isclose(sum(f), 1.0, abs_tol=1e-9) and f[1] == f[2] < f[0]

    def planned(fractions):  # the DEM plan's own counts, rounded to whole particles
        return class_counts(
            bed_particle_count(BED, SizeDistribution(diameters=tuple(d), number_fractions=tuple(fractions))), fractions
        )

    assert min(planned(f)) >= space.min_class_particles
    # the rarest that holds 50: one step (0.001) rarer leaves the largest classes short
    assert min(planned([f[0] + 0.002, f[1] - 0.001, f[2] - 0.001])) < space.min_class_particles


def test_a_bed_too_small_for_the_corner_is_refused():
    with pytest.raises(ValueError, match=r"cannot hold 50 particles in every class"):
        corner_point(BED / 4.0)


def test_the_config_holds_the_documented_design(default_config):
    points = default_config.grid.design_points
    names = [p.distribution for p in points]
    assert names == [*design_names(len(names) - 1), CORNER_NAME]
    volume = default_config.granulator.bed_solid_volume
    assert volume == pytest.approx(BED)
    corner = corner_point(volume)
    for point, design in zip(points, [*design_points(len(points) - 1, 20141, volume), corner]):
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
    with pytest.raises(ConfigError, match=r"grid\.design_points\[11\]\.distribution: 'sf99' is not defined"):
        Config.from_mapping(mapping)
