"""Breakage (pbm/breakage.py, the cell average in _compiled.breakage_totals): the fragment tables
against the integrals of b(v|u) over the cells, the compiled rates against the numpy oracle,
conservation of solid, liquid and gas to round-off in SI and scaled volumes, the number
produced exactly, pure breakage against Ziff & McGrady (1985) with the observed order, aggregation
with breakage against the Riccati number and the steady state, the selection rate's checks and
refresh, the settings and PBM-constant with breakage."""

from __future__ import annotations

import warnings

import numpy as np
import pbm_analytical as an
import pbm_oracle as oracle
import pbm_verification as ver
import pytest
from conftest import config_of
from scipy import integrate

from pbmdem.config import ConfigError, Solver
from pbmdem.pbm import (
    SCHEMES,
    CollisionKernel,
    ConstantFrequency,
    ConstantKernel,
    GranulationPBM,
    Grid,
    KernelInput,
    PBMInputError,
    State,
)
from pbmdem.pbm.breakage import FRAGMENTS, Breakage, ConstantSelection, PowerLawSelection
from pbmdem.pbm.setup import build_model

X_MAX = 60.0  # top of the verification grids (units of the initial mean volume): e^-60 beyond


def _tables(fragments, K=25, ratio=2.0 ** (1 / 3)):
    g = Grid(K, ratio, v0=1.0)
    return g, Breakage(ConstantSelection(1.0), fragments).fragment_tables(g.x, g.edges)


@pytest.mark.parametrize("ratio", [2.0, 2.0 ** (1 / 3)])
@pytest.mark.parametrize("fragments", FRAGMENTS)
def test_fragment_tables_are_the_integrals_of_b_over_the_cells(fragments, ratio):
    g, tab = _tables(fragments, ratio=ratio)
    x, K = g.x, g.bins
    number, first, share = tab
    # every parent's fragments carry its solid exactly (the column sums of the solid share are 1)
    np.testing.assert_allclose((x[:, None] * (number + first)).sum(axis=0), x, rtol=1e-14)
    np.testing.assert_allclose(share.sum(axis=0), 1.0, rtol=1e-14)
    assert np.all(np.triu(np.ones((K, K)), 1).T * np.abs(tab).max(axis=0) == 0)  # nothing above the parent
    lower = np.concatenate([[x[0]], g.edges[1:-1]])
    upper = np.append(g.edges[1:-1], np.inf)
    for k in (1, 3, 10, K - 1):
        u = x[k]
        for i in range(k + 1):
            a, b = lower[i], min(upper[i], u)
            if fragments == "binary":
                n = 2.0 if a <= u / 2 < b or (i == k and u / 2 == b) else 0.0
                s = n * u / 2
            else:
                n = integrate.quad(lambda v, u=u: 2.0 / u, a, b)[0] if b > a else 0.0
                s = integrate.quad(lambda v, u=u: 2.0 * v / u, a, b)[0] if b > a else 0.0
            if i == 0:  # fragments below x_0: granules of x_0 with their solid
                below = u if fragments == "binary" and u / 2 < x[0] else 0.0
                if fragments == "uniform":
                    below = integrate.quad(lambda v, u=u: 2.0 * v / u, 0.0, x[0])[0]
                n, s = n + below / x[0], s + below
            assert number[i, k] == pytest.approx(n, rel=1e-12, abs=1e-14)
            assert number[i, k] + first[i, k] == pytest.approx(s / x[i], rel=1e-12, abs=1e-14)


def test_granules_at_the_first_pivot_do_not_break():
    # their fragments would be smaller than x_0: counted as granules of x_0 with their solid, the
    # breakage of a first-pivot granule gives back one first-pivot granule
    for fragments in FRAGMENTS:
        _, tab = _tables(fragments)
        assert tab[0, 0, 0] == 1.0 and tab[1, 0, 0] == 0.0 and tab[2, 0, 0] == 1.0


