"""Every bad input gives a specific ValueError subclass naming the value and what is allowed."""

from __future__ import annotations

import numpy as np
import pbm_verification as ver
import pytest
from conftest import config_of

from pbmdem.config import ConfigError, Pbm, Solver
from pbmdem.pbm import (
    CollisionKernel,
    Consolidation,
    ConstantFrequency,
    ConstantKernel,
    GranulationPBM,
    Grid,
    GridOverflowError,
    GridRangeError,
    KernelShapeError,
    NegativePopulationError,
    PBMError,
    PBMInputError,
    State,
    SumKernel,
    run_batch,
)


def test_errors_are_value_errors():
    for cls in (PBMInputError, GridRangeError, GridOverflowError, KernelShapeError, NegativePopulationError):
        assert issubclass(cls, PBMError) and issubclass(cls, ValueError)


@pytest.mark.parametrize(
    "make,match",
    [
        (lambda: ConstantKernel(0.0), r"beta0 = 0.0"),
        (lambda: SumKernel(-1.0), r"sum kernel b = -1.0"),
        (lambda: ConstantFrequency(0.0), r"constant collision frequency = 0.0"),
        (lambda: ConstantFrequency(float("nan")), r"constant collision frequency = nan"),
        (lambda: Grid(2, 2.0, v0=1.0), r"grid bins = 2; allowed: an integer >= 3"),
        (lambda: Grid(10, 1.0, v0=1.0), r"grid ratio = 1.0; allowed: a number > 1"),
        (lambda: Grid(10, 2.0, v0=-1.0), r"grid v0 = -1.0"),
    ],
)
def test_bad_parameters(make, match):
    with pytest.raises(PBMInputError, match=match):
        make()


@pytest.mark.parametrize(
    "section,match",
    [
        ({"liquid_addition": {"rate": 0.0}}, r"pbm.liquid_addition.rate = 0.0"),
        ({"liquid_addition": {"distribution": "mass"}}, r"pbm.liquid_addition.distribution = 'mass'"),
        ({"consolidation": {"rate": -0.1}}, r"pbm.consolidation.rate = -0.1"),
        ({"consolidation": {"min_porosity": 1.0}}, r"pbm.consolidation.min_porosity = 1.0"),
        ({"aggregation": {"beta0": -2.0}}, r"pbm.aggregation.beta0 = -2.0"),
        ({"aggregation": {"success": {"model": "always_on"}}}, r"pbm.aggregation.success.model = 'always_on'"),
        ({"aggregation": {"scheme": "pivot"}}, r"pbm.aggregation.scheme = 'pivot'"),
        ({"grid": {"separate_feed": "maybe"}}, r"pbm.grid.separate_feed = 'maybe'"),
        ({"solver": {"max_steps": 0}}, r"pbm.solver.max_steps = 0"),
        ({"solver": {"method": "rk4"}}, r"pbm.solver.method = 'rk4'"),
    ],
)
def test_bad_settings_are_refused_where_they_enter(section, match):
    # the PBM's classes trust their settings: the typed `pbm:` section checks every value
    with pytest.raises(ConfigError, match=match):
        Pbm.from_dict(section, "pbm")


def test_initial_distribution_outside_the_grid():
    g = Grid(10, 2.0, min_diameter=1e-3)
    model = GranulationPBM(g, ConstantKernel(1e-3))
    with pytest.raises(GridRangeError, match=r"diameters \[0\.0005\] m .*outside the grid; allowed: 0\.001 \.\. "):
        model.initial_state(np.pi / 6 * np.array([0.5e-3, 2e-3]) ** 3, [10, 10])
    with pytest.raises(GridRangeError, match=r"diameters \[0\.5\] m"):
        model.initial_state(np.pi / 6 * np.array([0.5]) ** 3, [10])


def test_initial_distribution_outside_the_configured_grid(default_mapping):
    cfg = default_mapping
    cfg["pbm"] = {"grid": {"min_diameter": 2.5e-3}}
    with pytest.raises(GridRangeError, match=r"size distribution 'fine': diameters \[0\.002\] m"):
        run_batch(config_of(cfg).pbm_batch("fine"), None, 600)


def test_initial_porosity_below_minimum():
    g = Grid(10, 2.0, min_diameter=1e-3)
    model = GranulationPBM(g, ConstantKernel(1e-3), consolidation=Consolidation(0.1, 0.3))
    with pytest.raises(PBMInputError, match=r"initial porosity = 0.2 is below the minimum porosity 0.3"):
        model.initial_state(np.pi / 6 * np.array([2e-3]) ** 3, [10], porosity=0.2)


def test_overflow_beyond_the_last_bin_is_reported():
    g = Grid(8, 2.0, v0=1e-2)
    N = ver.discretise_exponential(g, 1.0, 0.1)
    model = GranulationPBM(g, ConstantKernel(1.0))
    s = State(0.0, N, np.zeros(8), np.zeros(8))
    with pytest.raises(
        GridOverflowError,
        match=r"beyond the last bin .* by t = [0-9.e+-]+ s aggregates carrying "
        r"[0-9.e+-]+ m3 of solid were refused, .*allowed: at most "
        r"max_overflow_fraction = 1e-06",
    ):
        model.run(0.0, 50.0, s)


