"""The pooled fast tail of the impact speeds (pbmdem.surrogate.tail.fit_speed_tail): a known
stretched exponential in tip-speed units recovered from sampled speeds in m/s, its use on a speed
law's bin fractions, and the surrogate that fits and applies it."""

import math

import numpy as np
import pytest
from synthetic_tables import make_synthetic_tables

from pbmdem.impact import N_VELOCITY_BINS, VELOCITY_EDGES, velocity_bin
from pbmdem.surrogate import CollisionSurrogate, training_data
from pbmdem.surrogate.calibration import member_quantiles
from pbmdem.surrogate.families import ResponseSurface
from pbmdem.surrogate.tail import fit_speed_tail, member_tail, with_speed_tail
from pbmdem.surrogate.velocity import speed_fractions

R = 0.0265
A, BETA = 8.0, 0.7  # the known tail: P(V > v | V > v_s) = exp(-A ((v/v_tip)^BETA - (v_s/v_tip)^BETA))
V_S = float(VELOCITY_EDGES[14])  # 1.78 m/s
TIPS = (1.67, 2.5, 3.33)  # m/s: 600, 900, 1200 rpm at R


def sampled_counts(rng, tip: float, n_tail: int, n_bulk: int, a: float = A) -> np.ndarray:
    """Bin counts of ``n_bulk`` slow impacts (log-normal below v_s) and ``n_tail`` impacts above v_s
    drawn from the known tail by its inverse distribution function."""
    bulk = 10.0 ** rng.normal(-0.7, 0.4, 4 * n_bulk)
    bulk = bulk[bulk < V_S][:n_bulk]
    u = (V_S / tip) ** BETA - np.log(rng.random(n_tail)) / a
    tail = tip * u ** (1.0 / BETA)
    return np.bincount(velocity_bin(np.concatenate([bulk, tail])), minlength=N_VELOCITY_BINS).astype(float)


def test_known_tail_recovered_from_sampled_speeds_including_above_2_m_s():
    rng = np.random.default_rng(5)
    counts = np.array([sampled_counts(rng, tip, 20_000, 50_000) for tip in TIPS])
    first, a, beta, spread = fit_speed_tail(counts, TIPS, 1.78)
    assert spread == 0.0  # one run (no groups)
    assert VELOCITY_EDGES[first] == pytest.approx(V_S)
    assert a == pytest.approx(A, rel=0.05)
    assert beta == pytest.approx(BETA, rel=0.05)
    # the fraction of the tail faster than 3.16 and 5.62 m/s: within 3 binomial standard errors + 5 %
    fitted = with_speed_tail(counts / counts.sum(axis=1, keepdims=True), TIPS, (first, a, beta))
    for row, tip in enumerate(TIPS):
        n_tail = counts[row, first:].sum()
        for edge in (15, 16):  # 3.16, 5.62 m/s
            v = VELOCITY_EDGES[edge]
            exact = math.exp(-A * ((v / tip) ** BETA - (V_S / tip) ** BETA))
            got = fitted[row, edge:].sum() / fitted[row, first:].sum()
            assert abs(got - exact) <= 3.0 * math.sqrt(exact * (1 - exact) / n_tail) + 0.05 * exact, (tip, v)


def test_rows_whose_tail_lies_beyond_twice_their_tip_speed_do_not_enter_the_fit():
    # a slow run (tip 0.69 m/s, 250 rpm) with a few pinched impacts at 2-5 m/s, 3-8 times its tip
    # speed: in tip-speed units they would dominate the pooled shape (final10, rpm250_sf07)
    rng = np.random.default_rng(5)
    counts = np.array([sampled_counts(rng, tip, 20_000, 50_000) for tip in TIPS])
    slow = np.zeros(N_VELOCITY_BINS)
    slow[:14] = 50_000.0 / 14
    slow[velocity_bin(np.array([1.9, 2.4, 3.5, 4.2, 5.0]))] += 1.0
    first, a, beta, _ = fit_speed_tail(np.vstack([counts, slow]), (*TIPS, 0.69), 1.78)
    assert (first, a, beta) == fit_speed_tail(counts, TIPS, 1.78)[:3]
    assert a == pytest.approx(A, rel=0.05)
    assert beta == pytest.approx(BETA, rel=0.05)
    # alone, such a row gives no tail: the speed law's own tail stays
    assert fit_speed_tail(slow[None, :], [0.69], 1.78) is None


