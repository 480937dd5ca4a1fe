"""Velocity-dependent aggregation success (Stokes criterion) and velocity-resolved frequencies.

All quantities in SI units (m, kg, s, Pa s) unless a test converts them on purpose.
"""

import math

import dem_tables
import numpy as np
import pandas as pd
import pytest

from pbmdem.config import ConfigError, Pbm
from pbmdem.impact import N_VELOCITY_BINS, VELOCITY_EDGES, EncounterRates, representative_velocities, velocity_bin
from pbmdem.pbm import CollisionKernel, GranulationPBM, Grid, KernelInput, SuccessProbability, TableFrequency
from pbmdem.pbm.errors import KernelShapeError, PBMInputError
from pbmdem.pbm.setup import build_success, run_batch
from pbmdem.pbm.success import (
    StokesCriterion,
    critical_stokes_number,
    layer_thickness,
    viscous_stokes_number,
)

V = representative_velocities()
STOKES = {"aggregation": {"success": {"velocity_model": "stokes"}}}


def held_below(crit: StokesCriterion, d, phi, velocities) -> np.ndarray:
    """(K, K, V) 1 where an impact at velocities[b] (m/s) of the pair (i, j) is held by the
    criterion ``crit`` (slower than its critical speed w*_ij), else 0."""
    w = np.asarray(velocities, float)
    return (w[None, None, :] < crit.critical_velocity(d, phi)[:, :, None]).astype(float)


def resolved(psi: SuccessProbability, diameters, phi, velocities) -> np.ndarray:
    """(K, K, V) psi_ij(v_b): the surface-liquid condition of ``psi`` times its velocity criterion
    (:func:`held_below`) at the speeds ``velocities`` (m/s); what CollisionKernel sums with the
    velocity fractions, in one readable product."""
    liquid = psi(phi)
    if psi.velocity is None:
        return np.repeat(liquid[:, :, None], np.size(velocities), axis=2)
    return liquid[:, :, None] * held_below(psi.velocity, diameters, phi, velocities)


def batch_with(config, section: dict, distribution: str = "fine"):
    """The default batch with its pbm settings replaced by a (partial) pbm section (schema defaults)."""
    pbm = Pbm.from_dict(section, "pbm")
    pbm = pbm.replace(grid=pbm.grid.replace(min_diameter=config.pbm.grid.min_diameter))
    return config.pbm_batch(distribution).replace(pbm=pbm)


# ----------------------------------------------------------------------------- Stokes numbers
def test_stokes_number_of_two_equal_granules_by_hand():
    # two 2 mm granules of 1000 kg/m3 meeting at 0.1 m/s through a 0.1 Pa s binder:
    # m* = m/2, a* = a/2 = 0.5 mm; St = m* w / (6 pi mu a*^2) = 2 rho d w / (9 mu) = 0.4 / 0.9
    st = viscous_stokes_number(2e-3, 2e-3, 0.1, 0.1, 1000.0)
    assert st == pytest.approx(4.0 / 9.0, rel=1e-14)
    # Ennis et al. (1991): 8 rho u0 a / (9 mu) with u0 = half the relative speed, a = 1 mm
    assert st == pytest.approx(8 * 1000.0 * 0.05 * 1e-3 / (9 * 0.1), rel=1e-14)


def test_stokes_number_of_an_unequal_pair_by_hand():
    # 1 mm and 3 mm, 1500 kg/m3, 0.5 m/s, 0.02 Pa s. Reduced mass
    # m* = rho pi/6 d_i^3 d_j^3 / (d_i^3 + d_j^3) = rho pi/6 (27/28) 1e-9 kg, reduced radius
    # a* = 0.5e-3 * 1.5e-3 / 2e-3 = 3.75e-4 m; St = m* w / (6 pi mu a*^2)
    #    = 1500 (27/28) 1e-9 * 0.5 / (36 * 0.02 * 3.75e-4^2) = 50/7
    assert viscous_stokes_number(1e-3, 3e-3, 0.5, 0.02, 1500.0) == pytest.approx(50.0 / 7.0, rel=1e-13)
    # symmetric in the pair, linear in speed, inverse in viscosity
    assert viscous_stokes_number(3e-3, 1e-3, 1.0, 0.04, 1500.0) == pytest.approx(50.0 / 7.0, rel=1e-13)