@pytest.mark.parametrize("scheme", sorted(SCHEMES))
@pytest.mark.parametrize("fragments", FRAGMENTS)
def test_compiled_breakage_rates_and_stages_equal_the_oracle(scheme, fragments):
    from pbmdem.pbm import _compiled, _compiled_steps

    rng = np.random.default_rng(3)
    g = Grid(30, 2.0 ** (1 / 3), v0=1.0)
    op = SCHEMES[scheme](g.x, g.edges[1:-1], extra=(1.5, 4.0))
    M, K, xc = op.M, op.K, op.class_volumes
    beta = rng.random((M, M)) * 1e-3
    beta = beta + beta.T
    N = rng.uniform(1.0, 100.0, M) * (np.arange(M) < M - 6)
    N[-2:] = rng.uniform(1.0, 100.0, 2)  # the feed classes
    u = np.concatenate([N, N * xc * rng.uniform(0.0, 0.08, M), N * xc * rng.uniform(0.0, 0.06, M)])
    brk = Breakage(ConstantSelection(1.0), fragments).compiled_arrays(g.x, g.edges)
    brk[0][:] = rng.uniform(0.0, 0.5, K)
    vectors = np.ascontiguousarray(np.stack([xc, np.ones(M), np.zeros(M)]))
    params = np.zeros(6)
    d, tally = np.empty((3, M)), np.empty(3)
    _compiled.class_rates(u, beta, _compiled.ALWAYS, vectors, params, *op.compiled_arrays(), *brk,
                          np.zeros((2, M)), d, tally)  # fmt: skip

    def oracle_rates(v):
        return oracle.class_rates(op, v, beta, brk=(brk[0], brk[1], brk[3][:2]))  # rows 2-3: fragment rows

    d_ref, tally_ref = oracle_rates(u)
    np.testing.assert_allclose(d.reshape(-1), d_ref, rtol=1e-12, atol=1e-14 * np.abs(d_ref).max())
    assert tally[0] == tally_ref[0]
    # the fragments merged into the first pivot: those of the pivots whose halves (binary) or
    # whose lower tail (uniform) lie below x_0, at the oracle's rates
    assert tally[1] > 0 and tally[2] > 0
    np.testing.assert_allclose(tally[1:], tally_ref[1:], rtol=1e-13)
    # breakage changes neither the solid (x_0 units) nor the liquid and gas totals
    dn = d[0] - oracle.aggregation_totals(op, beta, u.reshape(3, M))[0][0]
    assert abs(dn @ xc) < 1e-13 * np.sum(brk[0] * N[:K] * xc[:K])
    dt = 0.3 * _compiled_steps.depletion_time(u, d.reshape(-1))
    k, r = np.zeros((3, 3 * M)), np.zeros((4, 3))
    k[0], r[0] = d.reshape(-1), tally
    u_new, u_low, stage = np.empty(3 * M), np.empty(3 * M), np.empty(3 * M)
    _compiled_steps.ssp_step(u, k, r, dt, 3, beta, _compiled.ALWAYS, vectors, params, *op.compiled_arrays(), *brk,
                       np.zeros((2, M)), u_new, u_low, stage)  # fmt: skip
    ref_new, ref_low, ref_tally = oracle.ssp_step(oracle_rates, u, dt, 3)
    np.testing.assert_allclose(u_new, ref_new, rtol=1e-12, atol=1e-14 * np.abs(u).max())
    np.testing.assert_allclose(u_low, ref_low, rtol=1e-12, atol=1e-14 * np.abs(u).max())
    np.testing.assert_allclose(r[3], ref_tally, rtol=1e-12)


def _si_model(fragments, rate=0.05, separate_feed=True, kernel=None):
    g = Grid(30, 2.0 ** (1 / 3), min_diameter=2e-3)  # SI: pivots of 4.2e-9 .. 4.3e-6 m3
    kernel = kernel if kernel is not None else ConstantKernel(1e-5)
    brk = Breakage(PowerLawSelection(rate / g.x[10], 1.0), fragments)
    model = GranulationPBM(g, kernel, breakage=brk, separate_feed=separate_feed)
    d = np.array([2e-3, 3e-3, 5e-3, 8e-3])
    state = model.initial_state(np.pi / 6 * d**3, [400.0, 200.0, 80.0, 20.0], liquid_content=0.2, porosity=0.4)
    return g, model, state