def test_tail_keeps_each_rows_share_above_its_speed_and_sums_to_one():
    fractions = speed_fractions(np.array([-0.5, 0.1]), np.array([0.4, 0.3]), "gengamma", np.array([0.2, -0.3]))
    tail = (14, A, BETA)
    out = with_speed_tail(fractions, np.array([2.0, 3.3]), tail)
    assert np.allclose(out.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    assert np.allclose(out[:, 14:].sum(axis=1), fractions[:, 14:].sum(axis=1), rtol=1e-12, atol=0)
    assert np.array_equal(out[:, :14], fractions[:, :14])
    assert with_speed_tail(fractions, np.array([2.0, 3.3]), None) is fractions


def test_no_impact_above_the_speed_gives_no_tail_and_a_bad_edge_names_the_key():
    counts = np.zeros((2, N_VELOCITY_BINS))
    counts[:, 5:10] = 3.0
    assert fit_speed_tail(counts, [1.0, 2.0], 1.78) is None
    assert member_tail(None, 1.0) is None
    with pytest.raises(ValueError, match=r"surrogate\.speed_tail_from = 1\.5 m/s; allowed: null or an inner edge"):
        fit_speed_tail(counts, [1.0, 2.0], 1.5)


def test_surrogate_fits_the_pooled_tail_and_its_fractions_follow_it():
    pairs, velocities = make_synthetic_tables(R, rpms=(600.0, 900.0, 1200.0), sample_velocities=True, seed=4)
    data = training_data(pairs, R, velocity_table=velocities, speed_law="gengamma")
    counts = data.velocity_counts
    rows = np.isfinite(counts).all(axis=1)
    assert rows.any() and (counts[rows] >= 0).all() and np.isnan(counts[~rows]).all()
    assert counts[rows][:, 13:].sum() > 0  # impacts faster than 1 m/s to fit a tail to

    def fitted(tail_from):
        model = CollisionSurrogate(
            frequency_model=ResponseSurface(),
            velocity_model=ResponseSurface(),
            impeller_radius=R,
            physics_offset="cross_section",
            feature_transform="log",
            speed_law="gengamma",
            speed_tail_from=tail_from,
        )
        return model.fit(data.X, data.y, data.groups, velocity=data.velocity, velocity_counts=counts)

    plain, tailed = fitted(None), fitted(1.0)
    assert plain.speed_tail_ is None
    first, a, beta, spread = tailed.speed_tail_
    tips = data.X["tip_speed"].to_numpy()[rows]
    assert tailed.speed_tail_ == fit_speed_tail(counts[rows], tips, 1.0, data.groups[rows])
    # members: the tail's a scaled by exp(-z spread), from the fewest fast impacts to the most (the
    # synthetic runs hold too few fast impacts for a spread of their own: one is set)
    tailed.speed_tail_ = (first, a, beta, 0.2)
    scales = np.array([tailed.member(k).speed_tail_[1] for k in range(tailed.n_members)])
    assert np.allclose(scales, a * np.exp(-0.2 * member_quantiles(tailed.n_members)), rtol=1e-14, atol=0)
    assert np.all(np.diff(scales) < 0) and scales[tailed.n_members // 2] == pytest.approx(a, rel=1e-14)
    X = data.X.iloc[:20]
    law, tail = plain.velocity_fractions(X), tailed.velocity_fractions(X)
    assert np.array_equal(law[:, :first], tail[:, :first])  # the law below the tail's speed
    tip = X["tip_speed"].to_numpy()[:, None]
    exact = np.exp(-a * ((VELOCITY_EDGES[first + 1] / tip) ** beta - (VELOCITY_EDGES[first] / tip) ** beta))
    share = tail[:, first + 1 :].sum(axis=1, keepdims=True) / tail[:, first:].sum(axis=1, keepdims=True)
    assert np.allclose(share, exact, rtol=1e-9, atol=0)


def test_spread_between_runs_is_the_scatter_of_each_runs_own_scale():
    # six runs whose tails differ in a by a known factor: the spread is the sd of ln a_r (the pooled
    # a and beta describe their mixture, a heavier tail than any one run's: not compared)
    rng = np.random.default_rng(11)
    log_a = np.log(A) + np.array([-0.3, -0.1, 0.0, 0.1, 0.2, 0.3])
    counts = np.array([sampled_counts(rng, 3.33, 30_000, 1000, a=np.exp(la)) for la in log_a])
    runs = np.array(["r0", "r1", "r2", "r3", "r4", "r5"])
    spread = fit_speed_tail(counts, np.full(6, 3.33), 1.78, runs)[3]
    # each run's own a_r is fitted at the pooled beta, which is not the true one: allow 25 %
    assert spread == pytest.approx(np.std(log_a, ddof=1), rel=0.25)
    # a run with fewer than TAIL_RUN_MIN_COUNTS fast impacts does not count
    few = np.vstack([counts, sampled_counts(rng, 3.33, 50, 1000, a=A * 5)])
    assert fit_speed_tail(few, np.full(7, 3.33), 1.78, np.append(runs, "r6"))[3] == pytest.approx(spread, rel=0.05)