def test_stokes_number_does_not_depend_on_the_unit_system():
    si = viscous_stokes_number(2.5e-3, 4e-3, 0.3, 0.05, 1200.0)
    # the same impact in mm, g, s: d x 1e3, w x 1e3, rho (g/mm3) x 1e-6, mu in g/(mm s) = Pa s
    mm = viscous_stokes_number(2.5, 4.0, 300.0, 0.05, 1200.0e-6)
    assert mm == pytest.approx(si, rel=1e-13)
    crit_si = StokesCriterion(0.05, 0.4, 5e-6, 1200.0)
    crit_mm = StokesCriterion(0.05, 0.4, 5e-3, 1200.0e-6)
    d, phi = np.array([2.5e-3, 4e-3]), np.array([0.03, 0.05])
    np.testing.assert_allclose(
        crit_mm.critical_velocity(d * 1e3, phi), 1e3 * crit_si.critical_velocity(d, phi), rtol=1e-13
    )


def test_layer_thickness_is_the_shell_holding_the_surface_liquid():
    d, phi = 3e-3, 0.02
    h = layer_thickness(d, phi)
    assert h == pytest.approx(1.5e-3 * (1.0 - 0.98 ** (1.0 / 3.0)), rel=1e-12)
    # the shell volume is phi of the granule volume
    assert (d**3 - (d - 2 * h) ** 3) / d**3 == pytest.approx(phi, rel=1e-12)
    assert h == pytest.approx(phi * d / 6, rel=0.01)  # thin layer: about phi d / 6 (10 um here)
    assert layer_thickness(d, 0.0) == 0.0


def test_critical_stokes_number_by_hand():
    # h = 2 h_a, e = 0.4: St* = (1 + 2.5) ln 2
    assert critical_stokes_number(10e-6, 5e-6, 0.4) == pytest.approx(3.5 * math.log(2.0), rel=1e-14)
    assert critical_stokes_number(5e-6, 5e-6, 0.4) == 0.0  # layer no thicker than the asperities
    assert critical_stokes_number(2e-6, 5e-6, 1.0) == pytest.approx(2 * math.log(0.4))
    assert critical_stokes_number(0.0, 5e-6, 0.4) == -np.inf


def test_critical_velocity_and_success_on_each_side_by_hand():
    crit = StokesCriterion(viscosity=0.1, restitution=0.4, asperity_height=5e-6, density=1000.0)
    d = np.array([2e-3, 2e-3])
    # layer h = 2 h_a = 10 um: phi with d/2 (1 - (1 - phi)^(1/3)) = 1e-5
    phi_val = 1.0 - (1.0 - 1e-5 / 1e-3) ** 3
    phi = np.array([phi_val, phi_val])
    assert layer_thickness(2e-3, phi_val) == pytest.approx(1e-5, rel=1e-12)
    st_star = 3.5 * math.log(2.0)
    np.testing.assert_allclose(crit.critical_stokes(d, phi), st_star, rtol=1e-12)
    # St = 2 rho d w / (9 mu) = (40/9) w  =>  w* = St* 9 / 40 = 0.5458 m/s
    w_star = st_star * 9.0 / 40.0
    np.testing.assert_allclose(crit.critical_velocity(d, phi), w_star, rtol=1e-12)
    held = held_below(crit, d, phi, [0.5 * w_star, 0.99 * w_star, 1.01 * w_star, 2 * w_star])
    np.testing.assert_array_equal(held[0, 1], [1.0, 1.0, 0.0, 0.0])
    # on the project's bins: held in every bin whose representative speed is below w*, not above
    held = held_below(crit, d, phi, V)[0, 0]
    np.testing.assert_array_equal(held, (V < w_star).astype(float))
    assert held[velocity_bin(0.3)] == 1.0 and held[velocity_bin(1.0)] == 0.0


