"""Impact-velocity distributions per class pair: reading, two-parameter speed laws and bin fractions.

``results/dem/impact_velocity.csv`` (docs/architecture.md) holds, per run and class pair, the mean
number of encounters per replicate in every bin of :data:`pbmdem.impact.VELOCITY_EDGES`. The
surrogate summarises each pair's binned distribution by a two-parameter law of the impact speed v
(:data:`SPEED_LAWS`), both parametrised the same way, by

    mu = log10 of the median speed (m/s),   sigma = standard deviation of log10 v (decades),

and fitted by maximum likelihood to the bin counts (interval-censored: bin 0 is (0, 1 mm/s), the
last bin is open upwards because faster impacts are counted there):

* ``lognormal``: log10 v ~ Normal(mu, sigma); symmetric in log v, its fast tail falls as
  exp(-(log v)^2 / 2 sigma^2);
* ``weibull``: P(V > v) = exp(-(v / lambda)^k), with k = pi / (sqrt(6) ln(10) sigma) and
  lambda = 10**mu / ln(2)**(1/k); in log v it is skewed towards slow impacts and its fast tail is
  lighter (a stretched exponential in v, as the high-energy tails of driven granular gases,
  exp(-c v^{3/2}), van Noije & Ernst 1998, Granular Matter 1:57-64);
* ``gengamma``: the generalised gamma law (Stacy 1962) in Prentice's (1974, Biometrika 61:539)
  form, with a third parameter, the shape q: log10 v = mu + sigma (W - med W) / sd W with
  W = ln(q^2 G) / q, G ~ Gamma(1 / q^2); q -> 0 is the log-normal, q = 1 the Weibull, q < 0 a
  fast tail heavier than the log-normal's. The DEM's speed distributions need it: their fast tail is
  lighter than the log-normal's at high impeller speeds and heavier than the Weibull's at low ones
  (docs/surrogate.md, "Impact-speed laws").

The surrogate learns ``mu``, ``log10 sigma`` (and q) per pair; :func:`speed_fractions` turns them back
into fractions per bin of the chosen law, so predicted fractions always lie on the project's bins,
are >= 0 and sum to 1. Breakage counts the fraction of impacts faster than a critical speed, i.e.
the fast tail (benchmarks/bench_breakage_tail.py measures it per law).
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from scipy.optimize import minimize
from scipy.special import gammainc, gammaincc, gammaincinv, log_ndtr, ndtr, zeta

from pbmdem.impact import (
    N_VELOCITY_BINS,
    VELOCITY_EDGES,
    VELOCITY_KEYS,
    binned_counts,
    representative_velocities,
    velocity_edge_bin,
)
from pbmdem.readers import InputFileError

from .errors import CollisionTableError

#: Wide columns holding a pair's encounter counts per velocity bin once attached to the collision table.
VELOCITY_COUNT_COLUMNS = tuple(f"vbin{b:02d}" for b in range(N_VELOCITY_BINS))

#: Bounds of the fitted geometric spread sigma (decades). The lower bound is a fifth of a bin width
#: (bins are 0.25 decades): a pair whose encounters all fall into one bin cannot resolve less.
SIGMA_BOUNDS = (0.05, 3.0)

#: The impact-speed laws (module docstring) and their number of parameters (mu, sigma[, q]).
SPEED_LAWS = ("lognormal", "weibull", "gengamma")
LAW_PARAMETERS = {"lognormal": 2, "weibull": 2, "gengamma": 3}
#: Bounds of the generalised gamma's shape q (beyond them the tail bins cannot tell q apart).
SHAPE_BOUNDS = (-2.0, 3.0)
#: |q| below this is the log-normal (the generalised gamma's limit; differences O(q)).
_Q_LOGNORMAL = 1e-3

#: log10 of the inner bin edges; bin 0 starts at -inf (v -> 0), the last bin ends at +inf.
_LOG_EDGES = np.concatenate([[-np.inf], np.log10(VELOCITY_EDGES[1:-1]), [np.inf]])
#: log10 of one representative speed per bin (start values of the fit).
_LOG_CENTRES = np.log10(representative_velocities())


def attach_velocity_bins(
    table: pd.DataFrame, velocity: pd.DataFrame, source: str = "impact-velocity table"
) -> pd.DataFrame:
    """The collision table with one column per velocity bin (:data:`VELOCITY_COUNT_COLUMNS`).

    ``velocity`` is the impact-velocity table (long format, one row per run, pair and bin), read by
    :func:`pbmdem.impact.binned_counts`. Bins a pair lacks count 0; pairs of the collision table
    without any row in ``velocity`` get NaN (no velocity data).
    """
    key = list(VELOCITY_KEYS)
    try:
        pairs, counts = binned_counts(velocity, source)
    except InputFileError as exc:
        raise CollisionTableError(str(exc)) from None
    wide = pd.concat([pairs, pd.DataFrame(counts, columns=list(VELOCITY_COUNT_COLUMNS))], axis=1)
    out = table.drop(columns=[c for c in VELOCITY_COUNT_COLUMNS if c in table.columns]).copy()
    out_key = out[key].astype({"point_id": str, "class_i": int, "class_j": int})
    known = set(map(tuple, out_key.to_numpy().tolist()))
    extra = [k for k in map(tuple, pairs.to_numpy().tolist()) if k not in known]
    if extra:
        raise CollisionTableError(
            f"{source}: pair(s) {extra[:3]} (point_id, class_i, class_j) are not in the collision table"
        )
    merged = out_key.merge(wide, on=key, how="left")
    for col in VELOCITY_COUNT_COLUMNS:
        out[col] = merged[col].to_numpy(float)
    return out


def has_velocity(table: pd.DataFrame) -> bool:
    """True if the table carries velocity bin counts (see :func:`attach_velocity_bins`)."""
    return all(c in table.columns for c in VELOCITY_COUNT_COLUMNS)


def bin_counts(table: pd.DataFrame) -> np.ndarray:
    """(n, N_VELOCITY_BINS) encounter counts per bin of every row (NaN rows: no velocity data)."""
    return table.loc[:, list(VELOCITY_COUNT_COLUMNS)].to_numpy(float)


def velocity_rows(table: pd.DataFrame) -> np.ndarray:
    """Boolean mask of rows with a usable velocity distribution (finite counts, positive total)."""
    if not has_velocity(table):
        return np.zeros(len(table), bool)
    counts = bin_counts(table)
    return np.isfinite(counts).all(axis=1) & (np.nan_to_num(counts).sum(axis=1) > 0)


def empirical_fractions(counts) -> np.ndarray:
    """Counts per bin -> fractions per bin (rows sum to 1)."""
    counts = np.atleast_2d(np.asarray(counts, float))
    total = counts.sum(axis=1, keepdims=True)
    if not (total > 0).all():
        raise ValueError("every row needs a positive total count")
    return counts / total


def check_speed_law(law: str) -> str:
    """``law`` if it is one of :data:`SPEED_LAWS`, else ValueError naming them."""
    if law not in SPEED_LAWS:
        raise ValueError(f"impact-speed law {law!r}; allowed: {list(SPEED_LAWS)}")
    return law


#: pi / sqrt(6): the standard deviation of ln E for E ~ Exp(1) (a Gumbel law of minima)
_GUMBEL_STD = np.pi / np.sqrt(6.0)


def n_law_parameters(law: str) -> int:
    """Parameters per row of the speed law ``law``: 2 (mu, sigma) or 3 (mu, sigma, q)."""
    return LAW_PARAMETERS[check_speed_law(law)]


def _gengamma_standard(q):
    """(a, median, standard deviation) of W = ln(q^2 G) / q, G ~ Gamma(a = 1 / q^2). The trigamma
    function is zeta(2, a), what ``scipy.special.polygamma(1, a)`` computes (times (-1)^2 Gamma(2) = 1),
    without its Python set-up."""
    a = 1.0 / (q * q)
    med = np.log(q * q * gammaincinv(a, 0.5)) / q
    sd = np.sqrt(zeta(2.0, a)) / np.abs(q)
    return a, med, sd


def _log_cdf_sf(x, mu, sigma, law: str, shape=None):
    """log P(log10 v < x) and log P(log10 v > x) of the law (broadcast), each exact in its tail."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        if law == "weibull":  # P(V > v) = exp(-t), t = ln 2 exp(z), z = pi (log10 v - mu) / (sqrt(6) sigma)
            t = np.log(2.0) * np.exp(_GUMBEL_STD * (x - mu) / sigma)
            return np.log(-np.expm1(-t)), -t
        z = (x - mu) / sigma
        if law == "lognormal":
            return log_ndtr(z), log_ndtr(-z)
        full = np.broadcast(x, mu, sigma, shape).shape
        z = np.broadcast_to(z, full)
        # the law's constants per value of q (not per speed: gammaincinv is the costly part)
        q = np.asarray(shape, float)
        normal = np.abs(q) < _Q_LOGNORMAL
        qq = np.where(normal, 1.0, q)
        a, med, sd = _gengamma_standard(qq)
        g = np.exp(qq * (med + z * sd)) / (qq * qq)
        lower, upper = np.log(gammainc(a, g)), np.log(gammaincc(a, g))
        log_cdf, log_sf = np.where(qq > 0, lower, upper), np.where(qq > 0, upper, lower)
        if normal.any():  # the log-normal's rows (element by element: the same numbers where they are taken)
            log_cdf, log_sf = np.where(normal, log_ndtr(z), log_cdf), np.where(normal, log_ndtr(-z), log_sf)
        return np.broadcast_to(log_cdf, full), np.broadcast_to(log_sf, full)