@pytest.mark.parametrize("separate_feed", [True, False])
@pytest.mark.parametrize("fragments", FRAGMENTS)
def test_breakage_conserves_solid_liquid_and_gas_in_si_volumes(fragments, separate_feed):
    g, model, state = _si_model(fragments, separate_feed=separate_feed)
    res = model.run(0.0, 60.0, state, output_times=np.arange(0.0, 61.0, 10.0))
    assert res.info["breakage"] == repr(model.breakage)
    solid = res.number @ g.x
    for name, total in (("solid", solid), ("liquid", res.liquid.sum(axis=1)), ("gas", res.gas.sum(axis=1))):
        rel = np.abs(total / total[0] - 1).max()
        print(f"{fragments}, separate feed {separate_feed}: {name} changed by at most {rel:.1e}")
        assert rel < 1e-13, name
    # the aggregates broke: more granules than aggregation alone would leave
    plain = GranulationPBM(g, ConstantKernel(1e-5), separate_feed=separate_feed).run(0.0, 60.0, state)
    assert res.state.number.sum() > 1.2 * plain.state.number.sum()
    # fragments carry their parents' liquid and gas per solid: liquid/solid and gas/solid stay uniform
    np.testing.assert_allclose(res.state.liquid, 0.2 * res.state.number * g.x, rtol=1e-9, atol=1e-25)
    np.testing.assert_allclose(res.state.gas, 2.0 / 3.0 * res.state.number * g.x, rtol=1e-9, atol=1e-25)


def test_feed_granules_do_not_break():
    # without aggregation a population of feed granules (kept apart) stays as it is; the same
    # granules in the bins (no separate feed) break
    for separate_feed in (True, False):
        g, model, state = _si_model("binary", separate_feed=separate_feed, kernel=ver.NoAggregation())
        res = model.run(0.0, 30.0, state)
        if separate_feed:
            np.testing.assert_array_equal(res.state.feed.number, state.feed.number)
            np.testing.assert_allclose(res.state.number, state.number, rtol=1e-15)
        else:
            assert res.state.number.sum() > 1.2 * state.number.sum()


def test_numerics_do_not_depend_on_the_unit_of_volume():
    runs = []
    for unit in (1.0, 1e-9):  # the same problem in m3 and in mm3-scaled m3
        g = Grid(40, 2.0 ** (1 / 3), v0=4e-9 / unit)
        brk = Breakage(PowerLawSelection(0.02 / (g.x[8]), 1.0), "uniform")
        model = GranulationPBM(g, ConstantKernel(1e-4), breakage=brk)
        N = np.exp(-np.arange(40) / 3.0) * 100 * (np.arange(40) < 20)
        S = N * g.x
        runs.append(model.run(0.0, 30.0, State(0.0, N, 0.3 * S, 0.1 * S)))
    np.testing.assert_allclose(runs[0].state.number, runs[1].state.number, rtol=1e-10)
    assert runs[0].info["steps"] == runs[1].info["steps"]


@pytest.mark.parametrize("fragments", FRAGMENTS)
def test_the_number_produced_is_exact(fragments):
    # linear selection S = a v, any binary fragments: dM0/dt = a M1 exactly, for the discrete
    # moments too (two fragments per breakage, the cell average keeps their number); only
    # fragments below x_0 (here 1e-9 of the mean volume) are merged
    g = ver.geometric_grid(2, x0=1e-9, x_max=X_MAX)
    res = ver.simulate_breakage(Breakage(PowerLawSelection(0.5, 1.0), fragments), 4.0, g,
                                output_times=[1.0, 2.0, 3.0])  # fmt: skip
    M = res.moments()
    t = np.asarray(res.times)
    expected = M[0, 0] + 0.5 * M[0, 1] * t
    print(f"{fragments}: number error {np.abs(M[:, 0] / expected - 1).max():.1e}")
    np.testing.assert_allclose(M[:, 0], expected, rtol=1e-8)
    np.testing.assert_allclose(M[:, 1], M[0, 1], rtol=1e-14)


@pytest.mark.parametrize("exponent, t", [(1, 9.0), (2, 10.0)])
def test_analytical_breakage_solves_the_equation(exponent, t):
    # Ziff & McGrady's densities satisfy dn/dt = -S n + int_v^inf S(u) 2/u n(u) du and integrate
    # to the closed-form moments
    a = 0.7

    def n(v, tt=t):
        return an.breakage_number_density(v, tt, a, exponent, 1.0, 1.0)

    for v in (0.05, 0.4, 1.3):
        h = 1e-5 * t
        dndt = (n(v, t + h) - n(v, t - h)) / (2 * h)
        birth = integrate.quad(lambda u: a * u**exponent * 2.0 / u * n(u), v, np.inf, epsabs=0, epsrel=1e-12)[0]
        assert dndt == pytest.approx(-a * v**exponent * n(v) + birth, rel=1e-7)
    for k, ref in enumerate(an.breakage_moments(t, a, exponent, 1.0, 1.0)):
        val = integrate.quad(lambda v, k=k: v**k * n(v), 0, np.inf, epsabs=0, epsrel=1e-12, limit=200)[0]
        assert val == pytest.approx(ref, rel=1e-9)