def test_pair_layer_is_the_mean_of_both_layers():
    crit = StokesCriterion(0.1, 0.5, 4e-6, 1000.0)
    d = np.array([2e-3, 4e-3])
    phi = np.array([0.01, 0.03])
    h = layer_thickness(d, phi)
    st = crit.critical_stokes(d, phi)
    assert st[0, 1] == pytest.approx(3.0 * math.log((h[0] + h[1]) / 2 / 4e-6), rel=1e-12)
    assert st[0, 1] == st[1, 0]
    # a dry granule (no layer) holds nothing with a wet one whose layer is below 2 h_a
    dry = crit.critical_velocity(np.array([2e-3, 2e-3]), np.array([0.0, 0.005]))
    assert dry[0, 1] == 0.0 and dry[0, 0] == 0.0


def test_bad_stokes_parameters_are_refused():
    with pytest.raises(ConfigError, match=r"pbm.aggregation.success.stokes.restitution = 1.5"):
        Pbm.from_dict({"aggregation": {"success": {"stokes": {"restitution": 1.5}}}}, "pbm")
    with pytest.raises(ConfigError, match=r"pbm.aggregation.success.stokes.binder_viscosity = -1"):
        Pbm.from_dict({"aggregation": {"success": {"stokes": {"binder_viscosity": -1}}}}, "pbm")
    with pytest.raises(ConfigError, match=r"pbm.aggregation.success.velocity_model = 'fast'"):
        Pbm.from_dict({"aggregation": {"success": {"velocity_model": "fast"}}}, "pbm")


def test_a_velocity_criterion_needs_only_critical_velocity():
    # the kernel calls velocity.critical_velocity(d, phi) and nothing else of the criterion
    class OnlyCritical:
        def critical_velocity(self, d, phi):
            return np.ones((np.size(d), np.size(d)))

    assert SuccessProbability("step", 0.02, velocity=OnlyCritical()).velocity_dependent


# ----------------------------------------------------------------------------- combination with the liquid
def test_success_combines_liquid_condition_and_stokes_criterion():
    crit = StokesCriterion(0.1, 0.4, 5e-6, 1000.0)
    psi = SuccessProbability("step", threshold=0.02, velocity=crit)
    assert psi.velocity_dependent and not SuccessProbability().velocity_dependent
    d = np.array([3e-3, 3e-3, 3e-3])
    phi = np.array([0.01, 0.02, 0.05])  # below, at and above the liquid threshold
    res = resolved(psi, d, phi, V)
    w_star = crit.critical_velocity(d, phi)
    for i in range(3):
        for j in range(3):
            liquid = float(phi[i] >= 0.02 and phi[j] >= 0.02)
            np.testing.assert_array_equal(res[i, j], liquid * (V < w_star[i, j]))
    assert res[0].sum() == 0.0 and res[1, 1].sum() > 0 and res[1, 1, -1] == 0.0
    # more surface liquid -> thicker layer -> faster impacts held
    assert w_star[2, 2] > w_star[1, 1]
    # without the velocity criterion: the liquid condition in every bin
    np.testing.assert_array_equal(
        resolved(SuccessProbability("step", 0.02), d, phi, V),
        np.repeat(SuccessProbability("step", 0.02)(phi)[:, :, None], V.size, axis=2),
    )


def test_build_success_from_config():
    assert not build_success(Pbm()).velocity_dependent  # default: seed study
    psi = build_success(Pbm.from_dict(STOKES, "pbm"))
    assert psi.velocity_dependent
    assert (psi.velocity.viscosity, psi.velocity.restitution, psi.velocity.asperity_height, psi.velocity.density) == (
        0.1,
        0.4,
        5e-6,
        1000.0,
    )


def test_default_parameters_put_the_critical_speed_inside_the_bins():
    # documented in config.yaml: two 3 mm granules at phi = 0.02 are held below about 0.36 m/s
    w = build_success(Pbm.from_dict(STOKES, "pbm")).velocity.critical_velocity(np.array([3e-3]), np.array([0.02]))[0, 0]
    assert 0.3 < w < 0.4
    assert VELOCITY_EDGES[1] < w < VELOCITY_EDGES[-1]


