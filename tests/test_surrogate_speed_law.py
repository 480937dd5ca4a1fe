"""The impact-speed laws of the surrogate (pbmdem.surrogate.velocity.SPEED_LAWS): the Weibull law
beside the log-normal, fitted to bins, its fractions on the project's bins, its fast tail, and the
surrogate, its persistence and its baselines carrying the law."""

import math
import warnings

import numpy as np
import pandas as pd
import pytest
from scipy.stats import norm, weibull_min
from synthetic_tables import make_synthetic_tables

from pbmdem.impact import N_VELOCITY_BINS, VELOCITY_EDGES, fraction_above, velocity_bin
from pbmdem.surrogate import CollisionSurrogate, training_data
from pbmdem.surrogate.baselines import PhysicalScaling
from pbmdem.surrogate.families import ResponseSurface
from pbmdem.surrogate.velocity import (
    attach_velocity_bins,
    bin_counts,
    fit_speed_law,
    speed_fractions,
)

R = 0.0265


def weibull_bins(shape: float, scale: float) -> np.ndarray:
    """Exact fractions of a Weibull(shape, scale) speed law in every bin (last bin open upwards)."""
    cdf = weibull_min.cdf(VELOCITY_EDGES, shape, scale=scale)
    cdf[-1] = 1.0
    return np.diff(cdf)


def test_weibull_fractions_are_the_weibull_law_by_hand():
    # k = 2, lambda = 0.5 m/s: median = lambda ln2^(1/k); std of ln v = pi / (sqrt 6 k)
    k, lam = 2.0, 0.5
    mu = math.log10(lam * math.log(2.0) ** (1 / k))
    sigma = math.pi / (math.sqrt(6.0) * k) / math.log(10.0)
    frac = speed_fractions(mu, sigma, "weibull")[0]
    assert frac.shape == (N_VELOCITY_BINS,)
    assert np.all(frac >= 0) and frac.sum() == pytest.approx(1.0, abs=1e-12)
    assert np.allclose(frac, weibull_bins(k, lam), rtol=1e-9, atol=1e-15)
    # the fast tail by hand: P(V > 1 m/s) = exp(-(1 / 0.5)^2) = exp(-4) (1 m/s is a bin edge)
    assert frac @ fraction_above(1.0) == pytest.approx(math.exp(-4.0), rel=1e-9)


def test_weibull_tail_is_lighter_than_the_lognormal_of_same_median_and_spread():
    mu, sigma = math.log10(0.3), 0.3
    above = fraction_above(2.0)
    weib, logn = (speed_fractions(mu, sigma, law)[0] @ above for law in ("weibull", "lognormal"))
    assert 0 < weib < 0.1 * logn


@pytest.mark.parametrize("law", ("lognormal", "weibull"))
def test_fit_recovers_its_own_law(law):
    mu, sigma = -0.6, 0.35
    mu_fit, sigma_fit = fit_speed_law(1e4 * speed_fractions(mu, sigma, law), law)
    assert mu_fit[0] == pytest.approx(mu, abs=1e-3) and sigma_fit[0] == pytest.approx(sigma, rel=1e-2)


@pytest.mark.parametrize("q", (-0.8, 0.4, 1.6))
def test_gengamma_fit_recovers_its_shape(q):
    mu, sigma = -0.6, 0.35
    mu_fit, sigma_fit, q_fit = fit_speed_law(1e5 * speed_fractions(mu, sigma, "gengamma", q), "gengamma")
    assert mu_fit[0] == pytest.approx(mu, abs=1e-3) and sigma_fit[0] == pytest.approx(sigma, rel=1e-2)
    assert q_fit[0] == pytest.approx(q, abs=0.05)