#: the pure-breakage cases: selection exponent, t_end (M0 grows 10x (linear), 3.7x (quadratic))
CASES = [(1, 9.0), (2, 10.0)]


def _ziff_mcgrady(exponent, t, q):
    g = ver.geometric_grid(q, x0=1e-6, x_max=X_MAX)
    res = ver.simulate_breakage(Breakage(PowerLawSelection(1.0, exponent), "uniform"), t, g)
    err = res.moments()[-1] / np.array(an.breakage_moments(t, 1.0, exponent, 1.0, 1.0)) - 1.0
    psd = ver.density_errors(lambda v: an.breakage_number_density(v, t, 1.0, exponent, 1.0, 1.0), g, res.state.number)
    return err, psd


@pytest.mark.parametrize("exponent, t", CASES)
def test_pure_breakage_against_ziff_and_mcgrady(exponent, t):
    # tolerances: the errors on the ratio-2^(1/2) grid (docs/pbm.md, "Breakage") with ~25 % margin,
    # and second order in the PSD
    err2, psd2 = _ziff_mcgrady(exponent, t, 2)
    err4, psd4 = _ziff_mcgrady(exponent, t, 4)
    print(f"S = v^{exponent}: moments {err2} / {err4}, PSD L1 {psd2[0]:.2e} / {psd4[0]:.2e}")
    assert abs(err2[1]) < 1e-12 and abs(err4[1]) < 1e-12  # solid
    if exponent == 1:
        assert abs(err2[0]) < 6e-6  # number exact up to the fragments below x_0 = 1e-6
        assert abs(err2[2]) < 1e-3
    else:
        assert abs(err2[0]) < 1.4e-3 and abs(err4[0]) < 6e-4
        assert abs(err2[2]) < 1.4e-3
    assert psd2[0] < 2.3e-2 and psd2[1] < 2e-2
    assert np.log2(psd2[0] / psd4[0]) > 1.8  # observed order of the PSD


def test_aggregation_with_breakage_against_the_riccati_number_and_the_steady_state():
    # constant aggregation beta = 1 and uniform-daughter breakage S = 2 v from the exponential
    # (N0 = 1, m = 1): M0 -> 2, n -> 4 exp(-2 v)
    beta, s = 1.0, 2.0
    times = [0.5, 1.0, 2.0, 4.0]
    g = ver.geometric_grid(2, x0=1e-8, x_max=X_MAX)
    res = ver.simulate_breakage(Breakage(PowerLawSelection(s, 1.0), "uniform"), 12.0, g,
                                kernel=ConstantKernel(beta), output_times=times)  # fmt: skip
    M0 = res.moments()[:, 0]
    exact = an.aggregation_breakage_number(np.asarray(res.times), beta, s, 1.0, 1.0)
    print(f"aggregation + breakage: number error {np.abs(M0 / exact - 1).max():.1e}")
    np.testing.assert_allclose(M0, exact, rtol=1e-7)
    l1, q = ver.density_errors(lambda v: an.aggregation_breakage_steady_density(v, beta, s, 1.0), g, res.state.number)
    print(f"aggregation + breakage: steady PSD L1 {l1:.2e}, cumulative mass {q:.2e}")
    assert l1 < 1.7e-2 and q < 1.3e-2


def test_a_zero_selection_rate_changes_nothing():
    g, model, state = _si_model("binary", rate=0.0)
    plain = GranulationPBM(g, ConstantKernel(1e-5))
    a, b = model.run(0.0, 30.0, state), plain.run(0.0, 30.0, state)
    np.testing.assert_array_equal(a.number, b.number)
    np.testing.assert_array_equal(a.liquid, b.liquid)
    assert a.info["steps"] == b.info["steps"]


