"""Breakage selection from impacts (pbmdem.pbm.impact_breakage): hand-made impacts with known
speeds give the selection rate the Stokes deformation criterion predicts."""

import dem_tables
import numpy as np
import pbm_oracle
import pytest

from pbmdem.config import ConfigError, Pbm
from pbmdem.impact import N_VELOCITY_BINS, VELOCITY_EDGES, EncounterRates, ImpactRates, WallRates, fraction_above
from pbmdem.pbm.errors import PBMInputError
from pbmdem.pbm.impact_breakage import POROSITY_LIMIT, ImpactSelection, critical_speed, selection_rates
from pbmdem.pbm.kernels import KernelInput
from pbmdem.readers import InputFileError

RHO, Y, ST = 1000.0, 1.0e4, 0.2  # v* = sqrt(2 * 1e4 * 0.2 / 1000) = 2 m/s


def one_bin(shape, speed):
    """Fractions with every impact in the bin of `speed`."""
    f = np.zeros((*shape, N_VELOCITY_BINS))
    f[..., int(np.searchsorted(VELOCITY_EDGES, speed, side="right") - 1)] = 1.0
    return f


def fraction_columns(fractions: np.ndarray) -> np.ndarray:
    """(K,) for each partner j of the pair velocity ``fractions`` (K, K, V): the first partner of
    the run of neighbours j' <= j whose columns ``fractions[:, j', :]`` equal column j
    (``_compiled_selection.impact_selection`` sums such a column once per row; the bins sharing their
    nearest class of a coupling interval are such runs). The readable form of
    ``_compiled_selection.fraction_columns``, which ``ImpactSelection`` uses: its test oracle."""
    K = fractions.shape[1]
    same = (fractions[:, 1:, :] == fractions[:, :-1, :]).all(axis=(0, 2))  # column j + 1 equals column j
    starts = np.flatnonzero(np.concatenate([[True], ~same]))
    return starts[np.searchsorted(starts, np.arange(K), side="right") - 1].astype(np.int64)


def critical_speeds(selection: ImpactSelection, diameters, porosity=None) -> float | np.ndarray:
    """v* of granules of each diameter (m) and porosity: Y (d / d_ref)^(-e) with e =
    ``size_exponent`` times [r(eps) / r(eps_ref)]^n with r = (1 - eps) / eps and n =
    ``porosity_exponent``, so v* scales with the square root of both factors; ``porosity``
    None or NaN (an empty pivot): eps_ref. The one v* with e = n = 0. The readable form (and
    oracle) of ``_compiled_selection.critical_speeds``, which the selection uses."""
    s = selection
    if s.size_exponent == 0.0 and s.porosity_exponent == 0.0:
        return s.speed
    d = np.asarray(diameters, float)
    speeds = np.full(d.shape, s.speed)
    if s.size_exponent != 0.0:
        speeds = s.speed * (d / s.reference_diameter) ** (-0.5 * s.size_exponent)
    if s.porosity_exponent != 0.0 and porosity is not None:
        eps = np.broadcast_to(np.asarray(porosity, float), d.shape)
        eps = np.where(np.isfinite(eps), eps, s.reference_porosity)
        # kept inside (0, 1) so that v* stays finite and > 0 (at eps -> 0 a granule without
        # pores is unbreakable, at eps -> 1 one without solid breaks at any impact)
        eps = np.clip(eps, POROSITY_LIMIT, 1.0 - POROSITY_LIMIT)
        ref = (1.0 - s.reference_porosity) / s.reference_porosity
        speeds = speeds * (((1.0 - eps) / eps) / ref) ** (0.5 * s.porosity_exponent)
    return speeds


def contributions(selection: ImpactSelection, inp: KernelInput) -> dict[str, np.ndarray]:
    """Per kind of impact (pairs, each wall): (K,) breaking impacts per granule and second of the
    pivots of ``inp``, in numpy (:func:`selection_rates` at the selection's v*): the oracle of the
    compiled ``ImpactSelection.__call__``."""
    if selection._rates is None:
        selection.prepare(inp)
    d, n = inp.per_bin()
    speeds = critical_speeds(selection, d, selection._porosity(inp))
    return selection_rates(selection._rates, n, speeds, selection.walls, selection.pairs, selection.strength_spread)


class HandMadeSource:
    """Impacts with known speeds: pairs at `pair_speed`, the impeller at `impeller_speed`, the
    bowl at `bowl_speed`; frequencies given per pair and per granule."""

    def __init__(self, c, f_impeller, f_bowl, pair_speed, impeller_speed, bowl_speed):
        self.c, self.f = np.asarray(c, float), np.array([f_bowl, f_impeller], float)
        self.speeds = (pair_speed, impeller_speed, bowl_speed)
        self.calls = 0

    def impacts(self, diameters, numbers, rpm):
        self.calls += 1
        K = len(diameters)
        pair_speed, impeller_speed, bowl_speed = self.speeds
        walls = np.stack([one_bin((K,), bowl_speed), one_bin((K,), impeller_speed)])
        return ImpactRates(EncounterRates(self.c[:K, :K], one_bin((K, K), pair_speed)), WallRates(self.f[:, :K], walls))


