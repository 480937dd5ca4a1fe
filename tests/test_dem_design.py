"""The space-filling design of size distributions and the grid that runs it."""

import copy
import math

import pytest
import yaml
from conftest import ROOT

from pbmdem.config import Config, ConfigError
from pbmdem.dem.design import DesignSpace, design_distributions, design_names


def test_the_design_is_seeded_and_stays_in_its_space():
    space = DesignSpace()
    first = design_distributions(16, seed=7)
    assert first == design_distributions(16, seed=7)
    assert first != design_distributions(16, seed=8)
    for dist in first:
        d, f = dist["diameters"], dist["number_fractions"]
        assert d == sorted(d) and len(set(d)) == 3
        assert space.d_min_range[0] - 5e-5 <= d[0] <= space.d_min_range[1] + 5e-5
        assert d[-1] <= space.d_max_limit + 5e-5
        assert space.min_span - 0.1 <= d[-1] / d[0] <= space.max_span + 0.1
        assert math.isclose(sum(f), 1.0, abs_tol=1e-9)
        assert min(f) >= space.min_fraction - 0.005


def test_the_design_fills_its_space():
    """Sobol points spread over each coordinate: the smallest diameters and spans of 16
    distributions reach into every quarter of their ranges."""
    space = DesignSpace()
    dists = design_distributions(16, seed=20141)
    lo, hi = (math.log(x) for x in space.d_min_range)
    quarters = {min(3, int(4 * (math.log(d["diameters"][0]) - lo) / (hi - lo))) for d in dists}
    assert quarters == {0, 1, 2, 3}
    first = [d["number_fractions"][0] for d in dists]
    assert min(first) < 0.2 and max(first) > 0.5


@pytest.fixture(scope="module")
def coverage_config(default_config):
    """config/config.yaml with config/coverage.yaml laid over it (as Snakemake merges them)."""
    mapping = copy.deepcopy(default_config.to_dict())
    overlay = yaml.safe_load((ROOT / "config" / "coverage.yaml").read_text())
    for section, values in overlay.items():
        mapping[section].update(values)
    return Config.from_mapping(mapping)


def test_the_config_holds_the_documented_design(coverage_config):
    names = coverage_config.grid.design_distributions
    assert names == tuple(design_names(len(names)))
    for name, dist in zip(names, design_distributions(len(names), seed=20141)):
        sizes = coverage_config.size_distributions[name]
        assert list(sizes.diameters) == pytest.approx(dist["diameters"])
        assert list(sizes.number_fractions) == pytest.approx(dist["number_fractions"])


def test_design_distributions_run_at_every_speed_with_their_own_replicates(coverage_config):
    cfg = coverage_config
    grid = cfg.grid
    points = grid.points()
    for rpm in grid.impeller_rpm:
        for name in (*grid.size_distributions, *grid.design_distributions):
            assert (rpm, name) in points
    assert min(grid.impeller_rpm) == 150 and len(grid.impeller_rpm) >= 4
    assert cfg.point_replicates(grid.design_distributions[0]) == grid.design_replicates == 1
    assert cfg.point_replicates("fine") == cfg.dem_replicates
    for point in grid.extra_points:
        assert cfg.point_replicates(point.distribution) == cfg.dem_replicates
    assert cfg.validation.sweep.start == 150


def test_an_undefined_design_distribution_is_refused(default_config):
    mapping = copy.deepcopy(default_config.to_dict())
    mapping["grid"]["design_distributions"].append("sf99")
    with pytest.raises(ConfigError, match=r"grid\.design_distributions: 'sf99' is not defined"):
        Config.from_mapping(mapping)
