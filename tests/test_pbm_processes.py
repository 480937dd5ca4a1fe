"""Conservation with all processes on, liquid addition and consolidation against closed forms,
resumable runs, and the default granulation run from the config."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import config_of

from pbmdem.config import Solver
from pbmdem.pbm import (
    CollisionKernel,
    Consolidation,
    ConstantFrequency,
    ConstantKernel,
    GranulationPBM,
    Grid,
    LiquidAddition,
    Result,
    SuccessProbability,
    run_batch,
)
from pbmdem.pbm.setup import build_model, initial_state


@pytest.mark.parametrize("scheme", ["cell_average", "fixed_pivot"])
def test_default_run_conserves_solid_and_liquid(default_mapping, scheme):
    cfg = default_mapping
    cfg["pbm"]["aggregation"]["scheme"] = scheme
    config = config_of(cfg)
    res = run_batch(config.pbm_batch("fine"), None, 600)
    assert res.info["aggregation_scheme"] == scheme
    process = config.pbm.process
    t0, t1 = process.spray_start, process.spray_end
    S = res.moments()[:, 1]
    assert S[0] == pytest.approx(config.granulator.bed_solid_volume, rel=1e-12)
    rel = np.abs(S / S[0] - 1).max()
    print(f"default run ({scheme}): max relative solid-volume change {rel:.2e}")
    assert rel < 1e-10
    rate = config.pbm.liquid_addition.rate
    L = res.liquid.sum(axis=1)
    expected = rate * np.clip(np.minimum(res.times, t1) - t0, 0, None)
    print(
        f"default run: max liquid error relative to the sprayed total {np.abs(L - expected).max() / expected[-1]:.2e}"
    )
    np.testing.assert_allclose(L, expected, rtol=1e-10, atol=1e-12 * expected[-1])
    assert res.state.liquid_added == pytest.approx(rate * (t1 - t0), rel=1e-12)
    # all processes acted: granules grew, porosity fell toward eps_min, no overflow
    s = res.summary()
    growth = s["number_mean_diameter"].iloc[-1] / s["number_mean_diameter"].iloc[0]
    print(
        f"default run: number-mean diameter x{growth:.2f}, d50 {s['d50'].iloc[0] * 1e3:.2f} -> "
        f"{s['d50'].iloc[-1] * 1e3:.2f} mm, {res.info['steps']} steps"
    )
    assert 1.8 < growth < 3.5
    assert s["mean_porosity"].iloc[-1] == pytest.approx(0.2, abs=2e-3)
    # nothing reaches the last pivot (the fixed pivot's numerical diffusion carries ~1e-124 of the
    # solid there; the cell average nothing)
    assert res.state.refused_volume < 1e-15 * S[0]
    assert np.all(res.number >= 0) and np.all(res.liquid >= 0) and np.all(res.gas >= 0)


def _grid_and_state(model_kwargs, porosity=0.5, liquid_content=0.0):
    g = Grid(20, 2.0, min_diameter=1e-3)
    model = GranulationPBM(g, **model_kwargs)
    d = np.array([2e-3, 3e-3, 4e-3])
    state = model.initial_state(
        np.pi / 6 * d**3, [600.0, 300.0, 100.0], liquid_content=liquid_content, porosity=porosity
    )
    return g, model, state


def _no_aggregation():
    # aggregation switched off in practice: psi = 0 below an unreachable surface-liquid threshold
    return CollisionKernel(ConstantFrequency(1e-3), 1e-3, SuccessProbability("step", threshold=0.999))


@pytest.mark.parametrize("separate_feed", [False, True])
@pytest.mark.parametrize("rule", ["surface_area", "solid_volume"])
def test_liquid_addition_alone_is_linear(rule, separate_feed):
    rate, t0, t1 = 2e-9, 5.0, 25.0
    g, model, state = _grid_and_state(
        {"kernel": _no_aggregation(), "separate_feed": separate_feed, "liquid": LiquidAddition(rate, t0, t1, rule)}
    )
    times = np.linspace(0, 30, 31)
    res = model.run(0.0, 30.0, state, output_times=times)
    L = res.liquid.sum(axis=1)
    np.testing.assert_allclose(res.times, times)
    expected = rate * np.clip(np.minimum(times, t1) - t0, 0, None)
    np.testing.assert_allclose(L, expected, rtol=1e-12, atol=1e-15 * expected[-1])
    np.testing.assert_array_equal(res.number, np.broadcast_to(res.number[0], res.number.shape))
    # distribution rule: share per bin proportional to N d^2 (or N v), constant without aggregation
    if not separate_feed:
        w = state.number * (g.d**2 if rule == "surface_area" else g.x)
        np.testing.assert_allclose(res.liquid[-1], rate * (t1 - t0) * w / w.sum(), rtol=1e-10, atol=1e-25)
        return
    # feed granules at their own sizes (2, 3, 4 mm; 3 mm is between pivots): share per class
    # N d^2 (or N v) with the class's own diameter, put on the bins with the solid (lever rule)
    f = state.feed
    assert res.state.feed is not None
    d_f = np.cbrt(6 / np.pi * f.volumes)
    w = f.number * (d_f**2 if rule == "surface_area" else f.volumes)
    np.testing.assert_allclose(res.state.feed.liquid, rate * (t1 - t0) * w / w.sum(), rtol=1e-10, atol=1e-25)
    _, solid_share = g.lever_weights(f.volumes)
    np.testing.assert_allclose(res.liquid[-1], res.state.feed.liquid @ solid_share, rtol=1e-10, atol=1e-25)


def test_consolidation_alone_is_exponential():
    c, eps_min = 0.05, 0.2
    cons = Consolidation(c, eps_min)
    times = np.linspace(0, 60, 13)
    errs = []
    for rtol in (1e-3, 1e-5):
        g, model, state = _grid_and_state(
            {"kernel": _no_aggregation(), "consolidation": cons, "solver": Solver().replace(rtol=rtol)},
            porosity=0.5,
        )
        res = model.run(0.0, 60.0, state, output_times=times)
        S = state.number * g.x
        G_exact = np.array([cons.gas(t, S, state.gas) for t in times])
        errs.append(np.abs(res.gas - G_exact).max() / state.gas.max())
        print(f"consolidation alone, rtol {rtol:g}: max relative gas error {errs[-1]:.2e} ({res.info['steps']} steps)")
    # the error is the time-integration error and follows the requested tolerance
    assert errs[0] < 2e-4 and errs[1] < 2e-6
    eps = res.gas.sum(1) / (S.sum() + res.gas.sum(1))
    g_min = eps_min / (1 - eps_min)
    eps_exact = (g_min + (1 - g_min) * np.exp(-c * times)) / (1 + g_min + (1 - g_min) * np.exp(-c * times))
    np.testing.assert_allclose(eps, eps_exact, rtol=1e-4)


def test_consolidation_squeezes_liquid_to_the_surface():
    from pbmdem.pbm import surface_fraction

    cons = Consolidation(0.1, 0.2)
    g, model, state = _grid_and_state(
        {"kernel": _no_aggregation(), "consolidation": cons}, porosity=0.5, liquid_content=0.5
    )
    res = model.run(0.0, 60.0, state, output_times=[30.0])
    S = state.number * g.x
    phi = surface_fraction(S.sum(), res.liquid.sum(1), res.gas.sum(1))
    assert phi[0] == 0.0  # l/s = 0.5 < g/s = 1: all liquid in pores
    # at the end g/s -> 0.25: surface liquid (0.5 - 0.25) / (1 + 0.5)
    assert phi[-1] == pytest.approx(0.25 / 1.5, rel=1e-2)


def test_run_is_resumable_and_source_swappable(default_config):
    batch = default_config.pbm_batch("fine")
    whole = run_batch(batch, None, 600, t_end=400.0, times=[200.0, 400.0])
    model = build_model(batch.pbm, None, 600)
    state = initial_state(batch, model)
    parts = []
    for a, b in ((0.0, 100.0), (100.0, 200.0), (200.0, 300.0), (300.0, 400.0)):
        r = model.run(a, b, state)
        parts.append(r)
        state = r.state
    joined = Result.concat(parts)
    np.testing.assert_allclose(joined.times, [0, 100, 200, 300, 400])
    assert joined.info["steps"] == sum(p.info["steps"] for p in parts)
    assert joined.info["step_limits"]["event"] == sum(p.info["step_limits"]["event"] for p in parts)
    np.testing.assert_allclose(state.number, whole.state.number, rtol=2e-3, atol=1e-6 * state.number.sum())
    assert state.liquid.sum() == pytest.approx(whole.state.liquid.sum(), rel=1e-12)
    # swapping the source between intervals takes effect: a 10x larger c_ij aggregates faster
    fast = build_model(batch.pbm, None, 600)
    fast.kernel.set_source(ConstantFrequency(10 * batch.pbm.aggregation.constant_frequency))
    r_fast = fast.run(300.0, 400.0, parts[2].state)
    assert r_fast.state.number.sum() < 0.8 * parts[3].state.number.sum()


def test_result_tables_and_files(tmp_path, default_config):
    res = run_batch(default_config.pbm_batch("coarse"), None, 300)
    frames = res.to_frames()
    s, b = frames["summary"], frames["bins"]
    K = res.grid.bins
    assert len(b) == len(s) * K
    assert list(s["time"]) == sorted(s["time"])
    for col in (
        "d10",
        "d50",
        "d90",
        "number_mean_diameter",
        "mass_mean_diameter",
        "total_number",
        "mean_liquid_content",
        "mean_porosity",
    ):
        assert s[col].notna().all()
    assert (s["d10"] < s["d50"]).all() and (s["d50"] < s["d90"]).all()
    np.testing.assert_allclose(b.groupby("time")["mass_fraction"].sum(), 1.0, rtol=1e-12)
    paths = res.save(tmp_path / "out")
    for p in paths.values():
        assert p.is_file() and p.stat().st_size > 0
    import pandas as pd

    back = pd.read_csv(paths["summary"])
    np.testing.assert_allclose(back["d50"], s["d50"], rtol=1e-12)
    assert not list((tmp_path / "out").glob(".*"))  # no temporary files left behind


def test_mass_quantiles_interpolate_in_log_d():
    from pbmdem.pbm import mass_quantiles

    edges = np.array([1.0, 2.0, 4.0, 8.0])
    d50 = mass_quantiles(np.array([0.0, 1.0, 0.0]), edges, q=(0.5,))
    assert d50[0] == pytest.approx(np.sqrt(8.0))
    d = mass_quantiles(np.array([0.25, 0.5, 0.25]), edges, q=(0.1, 0.5, 0.9))
    np.testing.assert_allclose(d, [2**0.4, 2**1.5, 2**2.6])


def test_mass_quantiles_of_many_rows_are_those_of_each_row_to_the_bit():
    # the (T, K) form is the (K,) form row by row: the same numbers, NaN for a row without solid
    from pbmdem.pbm import mass_quantiles

    rng = np.random.default_rng(7)
    edges = np.cumprod(np.r_[1e-4, rng.uniform(1.05, 1.4, 30)])
    mass = rng.random((40, 30)) ** 8 * 1e-9
    mass[rng.random(mass.shape) < 0.5] = 0.0
    mass[3] = 0.0
    many = mass_quantiles(mass, edges)
    rows = np.array([mass_quantiles(row, edges) for row in mass])
    assert np.isnan(many[3]).all() and np.isfinite(np.delete(many, 3, axis=0)).all()
    np.testing.assert_array_equal(many, rows)


def test_constant_frequency_equals_constant_kernel():
    g = Grid(25, 2.0, v0=1e-3)
    import pbm_verification as ver

    from pbmdem.pbm import State

    N = ver.discretise_exponential(g, 1.0, 1.0)
    s = State(0.0, N, np.zeros(g.bins), np.zeros(g.bins))
    a = GranulationPBM(g, ConstantKernel(0.5)).run(0.0, 4.0, s)
    b = GranulationPBM(g, CollisionKernel(ConstantFrequency(0.25), 2.0, SuccessProbability("always"))).run(0.0, 4.0, s)
    np.testing.assert_allclose(a.state.number, b.state.number, rtol=1e-12, atol=1e-15)