def kernel_input(numbers, d=(0.002, 0.004)):
    d = np.asarray(d, float)
    return KernelInput(0.0, np.pi / 6 * d**3, d, np.asarray(numbers, float), np.zeros(d.size), rpm=600.0)


def test_critical_speed_of_the_stokes_criterion():
    assert critical_speed(RHO, Y, ST) == pytest.approx(2.0)
    assert critical_speed(1500.0, 3.0e4, 0.1) == pytest.approx(np.sqrt(2 * 3.0e4 * 0.1 / 1500.0))


def test_fraction_above_splits_a_straddling_bin_evenly_in_log_speed():
    above = fraction_above(2.0)
    b = int(np.searchsorted(VELOCITY_EDGES, 2.0, side="right") - 1)
    lo, hi = VELOCITY_EDGES[b], VELOCITY_EDGES[b + 1]
    assert above[b] == pytest.approx(np.log(hi / 2.0) / np.log(hi / lo))
    assert np.all(above[:b] == 0.0) and np.all(above[b + 1 :] == 1.0)
    assert fraction_above(0.0).tolist() == [1.0] * N_VELOCITY_BINS
    assert fraction_above(5e-4)[0] == pytest.approx(0.5)  # bin 0 is [0, 1 mm/s), even in v


def test_only_impacts_faster_than_the_critical_speed_break():
    c = np.array([[1e-3, 2e-3], [2e-3, 4e-3]])
    # pairs at 0.5 m/s and the bowl at 0.3 m/s cannot break (v* = 2 m/s); the impeller at 4 m/s can
    source = HandMadeSource(
        c, f_impeller=[3.0, 5.0], f_bowl=[7.0, 9.0], pair_speed=0.5, impeller_speed=4.0, bowl_speed=0.3
    )
    sel = ImpactSelection(source, RHO, Y, ST)
    inp = kernel_input([100, 50])
    sel.prepare(inp)
    np.testing.assert_allclose(sel(inp), [3.0, 5.0])
    parts = contributions(sel, inp)
    np.testing.assert_allclose(parts["pairs"], 0.0)
    np.testing.assert_allclose(parts["bowl"], 0.0)


def test_pair_impacts_count_every_partner_but_not_the_granule_itself():
    c = np.array([[1e-3, 2e-3], [2e-3, 4e-3]])
    source = HandMadeSource(c, [0.0, 0.0], [0.0, 0.0], pair_speed=4.0, impeller_speed=0.1, bowl_speed=0.1)
    sel = ImpactSelection(source, RHO, Y, ST)
    inp = kernel_input([100, 50])
    s = sel(inp)
    np.testing.assert_allclose(s, [1e-3 * 99 + 2e-3 * 50, 2e-3 * 100 + 4e-3 * 49])
    # the pair term follows the current numbers without asking the source again
    calls = source.calls
    np.testing.assert_allclose(sel(kernel_input([10, 5])), [1e-3 * 9 + 2e-3 * 5, 2e-3 * 10 + 4e-3 * 4])
    assert source.calls == calls


def test_walls_and_pairs_can_be_switched_off_and_a_stronger_granule_breaks_less():
    c = np.full((2, 2), 1e-3)
    source = HandMadeSource(c, [3.0, 5.0], [7.0, 9.0], pair_speed=4.0, impeller_speed=4.0, bowl_speed=4.0)
    inp = kernel_input([100, 50])
    only_bowl = ImpactSelection(source, RHO, Y, ST, walls=("bowl",), pairs=False)
    np.testing.assert_allclose(only_bowl(inp), [7.0, 9.0])
    # Y x 4 doubles v* to 4 m/s, inside the bin of the impacts: only the part above 4 m/s breaks
    strong = ImpactSelection(source, RHO, 4 * Y, ST, walls=("bowl",), pairs=False)
    assert strong.speed == pytest.approx(4.0)
    b = int(np.searchsorted(VELOCITY_EDGES, 4.0, side="right") - 1)
    split = np.log(VELOCITY_EDGES[b + 1] / 4.0) / np.log(VELOCITY_EDGES[b + 1] / VELOCITY_EDGES[b])
    np.testing.assert_allclose(strong(inp), np.array([7.0, 9.0]) * split)
    # Y x 100: v* = 20 m/s beyond every bin, nothing breaks
    assert np.all(ImpactSelection(source, RHO, 100 * Y, ST)(inp) == 0.0)


def test_bad_settings_and_sources_are_refused_by_name():
    # the settings are checked where they enter, by the typed pbm.breakage section
    with pytest.raises(ConfigError, match=r"pbm.breakage.yield_strength = -1.0"):
        Pbm.from_dict({"breakage": {"yield_strength": -1.0}}, "pbm")
    with pytest.raises(ConfigError, match=r"pbm.breakage.walls"):
        Pbm.from_dict({"breakage": {"walls": ["lid"]}}, "pbm")
    with pytest.raises(PBMInputError, match="impacts"):
        ImpactSelection(object(), RHO, Y, ST)