def test_fast_breakage_stays_positive_by_the_step_control():
    # a selection rate 1e4 x the aggregation's time scale: the depletion time of the breaking
    # classes limits the steps, every state stays >= 0
    g, model, state = _si_model("uniform", rate=50.0)
    res = model.run(0.0, 2.0, state)
    assert np.all(res.number >= 0) and np.all(res.liquid >= 0) and np.all(res.gas >= 0)
    assert res.info["step_limits"]["positivity"] + res.info["step_limits"]["error"] > 10
    assert res.state.number @ g.x == pytest.approx(state.number @ g.x, rel=1e-13)


class _Counting:
    def __init__(self, value):
        self.value, self.calls, self.prepared = value, 0, 0

    def prepare(self, inp):
        self.prepared += 1

    def __call__(self, inp):
        self.calls += 1
        return self.value(inp) if callable(self.value) else np.full(inp.pivots, self.value)


def test_the_selection_is_refreshed_at_the_kernels_update_interval():
    g = Grid(15, 2.0, min_diameter=2e-3)
    sel = _Counting(0.01)
    kernel = CollisionKernel(ConstantFrequency(1e-3), 1e-3, update_interval=1.0)
    model = GranulationPBM(g, kernel, breakage=Breakage(sel, "binary"))
    state = model.initial_state(np.pi / 6 * np.array([2e-3, 4e-3]) ** 3, [100.0, 50.0])
    times = np.arange(0.0, 5.01, 0.25)
    res = model.run(0.0, 5.0, state, output_times=times)
    assert sel.prepared == res.info["steps"] >= 20
    assert sel.calls == 5  # at t = 0, 1, 2, 3, 4 s
    model.run(0.0, 5.0, state, output_times=times)  # a new run evaluates at its first step again
    assert sel.calls == 10


@pytest.mark.parametrize(
    "value, match",
    [
        (lambda inp: np.ones(inp.pivots + 1), r"returned shape \(16,\); expected \(15,\)"),
        (lambda inp: -np.ones(inp.pivots), r"gave -1.0 1/s for the pivot of diameter 0.002 m .*allowed: finite"),
        (lambda inp: np.full(inp.pivots, np.nan), r"gave nan 1/s"),
    ],
)
def test_bad_selection_rates_are_named(value, match):
    g = Grid(15, 2.0, min_diameter=2e-3)
    model = GranulationPBM(g, ConstantKernel(1e-3), breakage=Breakage(_Counting(value)))
    state = model.initial_state(np.pi / 6 * np.array([2e-3, 4e-3]) ** 3, [100.0, 50.0])
    with pytest.raises(PBMInputError, match=match):
        model.run(0.0, 1.0, state)


def test_power_law_selection():
    # bad breakage settings are refused where they enter: test_bad_breakage_settings_name_the_key
    inp = KernelInput(0.0, np.array([1.0, 2.0]), np.ones(2), np.ones(2), np.zeros(2), 0.0)
    np.testing.assert_array_equal(PowerLawSelection(3.0, 2.0)(inp), [3.0, 12.0])


# ----------------------------------------------------------------------------- settings and PBM-constant
def _with_breakage(mapping, **breakage):
    mapping["pbm"]["breakage"].update(enabled=True, **breakage)
    return config_of(mapping)


def test_breakage_is_on_by_default_and_aggregation_only_one_setting_away(default_config, default_mapping):
    assert default_config.pbm.breakage.enabled is True  # config/config.yaml says why
    assert build_model(default_config.pbm).breakage is not None  # PBM-constant: the constant rate
    off = config_of({**default_mapping, "pbm": {**default_mapping["pbm"], "breakage": {"enabled": False}}})
    assert build_model(off.pbm).breakage is None  # aggregation only: the model before
    cfg = _with_breakage(default_mapping, fragments="uniform")
    model = build_model(cfg.pbm)
    assert (
        repr(model.breakage)
        == f"Breakage(ConstantSelection(rate={cfg.pbm.breakage.constant_rate:g}), fragments='uniform')"
    )
    own = PowerLawSelection(1.0, 1.0)
    assert build_model(cfg.pbm, ConstantFrequency(0.1), selection=own).breakage.selection is own
    with pytest.raises(PBMInputError, match=r"pbm.breakage.enabled = true with the collision-frequency source"):
        build_model(cfg.pbm, ConstantFrequency(0.1))