def _log_bin_probabilities(edges, mu, sigma, law: str, shape=None):
    """log P(edges[b] < log10 v < edges[b + 1]) of the law for the consecutive bins of ``edges``
    (last axis; mu, sigma, shape broadcast against it), computed stably in both tails: from the
    distribution function below the median, from the survival function above it. The law is
    evaluated once per edge (each inner edge bounds two bins)."""
    if law == "lognormal":  # the form of the log-normal fits before the other laws (same digits)
        cdf = log_ndtr((edges - mu) / sigma)
        lo, hi = cdf[..., :-1], cdf[..., 1:]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return hi + np.log1p(-np.exp(np.minimum(lo - hi, 0.0)))
    cdf, sf = _log_cdf_sf(edges, mu, sigma, law, shape)
    cdf_lo, sf_lo, cdf_hi, sf_hi = cdf[..., :-1], sf[..., :-1], cdf[..., 1:], sf[..., 1:]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        below = cdf_hi + np.log1p(-np.exp(np.minimum(cdf_lo - cdf_hi, 0.0)))
        above = sf_lo + np.log1p(-np.exp(np.minimum(sf_hi - sf_lo, 0.0)))
        return np.where(sf_lo < np.log(0.5), above, below)


def speed_fractions(mu, sigma, law: str = "lognormal", shape=None) -> np.ndarray:
    """(n, N_VELOCITY_BINS) fraction of the speed law ``law`` (:data:`SPEED_LAWS`) in each velocity bin.

    ``mu``: log10 of the median speed (m/s); ``sigma``: standard deviation of log10 v (decades);
    ``shape``: the generalised gamma's q (``gengamma`` only). Bin 0 takes everything below 1 mm/s,
    the last bin everything from its lower edge up.
    """
    if n_law_parameters(law) == 3 and shape is None:
        raise ValueError(f"the {law} law needs its shape q (speed_fractions(mu, sigma, law, shape))")
    mu = np.atleast_1d(np.asarray(mu, float))[:, None]
    sigma = np.atleast_1d(np.asarray(sigma, float))[:, None]
    if law == "lognormal":
        frac = np.diff(ndtr((_LOG_EDGES[None, :] - mu) / sigma), axis=1)
    else:  # from the log of each bin's probability: exact in the fast tail that breakage counts
        # a predicted shape beyond the fitted range (an extrapolating or widened member) is held at its bound
        q = None if shape is None else np.clip(np.atleast_1d(np.asarray(shape, float)), *SHAPE_BOUNDS)[:, None]
        frac = np.exp(_log_bin_probabilities(_LOG_EDGES[None, :], mu, sigma, law, q))
    # NaN -> 0 and negatives -> 0 (np.nan_to_num and np.clip without their Python set-up; the laws' bin
    # probabilities are at most 1, never infinite)
    frac = np.maximum(np.where(np.isnan(frac), 0.0, frac), 0.0)
    return frac / frac.sum(axis=1, keepdims=True)