def test_gengamma_is_the_lognormal_and_the_weibull_at_its_limits():
    from scipy.stats import gengamma

    mu, sigma = np.array([-0.5, 0.1]), np.array([0.3, 0.1])
    assert np.allclose(speed_fractions(mu, sigma, "gengamma", [1.0, 1.0]), speed_fractions(mu, sigma, "weibull"))
    assert np.allclose(speed_fractions(mu, sigma, "gengamma", [1e-4, -1e-4]), speed_fractions(mu, sigma, "lognormal"))
    # q = 0.5 by hand: v = s G^(q / ln 10 ...) -- scipy's Stacy form: v = scale G^(1/c), G ~ Gamma(a),
    # a = 1 / q^2, c = q / (sigma_W ln 10 ... ) matched through the median and the std of log10 v
    q, a = 0.5, 4.0
    from scipy.special import polygamma

    sd_log10 = np.sqrt(polygamma(1, a)) / np.log(10.0)  # std of log10 G
    c = sd_log10 / 0.3  # log10 v = log10 scale + log10(G) / c has std 0.3
    scale = 10**-0.5 / gengamma.median(a, 1.0) ** (1.0 / c)
    cdf = gengamma.cdf(VELOCITY_EDGES, a, c, scale=scale)
    cdf[-1] = 1.0
    assert np.allclose(speed_fractions(-0.5, 0.3, "gengamma", q)[0], np.diff(cdf), atol=1e-12)


def test_gengamma_fractions_on_the_bins_and_a_heavier_tail_for_negative_shape():
    above = fraction_above(2.0)
    tails = [speed_fractions(np.log10(0.3), 0.3, "gengamma", q)[0] for q in (-1.0, 0.0, 1.0, 1.5)]
    for f in tails:
        assert np.all(f >= 0) and f.sum() == pytest.approx(1.0, abs=1e-12)
    p = [f @ above for f in tails]
    assert p[0] > p[1] > p[2] > p[3] > 0
    with pytest.raises(ValueError, match="shape"):
        speed_fractions(0.0, 0.3, "gengamma")
    # shapes beyond the fitted bounds (a widened ensemble member) are held at the bounds
    assert np.array_equal(speed_fractions(-0.5, 0.3, "gengamma", 10.0), speed_fractions(-0.5, 0.3, "gengamma", 3.0))
    assert np.array_equal(speed_fractions(-0.5, 0.3, "gengamma", -9.0), speed_fractions(-0.5, 0.3, "gengamma", -2.0))


def gengamma_law(mu: float, sigma: float, q: float):
    """scipy's generalised gamma (Stacy form: v = scale G^(1/c), G ~ Gamma(a)) of the project's
    parameters: log10 median mu (m/s), std of log10 v sigma (decades), shape q (a = 1 / q^2)."""
    from scipy.special import polygamma
    from scipy.stats import gengamma

    a = 1.0 / q**2
    c = math.copysign(math.sqrt(polygamma(1, a)) / math.log(10.0) / sigma, q)
    return gengamma(a, c, scale=10**mu / gengamma.median(a, c))


@pytest.mark.parametrize("q", (-0.6, 0.5))  # a heavier and a lighter tail than the log-normal's
def test_gengamma_fit_of_sampled_speeds_recovers_the_tail_above_2_and_4_m_s(q):
    # 200 000 impacts of a known law, binned as the DEM bins them, fitted: the fitted law's rate
    # above 2 and 4 m/s (breakage's critical speeds) is the true law's within the stated tolerance,
    # 3 binomial standard errors of the fraction counted above that speed
    mu, sigma, n = math.log10(0.6), 0.3, 200_000
    true = gengamma_law(mu, sigma, q)
    assert np.allclose(speed_fractions(mu, sigma, "gengamma", q)[0], np.diff(np.r_[true.cdf(VELOCITY_EDGES[:-1]), 1.0]))
    v = true.rvs(n, random_state=np.random.default_rng(7))
    counts = np.bincount(velocity_bin(v), minlength=N_VELOCITY_BINS)
    mu_fit, sigma_fit, q_fit = (x[0] for x in fit_speed_law(counts, "gengamma"))
    fitted = gengamma_law(mu_fit, sigma_fit, q_fit)
    mu_ln, sigma_ln = (x[0] for x in fit_speed_law(counts, "lognormal"))
    for speed in (2.0, 4.0):
        p = true.sf(speed)
        tolerance = 3.0 * math.sqrt(p * (1.0 - p) / n)
        assert abs(fitted.sf(speed) - p) <= tolerance, speed
        # the binned law the PBM's breakage reads (fractions of the bins x the fraction above v)
        above = fraction_above(speed)
        binned = speed_fractions(mu_fit, sigma_fit, "gengamma", q_fit)[0] @ above
        assert abs(binned - speed_fractions(mu, sigma, "gengamma", q)[0] @ above) <= tolerance, speed
    # the test can tell: the log-normal fit of the same bins misses the tail at 4 m/s (by 3x or more)
    p4, lognormal4 = true.sf(4.0), norm.sf((math.log10(4.0) - mu_ln) / sigma_ln)
    assert max(p4 / lognormal4, lognormal4 / p4) > 3.0