@pytest.mark.parametrize(
    "key, value, match",
    [
        ("fragments", "ternary", r"pbm.breakage.fragments.*'ternary'.*binary.*uniform"),
        ("walls", ["lid"], r"pbm.breakage.walls\[0\].*'lid'"),
        ("constant_rate", -1.0, r"pbm.breakage.constant_rate = -1.0"),
        ("yield_strength", 0.0, r"pbm.breakage.yield_strength = 0.0"),
    ],
)
def test_bad_breakage_settings_name_the_key(default_mapping, key, value, match):
    default_mapping["pbm"]["breakage"][key] = value
    with pytest.raises(ConfigError, match=match):
        config_of(default_mapping)


def test_pbm_constant_breaks_at_the_constant_rate(tiny_config, tiny_mapping, tmp_path, monkeypatch):
    # PBM-constant with breakage: the selection pbm.breakage.constant_rate for every aggregate; the
    # calibration of its collision frequency (the surrogate's, tested with the validation) is fixed here
    from pbmdem.coupling import methods

    monkeypatch.setattr(methods, "calibrated_frequency", lambda loop, path, rpm: (0.12, []))
    plain = methods.pbm_constant(tiny_config.coupled_loop(), "unused", 600.0, tmp_path / "plain").result
    tiny_mapping["pbm"]["breakage"].update(enabled=True, constant_rate=0.05)
    loop = config_of(tiny_mapping).coupled_loop()
    res = methods.pbm_constant(loop, "unused", 600.0, tmp_path / "broken").result
    assert "ConstantSelection(rate=0.05)" in res.info["breakage"] and plain.info["breakage"] == "None"
    solid = res.moments()[:, 1]
    assert np.abs(solid / solid[0] - 1).max() < 1e-13
    assert res.state.number.sum() > plain.state.number.sum()
    assert res.summary()["d50"].iloc[-1] < plain.summary()["d50"].iloc[-1]


def test_one_breakage_serves_models_on_different_grids():
    # the selection array belongs to each model: a second model built with the same Breakage does
    # not take it from the first
    brk = Breakage(ConstantSelection(0.05), "binary")
    runs = []
    for bins in (30, 35):
        g = Grid(bins, 2.0 ** (1 / 3), min_diameter=2e-3)
        model = GranulationPBM(g, ver.NoAggregation(), breakage=brk, separate_feed=False)
        runs.append((g, model, model.initial_state(np.pi / 6 * np.array([5e-3]) ** 3, [100.0])))
    for _, model, state in runs:
        res = model.run(0.0, 10.0, state)
        assert res.state.number.sum() > 1.2 * state.number.sum()


class _FromPivot:
    """Selection ``rate`` (1/s) for the pivots of solid volume >= ``v_min`` (m3), 0 below."""

    def __init__(self, rate, v_min):
        self.rate, self.v_min = rate, v_min

    def prepare(self, inp):
        pass

    def __call__(self, inp):
        v = np.asarray(inp.volumes[: inp.pivots], float)
        return np.where(v >= self.v_min, self.rate, 0.0)