def grid_tables(speed_of_rpm):
    """Hand-made grid tables of one distribution at 300 and 1200 rpm: classes 2 and 4 mm, every
    wall encounter of a point at the one speed `speed_of_rpm[rpm]` (m/s), impeller encounters
    2 and 4 per granule and second, bowl 10 and 20; pairs at 0.1 m/s."""
    from pbmdem.impact import velocity_bin

    d, rpms, rate = (0.002, 0.004), list(speed_of_rpm), {"bowl": 10.0, "impeller": 2.0}
    pairs = dem_tables.pair_table(d, lambda rpm, a, b: 1e-3, rpms, "feed")
    pair_counts = {(rpm, a, b): {velocity_bin(0.1): 5.0} for rpm in rpms for a, b in ((0, 0), (0, 1), (1, 1))}
    walls = dem_tables.wall_table(d, lambda rpm, wall, c: rate[wall] * (1 + c), rpms, "feed")
    wall_counts = {(rpm, w, c): {velocity_bin(speed_of_rpm[rpm]): 7.0} for rpm in rpms for w in rate for c in (0, 1)}
    return (
        pairs,
        dem_tables.pair_velocity_table(pair_counts, "feed", every_bin=False),
        walls,
        dem_tables.wall_velocity_table(wall_counts, "feed", every_bin=False),
    )


def test_selection_from_hand_made_dem_tables_breaks_only_above_the_critical_speed():
    from pbmdem.pbm.table import TableFrequency
    from pbmdem.pbm.wall_table import WallTable

    pairs, pair_v, walls, wall_v = grid_tables({300: 0.5, 1200: 3.0})  # v* = 2 m/s between them
    source = TableFrequency(pairs, velocity_table=pair_v)
    source.walls = WallTable(walls, wall_v)
    sel = ImpactSelection(source, RHO, Y, ST)
    b = int(np.searchsorted(VELOCITY_EDGES, 3.0, side="right") - 1)
    above = fraction_above(2.0)[b]
    d = np.array([0.002, 0.004])
    for rpm, expected in ((300.0, [0.0, 0.0]), (1200.0, np.array([12.0, 24.0]) * above)):
        inp = KernelInput(0.0, np.pi / 6 * d**3, d, np.array([100.0, 50.0]), np.zeros(2), rpm=rpm)
        sel.prepare(inp)
        np.testing.assert_allclose(sel(inp), expected, rtol=1e-12)
    # between the table speeds the wall rates and the fractions mix linearly (here 50 / 50)
    rates = source.impacts(d, [100, 50], 750.0)
    np.testing.assert_allclose(rates.walls.of("impeller")[0], [2.0, 4.0])
    assert rates.walls.of("bowl")[1][0, b] == pytest.approx(0.5)


def test_wall_rates_of_one_run_are_read_per_class_and_wall():
    from pbmdem.frequency import wall_rates_from_tables

    _, _, walls, wall_v = grid_tables({600: 2.5})
    rates = wall_rates_from_tables(walls, wall_v, 2)
    np.testing.assert_allclose(rates.of("bowl")[0], [10.0, 20.0])
    np.testing.assert_allclose(rates.of("impeller")[1].sum(axis=1), 1.0)
    assert rates.of("impeller")[1][0].argmax() == np.searchsorted(VELOCITY_EDGES, 2.5, side="right") - 1


def test_a_wall_velocity_bin_off_the_project_edges_is_refused_by_row():
    from pbmdem.pbm.wall_table import WallTable

    _, _, walls, wall_v = grid_tables({600: 2.5})
    wall_v.loc[3, "v_lo"] *= 1.5
    with pytest.raises(PBMInputError, match=r"wall impact-velocity table: row 4, .* not one of the project's velocity"):
        WallTable(walls, wall_v)


# ---------------------------------------------------------------- gradual breakage (strength spread)
def test_breaking_probability_of_a_log_normal_strength_by_hand():
    from scipy.integrate import quad
    from scipy.stats import norm

    from pbmdem.impact import VELOCITY_EDGES, breaking_probability, fraction_above

    v_star, s = 2.0, 0.5
    p = breaking_probability(v_star, s)
    # bin [1.78, 3.16) m/s straddles v*: the mean of Phi(2 ln(v / v*) / s) over ln v, by quadrature
    for b in (12, 13, 14, 15):
        lo, hi = np.log(VELOCITY_EDGES[b]), np.log(VELOCITY_EDGES[b + 1])
        expected = quad(lambda u: norm.cdf(2 * (u - np.log(v_star)) / s), lo, hi)[0] / (hi - lo)
        assert p[b] == pytest.approx(expected, rel=1e-9)
    # far above v* every granule breaks, far below none
    assert p[1] < 1e-12 and p[-1] > 0.95
    # spread 0 is the sharp criterion; a small spread tends to it
    assert np.array_equal(breaking_probability(v_star, 0.0), fraction_above(v_star))
    assert np.allclose(breaking_probability(v_star, 1e-4), fraction_above(v_star), atol=1e-4)
    with pytest.raises(ValueError, match="spread"):
        breaking_probability(v_star, -0.1)