def test_overflow_below_the_allowed_fraction_is_refused_and_conserves_solid():
    g = Grid(8, 2.0, v0=1e-2)
    N = ver.discretise_exponential(g, 1.0, 0.1)

    model = GranulationPBM(g, ConstantKernel(1.0), solver=Solver().replace(max_overflow_fraction=1.0))
    res = model.run(0.0, 2.0, State(0.0, N, np.zeros(8), np.zeros(8)))
    assert res.state.refused_volume > 0
    M1 = res.moments()[:, 1]
    assert abs(M1[-1] / M1[0] - 1) < 1e-12


class _Source:
    def __init__(self, fn):
        self.fn = fn

    def __call__(self, d, n, rpm):
        return self.fn(d.size)

    def __repr__(self):
        return "BadSource"


@pytest.mark.parametrize(
    "fn,match",
    [
        (lambda K: np.ones((K - 1, K)), r"BadSource returned shape \(9, 10\); expected \(10, 10\)"),
        (lambda K: np.ones(K), r"returned shape \(10,\); expected \(10, 10\)"),
        (lambda K: np.triu(np.ones((K, K))), r"non-symmetric matrix: c\[0,1\] = 1 but c\[1,0\] = 0"),
        (lambda K: -np.ones((K, K)), r"negative value c\[0,0\] = -1; allowed: values >= 0"),
        (lambda K: np.full((K, K), np.nan), r"non-finite value c\[0,0\] = nan"),
    ],
)
def test_inconsistent_frequency_source(fn, match):
    g = Grid(10, 2.0, min_diameter=1e-3)
    model = GranulationPBM(g, CollisionKernel(_Source(fn), 1.0))
    state = model.initial_state(np.pi / 6 * np.array([2e-3]) ** 3, [100])
    with pytest.raises(KernelShapeError, match=match):
        model.run(0.0, 1.0, state)


@pytest.mark.parametrize(
    "what,value,match",
    [
        ("number", -1.0, r"number of bin 3 .* is -1.0 at t = 2 s \(start of run\)"),
        ("liquid", np.nan, r"liquid of bin 3 .* is nan at t = 2 s"),
    ],
)
def test_negative_or_nan_state(what, value, match):
    g = Grid(10, 2.0, min_diameter=1e-3)
    model = GranulationPBM(g, ConstantKernel(1e-3))
    s = State(2.0, np.ones(10), np.zeros(10), np.zeros(10))
    getattr(s, what)[3] = value
    with pytest.raises(NegativePopulationError, match=match):
        model.run(2.0, 3.0, s)


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
def test_nan_during_the_run_names_time_and_bin():
    class NaNLater:
        def __init__(self):
            self.calls = 0

        def __call__(self, inp):
            self.calls += 1
            K = inp.volumes.size
            beta = np.full((K, K), 1e-3)
            if inp.t > 0.5:
                beta[4, 4] = np.inf  # an infinite rate in bin 4
            return beta

        def prepare(self, inp):
            pass

        def reset(self):
            pass

    g = Grid(10, 2.0, min_diameter=1e-3)

    model = GranulationPBM(g, NaNLater(), solver=Solver().replace(max_step=0.2, max_overflow_fraction=1.0))
    N = np.zeros(10)
    N[:6] = 1.0
    s = State(0.0, N, np.zeros(10), np.zeros(10))
    with pytest.raises(NegativePopulationError, match=r"of bin \d+ .* at t = 0\.[0-9]+ s"):
        model.run(0.0, 2.0, s)


def test_run_state_time_mismatch():
    g = Grid(10, 2.0, min_diameter=1e-3)
    model = GranulationPBM(g, ConstantKernel(1e-3))
    s = State(1.0, np.ones(10), np.zeros(10), np.zeros(10))
    with pytest.raises(PBMInputError, match=r"the state is at t = 1.0, not at t_start = 0.0"):
        model.run(0.0, 2.0, s)
    with pytest.raises(PBMInputError, match=r"t_end = 0.5 must be > t_start = 1.0"):
        model.run(1.0, 0.5, s)


def test_bad_config_section(default_mapping):
    cfg = default_mapping
    cfg["pbm"] = {"liquid_addition": {"rate": 0.0}}
    with pytest.raises(
        ConfigError,
        match=r"pbm\.liquid_addition\.rate = 0\.0: 0\.0 is less than or equal to "
        r"the minimum of 0",
    ):
        config_of(cfg)
    cfg["pbm"] = {"consolidation": {"rate": 1.0, "speed": 2}}
    with pytest.raises(ConfigError, match=r"'speed' was unexpected"):
        config_of(cfg)
    cfg["pbm"] = {}
    with pytest.raises(ConfigError, match=r"size distribution 'huge' is not defined; defined names: "):
        config_of(cfg).pbm_batch("huge")