def test_fit_from_1_m_s_recovers_the_tail_above_2_m_s_of_a_law_whose_bulk_differs():
    # the DEM's pairs: many slow bed contacts (log-normal, median 3 cm/s) and a fast mode of a known
    # generalised gamma (q = 0.5, median 0.5 m/s), 400 000 impacts binned as the DEM bins them. The law
    # fitted from 1 m/s up (slower impacts one cell) gives the rate above 2 and 3.16 m/s (breakage's
    # critical speeds) within 3 binomial standard errors of the fraction counted there; fitted to every
    # bin, the bulk decides and the same law misses it by more than 10x.
    rng = np.random.default_rng(11)
    n, share = 400_000, 0.4
    fast = gengamma_law(math.log10(0.5), 0.3, 0.5)
    n_fast = rng.binomial(n, share)
    v = np.concatenate([fast.rvs(n_fast, random_state=rng), 10 ** rng.normal(math.log10(0.03), 0.25, n - n_fast)])
    counts = np.bincount(velocity_bin(v), minlength=N_VELOCITY_BINS)
    tail = fit_speed_law(counts, "gengamma", fit_from=1.0)
    bulk = fit_speed_law(counts, "gengamma")
    # the true law's bins, as the PBM's breakage reads them (fractions of the bins x the fraction above v)
    true = share * speed_fractions(math.log10(0.5), 0.3, "gengamma", 0.5)[0]
    true += (1.0 - share) * speed_fractions(math.log10(0.03), 0.25, "lognormal")[0]
    for speed in (2.0, VELOCITY_EDGES[15]):
        above = fraction_above(speed)
        p = true @ above
        tolerance = 3.0 * math.sqrt(p * (1.0 - p) / n)
        fitted = speed_fractions(tail[0], tail[1], "gengamma", tail[2])[0] @ above
        assert abs(fitted - p) <= tolerance, speed
        missed = speed_fractions(bulk[0], bulk[1], "gengamma", bulk[2])[0] @ above
        assert max(missed / p, p / missed) > 10.0, speed
    # below the speed it is fitted from the law keeps the share of slower impacts
    slower = counts[:13].sum() / n
    assert speed_fractions(tail[0], tail[1], "gengamma", tail[2])[0][:13].sum() == pytest.approx(slower, abs=1e-6)


def test_fit_from_must_be_a_bin_edge_and_reaches_the_training_data():
    with pytest.raises(ValueError, match=r"speed_law_from = 0\.9 m/s; allowed: null or an inner edge"):
        fit_speed_law(np.ones(N_VELOCITY_BINS), "gengamma", fit_from=0.9)
    pairs, velocities = make_synthetic_tables(R, rpms=(600.0, 1200.0), sample_velocities=True, seed=3)
    data = training_data(pairs, R, velocity_table=velocities, speed_law="gengamma", speed_law_from=1.0)
    rows = np.isfinite(data.velocity).all(axis=1)
    counts = bin_counts(data.table)[rows]
    assert data.speed_law_from == 1.0
    assert np.allclose(np.column_stack(fit_speed_law(counts, "gengamma", 1.0)), data.velocity[rows])


def test_weibull_fit_of_sampled_speeds_and_its_median():
    rng = np.random.default_rng(0)
    v = 0.4 * rng.weibull(1.5, 100_000)
    counts = np.bincount(velocity_bin(v), minlength=N_VELOCITY_BINS)
    mu, sigma = fit_speed_law(counts, "weibull")
    assert mu[0] == pytest.approx(np.log10(np.median(v)), abs=0.01)
    assert sigma[0] == pytest.approx(np.std(np.log10(v)), rel=0.03)