def test_gradual_selection_from_hand_made_impacts():
    # every pair and wall impact at 2.37 m/s (the bin [1.78, 3.16) m/s, its log centre): with
    # v* = 2 m/s the sharp criterion breaks a fraction log(3.16 / 2) / log(3.16 / 1.78) = 0.795 of
    # them; log-normal strengths (spread 0.5) break the bin's mean of Phi(4 ln(v / 2)) instead
    from scipy.integrate import quad
    from scipy.stats import norm

    from pbmdem.impact import VELOCITY_EDGES

    b = 14
    lo, hi = np.log(VELOCITY_EDGES[b]), np.log(VELOCITY_EDGES[b + 1])
    gradual = quad(lambda u: norm.cdf(4.0 * (u - np.log(2.0))), lo, hi)[0] / (hi - lo)
    sharp = np.log(VELOCITY_EDGES[b + 1] / 2.0) / np.log(VELOCITY_EDGES[b + 1] / VELOCITY_EDGES[b])
    K = 2
    frac = np.zeros((K, K, N_VELOCITY_BINS))
    frac[..., b] = 1.0
    wall_frac = np.zeros((2, K, N_VELOCITY_BINS))
    wall_frac[..., b] = 1.0
    rates = ImpactRates(
        EncounterRates(np.full((K, K), 0.01), frac), WallRates(np.array([[1.0, 2.0], [3.0, 4.0]]), wall_frac)
    )
    n = np.array([10.0, 5.0])
    v_star = critical_speed(RHO, Y, ST)
    assert v_star == pytest.approx(2.0)
    for spread, p in ((0.0, sharp), (0.5, gradual)):
        out = selection_rates(rates, n, v_star, spread=spread)
        assert out["pairs"] == pytest.approx(0.01 * np.array([9.0 + 5.0, 10.0 + 4.0]) * p, rel=1e-9)
        assert out["bowl"] == pytest.approx(np.array([1.0, 2.0]) * p, rel=1e-9)
        assert out["impeller"] == pytest.approx(np.array([3.0, 4.0]) * p, rel=1e-9)
    assert gradual != pytest.approx(sharp, rel=1e-2)


def test_larger_granules_weaker_with_a_strength_size_exponent():
    # Y (d / 2 mm)^(-1): a 2 mm granule has v* = 2 m/s, an 8 mm one v* = 2 / sqrt(4) = 1 m/s; every
    # impact at 1.3 m/s (bin [1, 1.78) m/s) breaks the 8 mm granule and none of the 2 mm ones
    d = (0.002, 0.008)
    source = HandMadeSource(np.full((2, 2), 0.01), [2.0, 2.0], [1.0, 1.0], 1.3, 1.3, 1.3)
    inp = kernel_input([10.0, 5.0], d=d)
    flat = ImpactSelection(source, RHO, Y, ST)
    sized = ImpactSelection(source, RHO, Y, ST, size_exponent=1.0, reference_diameter=0.002)
    assert critical_speeds(sized, np.array(d)) == pytest.approx([2.0, 1.0])
    assert np.all(flat(inp) == 0.0)
    parts = contributions(sized, inp)
    assert parts["pairs"] == pytest.approx([0.0, 0.01 * (10.0 + 4.0)])
    assert parts["impeller"] == pytest.approx([0.0, 2.0]) and parts["bowl"] == pytest.approx([0.0, 1.0])
    with pytest.raises(ConfigError, match=r"pbm.breakage.strength_size_exponent = -1.0"):
        Pbm.from_dict({"breakage": {"strength_size_exponent": -1.0}}, "pbm")


def test_breakage_study_variants_include_the_sharp_criterion(default_config):
    from pbmdem.coupling.studies import breakage_variants

    pbm = default_config.pbm
    variants = breakage_variants(pbm)
    assert list(variants) == ["off", "default", "Y/2", "Yx2", "sharp"]
    assert variants["default"].strength_spread == pbm.breakage.strength_spread > 0
    assert variants["sharp"].strength_spread == 0.0 and variants["sharp"].enabled
    sharp_only = breakage_variants(pbm.replace(breakage=pbm.breakage.replace(strength_spread=0.0)))
    assert "sharp" not in sharp_only


def test_a_porosity_exponent_of_zero_leaves_the_selection_bit_identical():
    # n = 0 (the default): the selection ignores porosity; the rates are those of the v* of
    # the size law alone, bit for bit, whatever porosity the input carries
    d = np.array([0.002, 0.004, 0.008])
    source = HandMadeSource(np.full((3, 3), 0.01), [2.0, 2.0, 3.0], [1.0, 1.0, 1.0], 1.3, 2.5, 3.1)
    inp = kernel_input([10.0, 5.0, 2.0], d=d)
    inp.porosity = np.array([0.5, 0.3, 0.2])
    for size_exponent in (0.0, 1.0):
        for spread in (0.0, 0.5):
            base = dict(strength_spread=spread, size_exponent=size_exponent)
            before = ImpactSelection(source, RHO, Y, ST, **base)
            after = ImpactSelection(source, RHO, Y, ST, **base, porosity_exponent=0.0, reference_porosity=0.3)
            v = before.speed if size_exponent == 0.0 else before.speed * (d / 0.002) ** (-0.5 * size_exponent)
            rates = source.impacts(d, inp.numbers, inp.rpm)
            expected = selection_rates(rates, inp.numbers, v, before.walls, before.pairs, spread)
            for sel in (before, after):
                parts = contributions(sel, inp)
                assert parts.keys() == expected.keys()
                for k in parts:
                    np.testing.assert_array_equal(parts[k], expected[k])