def _neg_loglik(theta, counts, law: str = "lognormal", first: int = 0):
    """Negative log-likelihood of the bin ``counts``; with ``first`` > 0 the bins below bin ``first``
    are one cell, P(v < edge ``first``) (:func:`fit_speed_law`'s ``fit_from``)."""
    mu, log_sigma = theta[:2]
    shape = theta[2] if len(theta) > 2 else None
    logp = _log_bin_probabilities(_LOG_EDGES, mu, np.exp(log_sigma), law, shape)
    logp = np.where(counts > 0, np.nan_to_num(logp, nan=-745.0, neginf=-745.0), 0.0)
    if first == 0:
        return -float(np.sum(counts * np.maximum(logp, -745.0)))
    below = float(np.sum(counts[:first]))
    log_below = 0.0
    if below > 0:
        log_cdf = _log_cdf_sf(_LOG_EDGES[first], mu, np.exp(log_sigma), law, shape)[0]
        log_below = max(float(np.nan_to_num(log_cdf, nan=-745.0)), -745.0)
    return -(below * log_below + float(np.sum(counts[first:] * np.maximum(logp[first:], -745.0))))


def fit_from_bin(fit_from: float | None, key: str = "surrogate.speed_law_from") -> int:
    """The bin from which :func:`fit_speed_law` resolves the bins (0: every bin) for ``fit_from``
    (m/s, an inner edge of :data:`~pbmdem.impact.VELOCITY_EDGES`, or None; :func:`pbmdem.impact.velocity_edge_bin`)."""
    return velocity_edge_bin(fit_from, key)