# ----------------------------------------------------------------------------- kernel
class FakeEncounters:
    """A velocity-resolved test source (not the DEM): constant encounter frequency, the encounters
    of each pair spread over the velocity bins around a speed that grows with the pair's size."""

    def __init__(self, value=0.5, spread=1.0):
        self.value, self.spread = value, spread
        self.calls = 0

    def __call__(self, diameters, numbers, rpm):
        return self.encounters(diameters, numbers, rpm).frequency

    def encounters(self, diameters, numbers, rpm):
        self.calls += 1
        d = np.asarray(diameters, float)
        K = d.size
        centre = 0.1 * np.sqrt(d[:, None] * d[None, :]) / 3e-3 * (1 + rpm / 600.0)  # m/s
        z = (np.log(V)[None, None, :] - np.log(centre)[:, :, None]) / self.spread
        f = np.exp(-0.5 * z**2)
        return EncounterRates(np.full((K, K), self.value), f / f.sum(axis=2, keepdims=True))


def two_bin_source(fractions):
    class S:
        def __call__(self, d, n, rpm):
            return np.full((d.size, d.size), 0.8)

        def encounters(self, d, n, rpm):
            f = np.zeros((d.size, d.size, N_VELOCITY_BINS))
            for b, w in fractions.items():
                f[:, :, b] = w
            return EncounterRates(np.full((d.size, d.size), 0.8), f)

    return S()


def kernel_input(d, phi):
    d = np.asarray(d, float)
    return KernelInput(
        t=0.0,
        volumes=math.pi / 6 * d**3,
        diameters=d,
        numbers=np.ones(d.size),
        surface_fraction=np.asarray(phi, float),
        rpm=600.0,
    )


def test_collision_kernel_sums_over_velocity_bins_by_hand():
    crit = StokesCriterion(0.1, 0.4, 5e-6, 1000.0)
    slow, fast = velocity_bin(0.01), velocity_bin(5.0)
    src = two_bin_source({slow: 0.25, fast: 0.75})
    kern = CollisionKernel(src, 1e-3, SuccessProbability("step", 0.02, velocity=crit))
    inp = kernel_input([3e-3, 3e-3], [0.01, 0.05])
    beta = kern(inp)
    # pair (1, 1): wet, slow bin held (w* ~ 0.9 m/s), fast bin not: beta = beta0 c 0.25
    assert beta[1, 1] == pytest.approx(1e-3 * 0.8 * 0.25, rel=1e-14)
    # pairs with granule 0 (phi below the threshold): nothing
    assert beta[0, 0] == 0.0 and beta[0, 1] == 0.0
    assert kern.velocity_fractions is not None and kern.frequency[0, 0] == 0.8
    # velocity-independent success with the same source: the source's (K, K) call, psi = liquid
    plain = CollisionKernel(src, 1e-3, SuccessProbability("step", 0.02))
    assert plain(inp)[1, 1] == pytest.approx(1e-3 * 0.8, rel=1e-14)
    assert plain.velocity_fractions is None


def test_collision_kernel_equals_the_sum_over_bins_of_the_definition():
    # beta_ij = beta0 c_ij sum_b f_ij,b psi_ij(v_b), psi_ij(v_b) from resolved
    crit = StokesCriterion(0.05, 0.6, 3e-6, 1200.0)
    psi = SuccessProbability("logistic", 0.02, 0.005, velocity=crit)
    src = FakeEncounters(value=0.7, spread=1.5)
    d = np.geomspace(1e-3, 2e-2, 12)
    phi = np.linspace(0.0, 0.08, 12)
    inp = kernel_input(d, phi)
    beta = CollisionKernel(src, 2e-3, psi)(inp)
    rates = src.encounters(d, np.ones(d.size), inp.rpm)
    expected = 2e-3 * rates.frequency * np.sum(rates.velocity_fractions * resolved(psi, d, phi, V), axis=2)
    np.testing.assert_allclose(beta, expected, rtol=1e-12, atol=0.0)
    assert 0 < np.count_nonzero(beta) < beta.size  # some pairs held, some not