@pytest.mark.parametrize("n", [1.0, 2.0])
def test_consolidated_granules_are_stronger_with_a_porosity_exponent(n):
    # Y(eps) = Y [((1 - eps)/eps) / ((1 - 0.5)/0.5)]^n: at eps = 0.2, (1 - eps)/eps = 4, so
    # v* = 2 m/s * 4^(n/2): 4 m/s (n = 1), 8 m/s (n = 2); at eps = 0.5 (and where a pivot is
    # empty, NaN) v* = 2 m/s. Every impact at 4.5 m/s (bin [3.16, 5.62) m/s) breaks the fresh
    # granule; of the consolidated one's the fraction above v* in log v: log(5.62/4)/log(5.62/3.16)
    # with n = 1, none with n = 2
    d = (0.004, 0.004, 0.004)
    source = HandMadeSource(np.full((3, 3), 0.01), [2.0, 2.0, 2.0], [1.0, 1.0, 1.0], 4.5, 4.5, 4.5)
    inp = kernel_input([10.0, 5.0, 0.0], d=d)
    inp.porosity = np.array([0.5, 0.2, np.nan])
    sharp = ImpactSelection(source, RHO, Y, ST, porosity_exponent=n)
    v_fresh, v_dense = 2.0, 2.0 * 4.0 ** (n / 2)
    assert critical_speeds(sharp, np.array(d), inp.porosity) == pytest.approx([v_fresh, v_dense, v_fresh])
    s = sharp(inp)
    lo, hi = VELOCITY_EDGES[15], VELOCITY_EDGES[16]
    dense_above = np.clip(np.log(hi / v_dense) / np.log(hi / lo), 0.0, 1.0)
    assert s[0] == pytest.approx(0.01 * (9.0 + 5.0 + 0.0) + 2.0 + 1.0)
    assert s[1] == pytest.approx((0.01 * (10.0 + 4.0 + 0.0) + 2.0 + 1.0) * dense_above)
    assert s[1] < s[0]
    # with a spread of strengths the consolidated granule breaks in fewer impacts, by the same law
    spread = ImpactSelection(source, RHO, Y, ST, strength_spread=0.5, porosity_exponent=n)
    rates = source.impacts(np.array(d), inp.numbers, 600.0)
    expected = selection_rates(rates, inp.numbers, np.array([v_fresh, v_dense, v_fresh]), spread=0.5)
    np.testing.assert_allclose(spread(inp), sum(expected.values()), rtol=1e-12)
    assert 0.0 < spread(inp)[1] < spread(inp)[0]
    # the reference porosity is the one whose strength is Y
    shifted = ImpactSelection(source, RHO, Y, ST, porosity_exponent=n, reference_porosity=0.2)
    assert critical_speeds(shifted, np.array(d), inp.porosity) == pytest.approx([2.0 / 4.0 ** (n / 2), 2.0, 2.0])
    with pytest.raises(ConfigError, match=r"pbm.breakage.strength_porosity_exponent = -1.0"):
        Pbm.from_dict({"breakage": {"strength_porosity_exponent": -1.0}}, "pbm")
    with pytest.raises(ConfigError, match=r"pbm.breakage.reference_porosity = 1.0"):
        Pbm.from_dict({"breakage": {"reference_porosity": 1.0}}, "pbm")
    inp.porosity = None
    with pytest.raises(PBMInputError, match="porosity"):
        sharp(inp)


def test_the_porosity_of_the_aggregates_decides_not_that_of_the_feed_classes():
    # K = 2 pivots followed by one feed class: only the pivots' porosities enter
    d = np.array([0.004, 0.008, 0.004])
    source = HandMadeSource(np.full((2, 2), 0.01), [2.0, 2.0], [1.0, 1.0], 3.0, 3.0, 3.0)
    inp = KernelInput(
        0.0, np.pi / 6 * d**3, d, np.array([5.0, 5.0, 100.0]), np.zeros(3), rpm=600.0,
        feed_weights=np.array([[1.0, 0.0]]), porosity=np.array([0.2, 0.5, 0.5]),
    )  # fmt: skip
    sel = ImpactSelection(source, RHO, Y, ST, porosity_exponent=2.0)
    s = sel(inp)
    assert s[0] == 0.0 and s[1] > 0.0