def fit_speed_law(counts, law: str = "lognormal", fit_from: float | None = None) -> tuple[np.ndarray, ...]:
    """Maximum-likelihood fit of the speed law ``law`` (:data:`SPEED_LAWS`) to binned counts, one per row.

    ``fit_from`` (m/s, an inner bin edge; None: every bin): the bins below it count as one cell,
    the impacts slower than ``fit_from``, so that the law describes P(V > v) from ``fit_from`` up,
    the fast tail that breakage counts, rather than the slow bulk (docs/surrogate.md, "Impact-speed
    laws"); mu and sigma are then the fitted law's, not the bulk's median and spread.

    Returns ``(mu, sigma)`` (``(mu, sigma, q)`` for ``gengamma``): log10 median speed (m/s),
    standard deviation of log10 v (decades) within :data:`SIGMA_BOUNDS`, and the shape q within
    :data:`SHAPE_BOUNDS`. Counts may be non-integer (means over replicates): they act as weights of
    the multinomial likelihood.
    """
    n_par = n_law_parameters(law)
    first = fit_from_bin(fit_from)
    counts = np.atleast_2d(np.asarray(counts, float))
    if counts.shape[1] != N_VELOCITY_BINS:
        raise ValueError(f"expected {N_VELOCITY_BINS} bins per row, got {counts.shape[1]}")
    if not (np.isfinite(counts).all() and (counts >= 0).all()):
        raise ValueError("bin counts must be finite and >= 0")
    out = np.empty((n_par, len(counts)))
    log_bounds = (np.log(SIGMA_BOUNDS[0]), np.log(SIGMA_BOUNDS[1]))
    bounds = [(np.log10(VELOCITY_EDGES[1]) - 3.0, np.log10(VELOCITY_EDGES[-1]) + 3.0), log_bounds, SHAPE_BOUNDS]
    for r, c in enumerate(counts):
        w = c / c.sum()
        m0 = float(np.dot(w, _LOG_CENTRES))
        s0 = float(np.clip(np.sqrt(np.dot(w, (_LOG_CENTRES - m0) ** 2) + 0.25**2 / 12), *SIGMA_BOUNDS))
        starts = [[m0, np.log(s0)]]
        if n_par == 3:  # the generalised gamma from the likeliest of a log-normal, a Weibull and a heavy tail
            starts = [min(([m0, np.log(s0), q0] for q0 in (0.01, 1.0, -0.5)), key=lambda x: _neg_loglik(x, w, law))]
        if first:  # the tail's fit from the law fitted to every bin, and from it with each start shape
            bulk = [float(v[0]) for v in fit_speed_law(w, law)]
            bulk[1] = np.log(bulk[1])
            starts = [bulk] + ([bulk[:2] + [q0] for q0 in (0.01, 1.0, -0.5)] if n_par == 3 else [])
        # beyond the log-normal, converged tightly: the looser default stops where another BLAS
        # kernel's rounding moves a flat likelihood's optimum by 1e-4 (tests/test_surrogate_families.py)
        options = {} if law == "lognormal" and not first else {"ftol": 1e-15, "gtol": 1e-10, "maxiter": 2000}
        fits = [
            minimize(
                _neg_loglik, x0=x0, args=(w, law, first), method="L-BFGS-B", bounds=bounds[:n_par], options=options
            )
            for x0 in starts
        ]
        best = min(fits, key=lambda f: f.fun if np.isfinite(f.fun) else np.inf)
        if not best.success and not np.isfinite(best.fun):
            warnings.warn(f"{law} fit of velocity row {r} did not converge: {best.message}", stacklevel=2)
        out[:, r] = best.x
        out[1, r] = np.exp(best.x[1])
    return tuple(out)