def test_collision_kernel_needs_encounters_for_a_velocity_model():
    psi = SuccessProbability("step", 0.02, velocity=StokesCriterion(0.1, 0.4, 5e-6, 1000.0))
    with pytest.raises(PBMInputError, match="has no encounters"):
        CollisionKernel(lambda d, n, rpm: np.ones((d.size, d.size)), 1e-3, psi)
    kern = CollisionKernel(FakeEncounters(), 1e-3, psi)
    with pytest.raises(PBMInputError, match="has no encounters"):
        kern.set_source(lambda d, n, rpm: np.ones((d.size, d.size)))


@pytest.mark.parametrize(
    "bad,match",
    [
        (lambda f: f * 2.0, r"sum to 2; allowed: 1"),
        (lambda f: np.where(f > 0, -f, f), "allowed: finite values >= 0"),
        (lambda f: f[:, :, :5], r"expected \(3, 3, 17\)"),
    ],
)
def test_bad_velocity_fractions_are_refused(bad, match):
    class Bad(FakeEncounters):
        def encounters(self, d, n, rpm):
            r = super().encounters(d, n, rpm)
            return type("R", (), {"frequency": r.frequency, "velocity_fractions": bad(r.velocity_fractions)})()

    psi = SuccessProbability("always", velocity=StokesCriterion(0.1, 0.4, 5e-6, 1000.0))
    kern = CollisionKernel(Bad(), 1e-3, psi)
    with pytest.raises(KernelShapeError, match=match):
        kern(kernel_input([2e-3, 3e-3, 4e-3], [0.05, 0.05, 0.05]))


def test_pbm_with_velocity_resolved_frequencies_conserves_solid_volume(default_config):
    res = run_batch(batch_with(default_config, STOKES), FakeEncounters(), 600.0)
    s = res.summary()
    solid = s["total_solid_volume"].to_numpy()
    assert abs(solid[-1] - solid[0]) <= 1e-13 * solid[0]
    # the Stokes criterion holds part of the wet encounters: growth, but less than without it
    plain = run_batch(batch_with(default_config, {}), FakeEncounters(), 600.0).summary()
    assert s["d50"].iloc[-1] > 1.05 * s["d50"].iloc[0]
    assert s["d50"].iloc[-1] < plain["d50"].iloc[-1]
    assert res.info["frequency_evaluations"] > 1
    # total liquid bookkeeping unchanged
    assert s["total_liquid_volume"].iloc[-1] == pytest.approx(s["liquid_added"].iloc[-1], rel=1e-12)


def test_pure_aggregation_with_velocity_resolved_kernel_conserves_solid_volume():
    grid = Grid(20, 2.0, min_diameter=1e-3)
    psi = SuccessProbability("always", velocity=StokesCriterion(0.1, 0.4, 5e-6, 1000.0))
    kern = CollisionKernel(FakeEncounters(value=0.05), 1.0, psi)
    model = GranulationPBM(grid, kern, rpm=300.0)
    state = model.initial_state([grid.x[2], grid.x[4]], [400.0, 100.0], liquid_content=0.3, porosity=0.1)
    res = model.run(0.0, 30.0, state, output_times=[10.0, 20.0])
    x = grid.x
    s0 = float(np.sum(state.number * x))
    s1 = float(np.sum(res.state.number * x))
    assert abs(s1 - s0) <= 1e-13 * s0
    assert res.state.number.sum() < 0.9 * state.number.sum()  # it did aggregate


# ----------------------------------------------------------------------------- DEM table with velocities
D2 = np.array([0.002, 0.004])


def pair_table(rpms=(300.0, 900.0)):
    return dem_tables.pair_table(D2, lambda rpm, a, b: 0.1 * (a + b + 1) * rpm / 300.0, rpms, frequency_per_pair=9.0)


#: encounters per (rpm, pair) and velocity bin of the hand-written velocity table
COUNTS = {
    (300.0, 0, 0): {2: 3.0, 5: 1.0},
    (300.0, 0, 1): {5: 2.0},
    (300.0, 1, 1): {5: 1.0, 8: 1.0},
    (900.0, 0, 0): {8: 4.0},
    (900.0, 0, 1): {8: 1.0, 11: 1.0},
    (900.0, 1, 1): {11: 5.0},
}