def _porosity_model(n, separate_feed=True, consolidation=None):
    from pbmdem.pbm import ConstantKernel, GranulationPBM, Grid
    from pbmdem.pbm.breakage import Breakage

    g = Grid(30, 2.0 ** (1 / 3), min_diameter=2e-3)  # SI: pivots of 4.2e-9 .. 4.3e-6 m3
    # every impact at 3 m/s: v* 2 m/s when fresh (eps 0.5), 8 m/s when consolidated (eps 0.2, n = 2)
    source = HandMadeSource(np.full((30, 30), 1e-4), np.full(30, 0.05), np.full(30, 0.02), 3.0, 3.0, 3.0)
    sel = ImpactSelection(source, RHO, Y, ST, strength_spread=0.5, porosity_exponent=n)
    model = GranulationPBM(
        g, ConstantKernel(1e-5), consolidation=consolidation, breakage=Breakage(sel, "binary"),
        separate_feed=separate_feed,
    )  # fmt: skip
    return g, model


@pytest.mark.parametrize("n", [0.0, 2.0])
def test_breakage_with_a_porosity_dependent_strength_conserves_solid_liquid_and_gas(n):
    # bins alternately fresh (eps 0.5) and consolidated (eps 0.2), no consolidation: aggregation
    # and breakage move solid, liquid and gas between bins and conserve each, in SI volumes
    from pbmdem.pbm import State

    g, model = _porosity_model(n)
    N = np.where(np.arange(30) < 12, 100.0 * np.exp(-np.arange(30) / 4.0), 0.0)
    S = N * g.x
    G = np.where(np.arange(30) % 2 == 0, 1.0, 0.25) * S
    state = State(0.0, N, 0.2 * S, G)
    res = model.run(0.0, 60.0, state, output_times=np.arange(0.0, 61.0, 10.0))
    for name, total in (("solid", res.number @ g.x), ("liquid", res.liquid.sum(axis=1)), ("gas", res.gas.sum(axis=1))):
        rel = np.abs(total / total[0] - 1).max()
        print(f"n = {n:g}: {name} changed by at most {rel:.1e}")
        assert rel < 1e-13, name
    # the selection saw each bin's porosity: with n = 2 the consolidated bins' impeller impacts break less
    impeller = contributions(model.breakage.selection, pbm_oracle.bin_input(model, 0.0, N, 0.2 * S, G))["impeller"][:12]
    if n == 0.0:
        assert np.all(impeller == impeller[0]) and impeller[0] > 0.0
    else:
        assert np.all(impeller[1::2] < 0.1 * impeller[0::2])


def test_consolidated_aggregates_break_less_and_the_batch_conserves_solid_and_liquid():
    # a batch consolidating from eps 0.5 towards 0.2 while it aggregates and its aggregates break:
    # solid and liquid to round-off; the gas follows consolidation's closed form for the whole batch,
    # G_min + (G0 - G_min) e^(-ct), within the solver's tolerance; with n = 2 fewer granules remain
    from pbmdem.pbm.processes import Consolidation

    d = np.array([2e-3, 3e-3, 5e-3, 8e-3])
    for separate_feed in (True, False):
        numbers = {}
        for n in (0.0, 2.0):
            g, model = _porosity_model(n, separate_feed, Consolidation(0.02, 0.2))
            state = model.initial_state(np.pi / 6 * d**3, [400.0, 200.0, 80.0, 20.0], liquid_content=0.2, porosity=0.5)
            res = model.run(0.0, 120.0, state, output_times=np.arange(0.0, 121.0, 20.0))
            solid = res.number @ g.x
            for name, total in (("solid", solid), ("liquid", res.liquid.sum(axis=1))):
                assert np.abs(total / total[0] - 1).max() < 1e-13, (n, separate_feed, name)
            gas0 = res.gas.sum(axis=1)[0]
            closed = 0.25 * solid[0] + (gas0 - 0.25 * solid[0]) * np.exp(-0.02 * np.asarray(res.times))
            np.testing.assert_allclose(res.gas.sum(axis=1), closed, rtol=1e-4)
            numbers[n] = res.state.number.sum()
        assert numbers[2.0] < numbers[0.0]


def test_the_porosity_exponent_setting_reaches_the_selection(default_config):
    from pbmdem.pbm.impact_breakage import impact_selection

    pbm = default_config.pbm
    # the default: breakage on, the viscous (n = 2) strength law, Y given for a fresh granule
    assert pbm.breakage.enabled and pbm.breakage.strength_porosity_exponent == 2.0
    assert pbm.breakage.reference_porosity == 0.5 == pbm.initial.porosity
    sel = impact_selection(pbm)
    assert (sel.porosity_exponent, sel.reference_porosity) == (2.0, 0.5)
    brk = pbm.breakage.replace(strength_porosity_exponent=1.0, reference_porosity=0.4)
    sel = impact_selection(pbm.replace(breakage=brk))
    assert (sel.porosity_exponent, sel.reference_porosity) == (1.0, 0.4)