def test_fragments_below_the_grid_floor_are_counted_against_a_grid_extended_downwards():
    """Strong binary breakage, SI volumes (first pivot 2 mm): the halves of the 2-2.5 mm granules
    fall below the first pivot and are merged into it. The tally of the run (info, summary, state)
    equals what an independent reference holds below the floor: the same problem on a grid that
    reaches three bins (one halving) lower, where those halves have bins of their own and nothing
    is merged. Granules of the first pivot do not break in either run (their halves would break
    again on the extended grid only), so that everything above the floor evolves alike."""
    ratio, d0 = 2.0 ** (1 / 3), 2e-3
    clipped = Grid(30, ratio, min_diameter=d0)
    x0 = clipped.x[0]
    extended = Grid(33, ratio, v0=0.5 * x0)  # pivots x_0 / 2, x_0 / 2^(2/3), x_0 / 2^(1/3), x_0, ...
    rate, t_end = 0.05, 120.0  # 1/s per granule: six breakages per granule over the run
    N = np.array([0, 40, 30, 60, 50, 40, 30, 20, 10, 5], float)  # 2 mm and up: none at the first pivot
    runs, solver = {}, Solver().replace(max_step=0.5)
    for name, g, pad in (("clipped", clipped, 0), ("extended", extended, 3)):
        selection = _FromPivot(rate, 1.5 * x0)  # every pivot above the 2 mm one
        brk = Breakage(selection, "binary")
        # the same steps in both runs (max_step limits every one): their results differ only by round-off
        model = GranulationPBM(g, ver.NoAggregation(), solver=solver, breakage=brk, separate_feed=False)
        n = np.zeros(g.bins)
        n[pad : pad + N.size] = N
        S = n * g.x
        runs[name] = model.run(0.0, t_end, State(0.0, n, 0.2 * S, 0.5 * S), output_times=[30.0, 60.0, 90.0])
    clip, ext = runs["clipped"], runs["extended"]
    floor = clip.info["grid_floor"]
    assert ext.info["grid_floor"]["merged_number"] == 0.0 and ext.info["grid_floor"]["merged_volume"] == 0.0
    below_n, below_v = ext.number[:, :3].sum(axis=1), ext.number[:, :3] @ extended.x[:3]
    assert below_n[-1] > 0.05 * ext.state.number.sum()  # strong: well above the 1 % flag
    print(f"merged {floor['merged_number']:.6g} fragments ({below_n[-1]:.6g} below the extended floor)")
    # the tally at every recorded time: the number and solid the extended grid holds below x_0
    s = clip.summary()
    np.testing.assert_allclose(s.merged_number, below_n, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(s.merged_solid_volume, below_v, rtol=1e-9, atol=1e-12 * x0)
    assert floor["merged_number"] == s.merged_number.iloc[-1] == clip.state.merged_number
    assert floor["merged_volume"] == pytest.approx(below_v[-1], rel=1e-9)
    # number accounting: the clipped run keeps their solid as merged_volume / x_0 granules of x_0,
    # and misses merged_number - merged_volume / x_0 granules
    np.testing.assert_allclose(clip.number[:, 0], ext.number[:, 3] + below_v / x0, rtol=1e-9)
    np.testing.assert_allclose(clip.number[:, 1:], ext.number[:, 4:], rtol=1e-9, atol=1e-12)
    lost = ext.state.number.sum() - clip.state.number.sum()
    assert floor["lost_number"] == pytest.approx(lost, rel=1e-9)
    assert floor["lost_number"] == pytest.approx(floor["merged_number"] - floor["merged_volume"] / x0, rel=1e-12)
    assert floor["merged_fraction"] == pytest.approx(floor["merged_number"] / clip.state.number.sum(), rel=1e-12)
    assert floor["flagged"] and not ext.info["grid_floor"]["flagged"]
    assert floor["floor_diameter"] == d0


def test_the_grid_floor_of_a_resumed_run_is_that_of_the_whole_batch():
    # the tally is cumulative in the State: a run resumed halfway ends with the whole batch's
    g, model, state = _si_model("uniform", rate=0.5, separate_feed=False)
    whole = model.run(0.0, 40.0, state)
    half = model.run(0.0, 20.0, state)
    rest = model.run(20.0, 40.0, half.state)
    assert 0.0 < half.state.merged_number < whole.state.merged_number
    joined = type(whole).concat([half, rest])
    for key in ("merged_number", "merged_volume"):
        assert joined.info["grid_floor"][key] == pytest.approx(whole.info["grid_floor"][key], rel=1e-6)
    # without breakage nothing is merged
    plain = GranulationPBM(g, ConstantKernel(1e-5), separate_feed=False).run(0.0, 40.0, state)
    assert plain.info["grid_floor"]["merged_number"] == 0.0 and not plain.info["grid_floor"]["flagged"]


@pytest.mark.parametrize("exponent", [-1.0, -0.01, float("nan"), float("inf"), "steep"])
def test_a_power_law_selection_refuses_exponents_outside_its_range(exponent):
    # a negative exponent breaks the smallest granules fastest: the shattering transition (mass lost
    # to zero size), which no grid holds; refused when the selection is made, not at run time
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(PBMInputError, match=r"breakage selection exponent = .*allowed: a finite number >= 0"):
            PowerLawSelection(1.0, exponent)


def test_a_power_law_selection_that_overflows_on_the_grid_is_refused_without_a_warning():
    g = ver.geometric_grid(2, x0=1.0, x_max=1e6)
    selection = PowerLawSelection(1.0, 60.0)  # (1e6)^60 is beyond the largest float
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(PBMInputError, match=r"at pivot \d+ \(volume .*\) = inf; allowed: finite rates"):
            ver.simulate_breakage(Breakage(selection, "uniform"), 1.0, g)