def velocity_table():
    return dem_tables.pair_velocity_table(COUNTS)


def hand_fractions(rpm, a, b):
    f = np.zeros(N_VELOCITY_BINS)
    for k, n in COUNTS[(rpm, a, b)].items():
        f[k] = n
    return f / f.sum()


def test_table_encounters_at_the_nodes_between_sizes_and_speeds():
    src = TableFrequency(pair_table(), velocity_table=velocity_table())
    rates = src.encounters(D2, np.ones(2), 300.0)
    np.testing.assert_allclose(rates.frequency, [[0.1, 0.2], [0.2, 0.3]], rtol=1e-12)
    np.testing.assert_allclose(rates.frequency, src(D2, np.ones(2), 300.0))
    for a, b in ((0, 0), (0, 1), (1, 1)):
        np.testing.assert_allclose(rates.velocity_fractions[a, b], hand_fractions(300.0, a, b), atol=1e-15)
        np.testing.assert_allclose(rates.velocity_fractions[b, a], hand_fractions(300.0, a, b), atol=1e-15)
    # half-way in log d between 2 and 4 mm (both bins): mean of the four corners
    dm = np.array([np.sqrt(0.002 * 0.004)])
    mid = src.encounters(dm, np.ones(1), 300.0).velocity_fractions[0, 0]
    corners = hand_fractions(300.0, 0, 0) + 2 * hand_fractions(300.0, 0, 1) + hand_fractions(300.0, 1, 1)
    np.testing.assert_allclose(mid, corners / 4, atol=1e-15)
    # beyond the table's sizes: the nearest size (clamped)
    far = src.encounters(np.array([0.001, 0.01]), np.ones(2), 300.0).velocity_fractions
    np.testing.assert_allclose(far[0, 0], hand_fractions(300.0, 0, 0), atol=1e-15)
    np.testing.assert_allclose(far[1, 1], hand_fractions(300.0, 1, 1), atol=1e-15)
    # between speeds: fractions mixed linearly with the weights of the rpm interpolation
    r = src.encounters(D2, np.ones(2), 450.0)
    np.testing.assert_allclose(
        r.velocity_fractions[0, 1], 0.75 * hand_fractions(300.0, 0, 1) + 0.25 * hand_fractions(900.0, 0, 1), atol=1e-15
    )
    np.testing.assert_allclose(r.velocity_fractions.sum(axis=2), 1.0, rtol=1e-14)
    np.testing.assert_allclose(
        src.encounters(D2, np.ones(2), 2000.0).velocity_fractions[1, 1], hand_fractions(900.0, 1, 1), atol=1e-15
    )


def test_table_pair_without_encounters_gets_the_pooled_distribution():
    t = pair_table(rpms=(300.0,))
    t.loc[(t.class_i == 1) & (t.class_j == 1), "encounter_frequency_per_pair"] = 0.0
    vt = velocity_table()
    vt = vt[~((vt.rpm == 300.0) & (vt.class_i == 1) & (vt.class_j == 1)) & (vt.rpm == 300.0)]
    f = TableFrequency(t, velocity_table=vt).encounters(D2, np.ones(2), 300.0).velocity_fractions
    pooled = np.zeros(N_VELOCITY_BINS)
    pooled[2], pooled[5] = 3.0, 3.0
    np.testing.assert_allclose(f[1, 1], pooled / 6.0, atol=1e-15)