@pytest.mark.parametrize("spread", [0.0, 0.5, 1.3])
def test_the_compiled_selection_equals_the_numpy_form_on_random_impacts(spread):
    # ImpactSelection.__call__ (compiled: _compiled_selection.breaking_probability + impact_selection) against
    # the numpy definition (selection_rates summed over its kinds) on random impacts, numbers,
    # sizes and porosities (so one v* per class), with pairs and each subset of the walls
    from pbmdem.impact import breaking_probability

    rng = np.random.default_rng(7)
    K = 9
    d = 0.002 * 1.26 ** np.arange(K)
    c = rng.uniform(0.0, 0.3, (K, K))
    pair_f = rng.dirichlet(np.ones(N_VELOCITY_BINS), (K, K))
    rates = ImpactRates(
        EncounterRates(0.5 * (c + c.T), 0.5 * (pair_f + pair_f.transpose(1, 0, 2))),
        WallRates(rng.uniform(0.0, 5.0, (2, K)), rng.dirichlet(np.ones(N_VELOCITY_BINS), (2, K))),
    )

    class Source:
        def impacts(self, diameters, numbers, rpm):
            return rates

    numbers = rng.uniform(0.0, 40.0, K)
    numbers[3] = 0.5  # fewer than one partner of its own class
    inp = KernelInput(0.0, np.pi / 6 * d**3, d, numbers, np.zeros(K), rpm=900.0)
    inp.porosity = rng.uniform(0.2, 0.5, K)
    for walls, pairs in ((("impeller", "bowl"), True), (("bowl",), True), ((), True), (("impeller",), False)):
        sel = ImpactSelection(Source(), RHO, Y, ST, walls, pairs, spread, size_exponent=0.5, porosity_exponent=2.0)
        parts = contributions(sel, inp)
        expected = np.sum(list(parts.values()), axis=0) if parts else np.zeros(K)
        got = sel(inp)
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-300)
        assert got.shape == (K,) and (got > 0).any()
    # the compiled probability against pbmdem.impact.breaking_probability, one row per v*
    from pbmdem.pbm import _compiled_selection

    v = np.array([1e-4, 5e-4, 0.0316, 0.3, 0.3, 2.0, 2.0, 2.0, 9.9, 12.0])  # repeated: a row copied
    out = np.empty((v.size, N_VELOCITY_BINS))
    _compiled_selection.breaking_probability(v, spread, VELOCITY_EDGES, out)
    np.testing.assert_allclose(out, breaking_probability(v, spread), rtol=1e-12, atol=1e-15)


def test_a_coupling_intervals_dem_run_is_read_as_pbm_dem_hands_it_to_the_pbm(tmp_path):
    """pbmdem.coupling.providers.dem_rates: the four tables of one DEM run (what PBM-DEM reads at
    each interval, and what benchmarks/bench_replay.py reads back from a finished run)."""
    from synthetic_tables import make_synthetic_tables, make_synthetic_wall_tables

    from pbmdem.coupling.providers import dem_rates

    pairs, velocities = make_synthetic_tables(
        0.1, rpms=(600,), distributions={"feed": (0.625, 0.375)}, diameters=(0.002, 0.004),
        n_total_range=(80, 80), law=lambda *a: 0.05, n_replicates=1, noise_log10=0.0,
    )  # fmt: skip
    walls, wall_velocities = make_synthetic_wall_tables(pairs, 0.1)
    frames = dict(zip(("collisions", "impact_velocity", "wall_collisions", "wall_impact_velocity"),
                      (pairs, velocities, walls, wall_velocities), strict=True))  # fmt: skip
    for name, frame in frames.items():
        frame = frames[name] = frame.assign(replicate=0)
        for col in {"collisions", "encounters"} & set(frame):  # whole counts in a run's tables
            frame[col] = frame[col].round().astype(int)
        frame.to_csv(tmp_path / f"{name}.csv", index=False)
    rates = dem_rates(tmp_path, 2)
    np.testing.assert_allclose(rates.pairs.frequency, np.full((2, 2), 0.05))
    # the pair (0, 1)'s fractions are its encounters per bin over all of them
    counts = frames["impact_velocity"].query("class_i == 0 and class_j == 1")["encounters"].to_numpy(float)
    np.testing.assert_allclose(rates.pairs.velocity_fractions[1, 0], counts / counts.sum())
    bowl = frames["wall_collisions"].query("wall == 'bowl'").sort_values("class_i")
    np.testing.assert_allclose(rates.walls.of("bowl")[0], bowl["encounter_frequency_per_particle"])
    (tmp_path / "wall_collisions.csv").unlink()
    with pytest.raises(InputFileError, match="wall_collisions.csv"):
        dem_rates(tmp_path, 2)