def total_variation(p, q) -> np.ndarray:
    """Total-variation distance 0.5 sum |p - q| of fraction rows (0: identical, 1: disjoint)."""
    return 0.5 * np.abs(np.asarray(p, float) - np.asarray(q, float)).sum(axis=-1)


#: Impact speeds (m/s) whose exceedance fractions score an impact-speed law for breakage: the bin
#: edges from 1 m/s up. The critical speed of breakage sqrt(2 Y St*/rho) is 2 m/s at the default
#: strength and rises 4x as a granule consolidates (docs/pbm.md); the fast tail is what breakage reads.
TAIL_SPEEDS = tuple(float(e) for e in VELOCITY_EDGES[1:-1] if e >= 1.0)


def tail_error(predicted, observed, speeds=TAIL_SPEEDS) -> np.ndarray:
    """Per row of bin fractions (:data:`pbmdem.impact.VELOCITY_EDGES`): the mean over ``speeds`` of
    |log10(predicted / observed fraction of impacts faster than the speed)|, over the speeds where
    the observed fraction is above zero (NaN for a row without any)."""
    predicted, observed = np.atleast_2d(predicted), np.atleast_2d(observed)
    lo = np.asarray(VELOCITY_EDGES[:-1], float)
    errors = []
    for v in speeds:
        above = lo >= v - 1e-12
        p, o = predicted[:, above].sum(axis=1), observed[:, above].sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            errors.append(np.where(o > 0, np.abs(np.log10(np.maximum(p, 1e-300) / o)), np.nan))
    errors = np.column_stack(errors)
    out = np.full(len(errors), np.nan)
    ok = np.isfinite(errors).any(axis=1)
    out[ok] = np.nanmean(errors[ok], axis=1)
    return out