def test_unknown_law_is_refused():
    with pytest.raises(ValueError, match="weibull"):
        speed_fractions(0.0, 0.3, "gamma")
    with pytest.raises(ValueError, match="allowed"):
        fit_speed_law(np.ones(N_VELOCITY_BINS), "gamma")


@pytest.fixture(scope="module")
def data():
    table = attach_velocity_bins(*make_synthetic_tables(R, seed=3, noise_log10=0.03, sample_velocities=True))
    return training_data(table, R, speed_law="weibull")


def _fitted_surrogate(data, speed_law: str) -> CollisionSurrogate:
    """A response-surface surrogate with the speed law `speed_law`, fitted on `data` (convergence
    warnings of the small synthetic set ignored)."""
    model = CollisionSurrogate(
        frequency_model=ResponseSurface(degree=(1,), n_members=3),
        impeller_radius=R,
        physics_offset="cross_section",
        feature_transform="log",
        speed_law=speed_law,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return model.fit(data.X, data.y, groups=data.groups, velocity=data.velocity)


def test_surrogate_predicts_fractions_of_its_law_and_persists_it(data, tmp_path):
    from pbmdem.surrogate import load_surrogate, save_surrogate

    assert data.speed_law == "weibull"
    model = _fitted_surrogate(data, "weibull")
    frac = model.velocity_fractions(data.X.iloc[:5])
    assert np.allclose(frac, speed_fractions(*model.predict_velocity(data.X.iloc[:5]), "weibull"))
    assert not np.allclose(frac, speed_fractions(*model.predict_velocity(data.X.iloc[:5]), "lognormal"))
    d, n = np.array([1e-3, 2e-3]), np.array([3000.0, 500.0])
    rates = model.encounters(d, n, 600.0, check_domain=False)
    assert np.allclose(rates.velocity_fractions.sum(axis=-1), 1.0) and (rates.velocity_fractions >= 0).all()
    save_surrogate(model, tmp_path / "model.skops", tmp_path / "model.json")
    loaded = load_surrogate(tmp_path / "model.skops")
    assert loaded.speed_law == "weibull"
    assert np.array_equal(loaded.velocity_fractions(data.X.iloc[:5]), frac)


def test_three_parameter_law_through_the_surrogate(data):
    table = data.table
    gg = training_data(table, R, speed_law="gengamma")
    assert gg.velocity.shape == (len(gg.y), 3)
    model = _fitted_surrogate(gg, "gengamma")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ValueError, match=r"\(n_samples, 3\)"):
            model.fit(gg.X, gg.y, groups=gg.groups, velocity=gg.velocity[:, :2])
    rates = model.encounters(np.array([1e-3, 2e-3]), np.array([3000.0, 500.0]), 600.0, check_domain=False)
    d32 = (3000 * 1e-9 + 500 * 8e-9) / (3000 * 1e-6 + 500 * 4e-6)  # Sauter diameter of the two classes
    X = pd.DataFrame(
        [[1e-3, 2e-3, 3000 / 3500, 500 / 3500, 3500.0, 2 * np.pi * R * 10.0, 1e-3 / d32, 2e-3 / d32]],
        columns=list(gg.X.columns),
    )
    assert np.allclose(rates.velocity_fractions[0, 1], model.velocity_fractions(X, check_domain=False)[0])
    assert np.allclose(rates.velocity_fractions.sum(axis=-1), 1.0)
    base = PhysicalScaling(speed_law="gengamma").fit(gg.X, gg.y, velocity=gg.velocity)
    assert np.allclose(base.velocity_fractions(gg.X.iloc[:2]).sum(axis=1), 1.0)


def test_baseline_and_evaluation_follow_the_data_law(data):
    from pbmdem.surrogate import cross_validate_models

    base = PhysicalScaling(speed_law="weibull").fit(data.X, data.y, velocity=data.velocity)
    assert np.allclose(
        base.velocity_fractions(data.X.iloc[:3]), speed_fractions(*base.predict_velocity(data.X.iloc[:3]), "weibull")
    )
    with pytest.raises(ValueError, match="another impact-speed law"):
        cross_validate_models(data, {"physical": PhysicalScaling()}, "group_kfold", 3)