def test_bins_that_share_their_nearest_class_fractions_give_the_selection_to_the_bit():
    # a coupling interval's bins take the velocity fractions of their nearest class
    # (ClassFrequencySource.encounters): the compiled selection sums each shared column once per
    # row (fraction_columns); against every column summed on its own (the identity map) and the numpy form
    from pbmdem.pbm import _compiled_selection

    rng = np.random.default_rng(11)
    K, classes = 12, 4
    nearest = np.repeat(np.arange(classes), 3)
    class_f = rng.dirichlet(np.ones(N_VELOCITY_BINS), (classes, classes))
    pair_f = np.ascontiguousarray(class_f[np.ix_(nearest, nearest)])
    columns = fraction_columns(pair_f)
    assert columns.tolist() == [0, 0, 0, 3, 3, 3, 6, 6, 6, 9, 9, 9]
    assert _compiled_selection.fraction_columns(pair_f).tolist() == columns.tolist()
    c = rng.uniform(0.0, 0.3, (K, K))
    c = 0.5 * (c + c.T)
    walls = WallRates(rng.uniform(0.0, 5.0, (2, K)), rng.dirichlet(np.ones(N_VELOCITY_BINS), (2, K)))
    numbers = rng.uniform(0.0, 40.0, K)
    numbers[[1, 7]] = 0.0, 0.5  # an empty bin (its column's first member skipped), one partner short
    v = rng.uniform(0.5, 6.0, K)
    probability = np.empty((K, N_VELOCITY_BINS))
    _compiled_selection.breaking_probability(v, 0.5, VELOCITY_EDGES, probability)
    shared, each = np.empty(K), np.empty(K)
    args = (walls.frequency, walls.velocity_fractions, probability, numbers, True)
    _compiled_selection.impact_selection(c, pair_f, columns, *args, shared)
    _compiled_selection.impact_selection(c, pair_f, np.arange(K), *args, each)
    assert shared.tobytes() == each.tobytes()
    rates = ImpactRates(EncounterRates(c, pair_f), walls)
    np.testing.assert_allclose(shared, np.sum(list(selection_rates(rates, numbers, v, spread=0.5).values()), axis=0),
                               rtol=1e-12)  # fmt: skip


def test_the_compiled_fraction_columns_equal_the_numpy_form_on_random_runs():
    # runs of equal columns, a column equal to its neighbour but in one entry, NaN (never equal)
    from pbmdem.pbm import _compiled_selection

    rng = np.random.default_rng(5)
    for trial in range(50):
        K, classes = int(rng.integers(1, 30)), int(rng.integers(1, 6))
        nearest = np.sort(rng.integers(0, classes, K))
        class_f = rng.dirichlet(np.ones(N_VELOCITY_BINS), (classes, classes))
        f = np.ascontiguousarray(class_f[np.ix_(nearest, nearest)])
        if K > 2 and trial % 3 == 0:
            j = int(rng.integers(1, K))
            f[:, j] = f[:, j - 1]
            f[int(rng.integers(0, K)), j, int(rng.integers(0, N_VELOCITY_BINS))] += 1e-16 if trial % 2 else 0.0
        if K > 2 and trial % 7 == 0:
            f[:, 1:3, 0] = np.nan
        expected = fraction_columns(f)
        assert _compiled_selection.fraction_columns(f).tolist() == expected.tolist()


def test_the_compiled_impact_selection_sums_as_the_plain_loops_do_to_the_bit():
    # _compiled_selection.impact_selection runs the sums of four columns side by side: against the
    # plain loops (one sum over the bins after the other, in the bins' order) on random impacts with
    # empty classes, partners short of one, zero frequencies, shared columns and 0-2 walls
    from pbmdem.pbm import _compiled_selection

    def plain(c, f, walls_c, walls_f, p, n, pairs):
        out = []
        for i in range(len(n)):
            total = 0.0
            for j in range(len(n)) if pairs else ():
                partners = n[j] - 1.0 if i == j else n[j]
                if n[j] <= 0.0 or partners <= 0.0 or c[i, j] == 0.0:
                    continue
                dot = 0.0
                for b in range(p.shape[1]):
                    dot += f[i, j, b] * p[i, b]
                total += c[i, j] * dot * partners
            for w in range(walls_c.shape[0]):
                dot = 0.0
                for b in range(p.shape[1]):
                    dot += walls_f[w, i, b] * p[i, b]
                total += walls_c[w, i] * dot
            out.append(total)
        return np.array(out)

    rng = np.random.default_rng(17)
    for K, W, pairs in ((1, 2, True), (5, 2, True), (7, 1, True), (13, 0, True), (6, 2, False)):
        nearest = np.sort(rng.integers(0, max(K // 2, 1), K))
        f = np.ascontiguousarray(rng.dirichlet(np.ones(N_VELOCITY_BINS), (K, K))[:, nearest])
        c = rng.uniform(0.0, 0.3, (K, K)) * (rng.random((K, K)) > 0.2)
        walls_c, walls_f = rng.uniform(0.0, 5.0, (W, K)), rng.dirichlet(np.ones(N_VELOCITY_BINS), (W, K))
        n = rng.uniform(0.0, 40.0, K) * (rng.random(K) > 0.2)
        n[K // 2] = 0.5
        p = np.empty((K, N_VELOCITY_BINS))
        _compiled_selection.breaking_probability(rng.uniform(0.5, 6.0, K), 0.5, VELOCITY_EDGES, p)
        out = np.empty(K)
        _compiled_selection.impact_selection(c, f, fraction_columns(f), walls_c, walls_f, p, n, pairs, out)
        assert out.tobytes() == plain(c, f, walls_c, walls_f, p, n, pairs).tobytes()