def test_table_encounters_from_csv(tmp_path):
    t, vt = pair_table(), velocity_table()
    coarse = t.assign(distribution="coarse", point_id=t.point_id.str.replace("fine", "coarse"))
    pc, pv = tmp_path / "collisions.csv", tmp_path / "impact_velocity.csv"
    pd.concat([t, coarse]).to_csv(pc, index=False)
    vt_coarse = vt.assign(
        distribution="coarse",
        point_id=vt.point_id.str.replace("fine", "coarse"),
        encounters=np.where(vt.v_lo == VELOCITY_EDGES[3], 1.0, 0.0),
    )
    pd.concat([vt, vt_coarse]).to_csv(pv, index=False)
    fine = TableFrequency.from_csv(pc, distribution="fine", velocity_path=pv)
    np.testing.assert_allclose(
        fine.encounters(D2, np.ones(2), 900.0).velocity_fractions[1, 1], hand_fractions(900.0, 1, 1), atol=1e-15
    )
    c = TableFrequency.from_csv(pc, distribution="coarse", velocity_path=pv).encounters(D2, np.ones(2), 300.0)
    np.testing.assert_allclose(c.velocity_fractions[:, :, 3], 1.0)
    with pytest.raises(PBMInputError, match="needs the impact-velocity table"):
        TableFrequency.from_csv(pc, distribution="fine").encounters(D2, np.ones(2), 300.0)
    with pytest.raises(FileNotFoundError, match="impact-velocity table .*missing.csv does not exist"):
        TableFrequency.from_csv(pc, distribution="fine", velocity_path=tmp_path / "missing.csv")


@pytest.mark.parametrize(
    "mutate,match",
    [
        (lambda v: v.drop(columns=["encounters"]), r"impact-velocity table: missing column\(s\) \['encounters'\]"),
        (lambda v: v.assign(encounters=-1.0), r"column 'encounters' = -1.0: a finite number >= 0 is required"),
        (lambda v: v.assign(v_lo=v.v_lo * 1.5), r"is not one of the project's velocity bins"),
        (lambda v: v.assign(point_id="rpm600_fine"), r"has no rows for the collision table's points"),
        (lambda v: v.assign(class_j=np.where(v.class_j == 1, 2, v.class_j)), r"has no row in the collision table"),
        (
            lambda v: v.assign(encounters=np.where((v.class_i == 0) & (v.class_j == 1), 0.0, v.encounters)),
            r"pair d_i = 0.002, d_j = 0.004 has encounter_frequency_per_pair = 0.2 but no encounters",
        ),
    ],
)
def test_bad_velocity_tables(mutate, match):
    with pytest.raises(PBMInputError, match=match):
        TableFrequency(pair_table(), velocity_table=mutate(velocity_table()))


def test_pbm_on_a_velocity_resolved_table_conserves_solid_volume():
    src = TableFrequency(pair_table(), velocity_table=velocity_table())
    psi = SuccessProbability("always", velocity=StokesCriterion(0.1, 0.4, 5e-6, 1000.0))
    grid = Grid(25, 2.0, min_diameter=1e-3)
    model = GranulationPBM(grid, CollisionKernel(src, 0.01, psi), rpm=600.0)
    state = model.initial_state([grid.x[3], grid.x[6]], [300.0, 30.0], liquid_content=0.3, porosity=0.1)
    res = model.run(0.0, 20.0, state)
    s0 = float(np.sum(state.number * grid.x))
    assert abs(float(np.sum(res.state.number * grid.x)) - s0) <= 1e-13 * s0
    assert res.state.number.sum() < state.number.sum()


# ----------------------------------------------------------------------------- constant source, CLI
def test_constant_frequency_with_one_impact_velocity():
    from pbmdem.pbm import ConstantFrequency

    r = ConstantFrequency(0.5, impact_velocity=0.3).encounters(D2, np.ones(2), 600.0)
    np.testing.assert_array_equal(r.frequency, 0.5)
    np.testing.assert_array_equal(r.velocity_fractions.argmax(axis=2), velocity_bin(0.3))
    np.testing.assert_array_equal(r.velocity_fractions.sum(axis=2), 1.0)
    with pytest.raises(PBMInputError, match="constant_impact_velocity"):
        ConstantFrequency(0.5).encounters(D2, np.ones(2), 600.0)


def test_constant_baseline_with_stokes_needs_an_impact_velocity(default_config):
    with pytest.raises(PBMInputError, match=r"constant_impact_velocity = a speed in m/s \(now null\)"):
        run_batch(batch_with(default_config, STOKES), None, 600.0, t_end=10.0)
    slow = {"aggregation": {"constant_impact_velocity": 0.05, "success": {"velocity_model": "stokes"}}}
    fast = {"aggregation": {"constant_impact_velocity": 5.0, "success": {"velocity_model": "stokes"}}}
    d_slow = run_batch(batch_with(default_config, slow), None, 600.0).summary()["d50"]
    d_plain = run_batch(batch_with(default_config, {}), None, 600.0).summary()["d50"]
    d_fast = run_batch(batch_with(default_config, fast), None, 600.0).summary()["d50"]
    # slow impacts are all held once wet (same as velocity-independent), 5 m/s impacts never are
    assert d_slow.iloc[-1] == pytest.approx(d_plain.iloc[-1], rel=1e-12)
    assert d_fast.iloc[-1] == pytest.approx(d_fast.iloc[0], rel=1e-12)


def test_cli_table_run_with_velocity_table(tmp_path, root, capsys):
    import yaml

    from pbmdem.cli import main

    pc, pv = tmp_path / "collisions.csv", tmp_path / "impact_velocity.csv"
    pair_table().to_csv(pc, index=False)
    velocity_table().to_csv(pv, index=False)
    cfg = yaml.safe_load((root / "config" / "config.yaml").read_text())
    cfg["pbm"]["aggregation"]["success"]["velocity_model"] = "stokes"
    cfg_path = tmp_path / "config.yaml"
    cfg_path.write_text(yaml.safe_dump(cfg))
    base = [
        "pbm",
        "--config",
        str(cfg_path),
        "--kernel",
        "table",
        "--table",
        str(pc),
        "--rpm",
        "600",
        "--distribution",
        "fine",
        "--out",
        str(tmp_path / "out"),
    ]
    assert main(base) == 2
    assert "needs --velocity-table PATH" in capsys.readouterr().err
    # with breakage on, its selection comes from the wall tables too
    cfg["pbm"]["breakage"]["enabled"] = True
    cfg_path.write_text(yaml.safe_dump(cfg))
    assert main(base + ["--velocity-table", str(pv)]) == 2
    assert "--wall-table PATH" in capsys.readouterr().err
    cfg["pbm"]["breakage"]["enabled"] = False  # aggregation's velocity table is what this test is about
    cfg_path.write_text(yaml.safe_dump(cfg))
    assert main(base + ["--velocity-table", str(pv)]) == 0
    s = pd.read_csv(tmp_path / "out" / "summary.csv")
    assert s["total_solid_volume"].iloc[-1] == pytest.approx(s["total_solid_volume"].iloc[0], rel=1e-13)
    assert s["number_mean_diameter"].iloc[-1] > s["number_mean_diameter"].iloc[0]
    capsys.readouterr()
    assert (
        main(
            [
                "pbm",
                "--config",
                str(cfg_path),
                "--kernel",
                "constant",
                "--velocity-table",
                str(pv),
                "--rpm",
                "600",
                "--out",
                str(tmp_path / "o2"),
            ]
        )
        == 2
    )
    assert "read with --kernel table only" in capsys.readouterr().err


def test_velocity_rows_of_other_points_are_left_out():
    # one point's collision table beside the grid's velocity table
    t = pair_table(rpms=(900.0,))
    r = TableFrequency(t, velocity_table=velocity_table()).encounters(D2, np.ones(2), 900.0)
    np.testing.assert_allclose(r.velocity_fractions[0, 1], hand_fractions(900.0, 0, 1), atol=1e-15)


def test_single_size_table_with_velocities():
    t = pair_table(rpms=(300.0,))
    t = t[(t.class_i == 0) & (t.class_j == 0)]
    vt = velocity_table()
    vt = vt[(vt.rpm == 300.0) & (vt.class_i == 0) & (vt.class_j == 0)]
    r = TableFrequency(t, velocity_table=vt).encounters(np.array([0.001, 0.003, 0.02]), np.ones(3), 300.0)
    np.testing.assert_allclose(r.frequency, 0.1, rtol=1e-12)
    for i in range(3):
        for j in range(3):
            np.testing.assert_allclose(r.velocity_fractions[i, j], hand_fractions(300.0, 0, 0), atol=1e-15)
