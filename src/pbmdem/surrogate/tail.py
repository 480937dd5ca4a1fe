"""The pooled fast tail of the impact speeds: one law above a speed for every pair and run.

A speed law fitted to one pair's bins (:mod:`pbmdem.surrogate.velocity`) has its shape set by the
slow bulk; breakage reads the last per mille above 2-8 m/s, where one pair of one DEM run holds a
handful of impacts. Above a speed v_s (``surrogate.speed_tail_from``) the surrogate therefore uses

    P(V > v | V > v_s) = exp(-a [(v / v_tip)^beta - (v_s / v_tip)^beta]),   v >= v_s,

one stretched exponential in units of the impeller tip speed v_tip, fitted by maximum likelihood
to every pair of every run at once (:func:`fit_speed_tail`), and scaled to each pair's own share of
impacts above v_s, which its law predicts well (:func:`with_speed_tail`). Impacts above v_s are
driven by the impeller, whose speed sets their scale; high-energy tails of driven granular gases are
stretched exponentials (van Noije & Ernst 1998, Granular Matter 1:57-64). Evidence and limits:
docs/surrogate.md, "The pooled fast tail".
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from pbmdem.impact import VELOCITY_EDGES

from .velocity import fit_from_bin, speed_fractions


def _tail_survival(v, tip_speed, first: int, a: float, beta: float):
    """P(V > v | V > the lower edge of bin ``first``) of :func:`fit_speed_tail`'s law (broadcast)."""
    u = lambda x: (np.asarray(x, float) / tip_speed) ** beta  # noqa: E731
    with np.errstate(over="ignore", invalid="ignore"):
        return np.where(np.isinf(v), 0.0, np.exp(-a * (u(np.where(np.isinf(v), 1.0, v)) - u(VELOCITY_EDGES[first]))))


def _tail_bins(tip_speed, first: int, a: float, beta: float) -> np.ndarray:
    """(n, bins from ``first`` up) conditional fractions of the tail law at each row's tip speed."""
    t = np.asarray(tip_speed, float).reshape(-1, 1)
    # the survival at each lower edge; a bin's upper edge is the next one's lower edge, the last's is inf (0)
    lower = _tail_survival(VELOCITY_EDGES[first:-1], t, first, a, beta)
    upper = np.zeros_like(lower)
    upper[:, :-1] = lower[:, 1:]
    return lower - upper


#: Impacts from the tail's speed up that a run needs for its own scale a_r (:func:`fit_speed_tail`'s
#: spread): with 100, Poisson noise alone spreads ln a_r by about 0.1 or less.
TAIL_RUN_MIN_COUNTS = 100

#: A row (class pair and run) enters the pooled fit only if v_s is at most this many times its tip
#: speed. The law is written in tip-speed units because the impeller drives the fast impacts; a run
#: whose v_s lies far above its own tip speed holds, at most, a few impacts from rare events that
#: the impeller's scale does not describe (pinching in the blade-bowl gap), and 1/v_tip-scaled they
#: dominate the shape (docs/surrogate.md, "The pooled fast tail"). Twice v_tip is a scale argument,
#: not a bound: a blade-struck granule leaves at up to about (1 + e) v_tip, e <= 1.
TAIL_MAX_TIP_MULTIPLE = 2.0


def _neg_loglik(log_a: float, counts, tip, first: int, beta: float) -> float:
    """Negative log-likelihood of the tail ``counts`` (n, bins from ``first`` up) at a = exp(log_a)."""
    return -float(np.sum(counts * np.log(np.maximum(_tail_bins(tip, first, np.exp(log_a), beta), 1e-300))))


def fit_speed_tail(counts, tip_speed, tail_from: float, groups=None) -> tuple[int, float, float, float] | None:
    """The fast tail of the impact speeds, pooled over every row (class pair and run): maximum
    likelihood of the bin ``counts`` (n, bins) from the speed ``tail_from`` up (m/s, an inner bin
    edge, :func:`fit_from_bin`) under

        P(V > v | V > v_s) = exp(-a [(v / v_tip)^beta - (v_s / v_tip)^beta]),   v >= v_s,

    with v_tip each row's impeller ``tip_speed`` (m/s): one stretched exponential in tip-speed units
    for every pair and run (docs/surrogate.md, "The pooled fast tail"). A single pair's tail holds a
    handful of impacts (at 1200 rpm about 1 in 750 pair impacts is faster than 3.16 m/s); pooled, the
    grid's holds thousands. The spread is the standard deviation of ln a_r over the runs (``groups``)
    with at least :data:`TAIL_RUN_MIN_COUNTS` impacts from ``tail_from`` up, a_r each run's own scale
    at the pooled beta: how far one bed's tail departs from the pooled one (0 with fewer than two
    such runs); the surrogate's members scale a by exp(-z spread). Returns (bin of ``tail_from``, a,
    beta, spread), or None without any count from ``tail_from`` up (the tail stays the speed law's).
    Rows whose ``tail_from`` exceeds :data:`TAIL_MAX_TIP_MULTIPLE` times their tip speed are left out."""
    first = fit_from_bin(tail_from, "surrogate.speed_tail_from")
    counts = np.atleast_2d(np.asarray(counts, float))[:, first:]
    tip = np.asarray(tip_speed, float).ravel()
    groups = np.zeros(len(tip)) if groups is None else np.asarray(groups).ravel()
    keep = (counts.sum(axis=1) > 0) & (tip * TAIL_MAX_TIP_MULTIPLE >= VELOCITY_EDGES[first])
    if not keep.any():
        return None
    counts, tip, groups = counts[keep], tip[keep], groups[keep]

    def nll(theta):
        return _neg_loglik(theta[0], counts, tip, first, np.exp(theta[1]))

    best = min(
        (
            minimize(nll, x0=[np.log(a0), 0.0], method="Nelder-Mead", options={"xatol": 1e-8, "fatol": 1e-10})
            for a0 in (1.0, 10.0)
        ),
        key=lambda f: f.fun,
    )
    a, beta = float(np.exp(best.x[0])), float(np.exp(best.x[1]))
    log_a = []
    for g in np.unique(groups):
        rows = groups == g
        if counts[rows].sum() >= TAIL_RUN_MIN_COUNTS:
            fit = minimize_scalar(
                _neg_loglik,
                bounds=(np.log(a) - 5.0, np.log(a) + 5.0),
                args=(counts[rows], tip[rows], first, beta),
                method="bounded",
                options={"xatol": 1e-8},
            )
            log_a.append(fit.x)
    return first, a, beta, float(np.std(log_a, ddof=1)) if len(log_a) >= 2 else 0.0


def with_speed_tail(fractions, tip_speed, tail) -> np.ndarray:
    """Bin ``fractions`` (n, bins) of a speed law with the bins from the tail's speed up replaced by
    the pooled tail ``tail`` = (bin, a, beta[, spread]) of :func:`fit_speed_tail` (None: unchanged), scaled to
    the law's own fraction above that speed: P(V > v_s) is the law's (per pair), its shape above is
    the tail's. a and beta may also be (n, 1) columns, one tail per row (element by element the same numbers)."""
    if tail is None:
        return fractions
    first, a, beta = tail[:3]
    out = np.array(fractions, float)
    above = out[:, first:].sum(axis=1, keepdims=True)
    out[:, first:] = above * _tail_bins(tip_speed, first, a, beta)
    return out


def member_tail(tail, z: float):
    """The tail of the surrogate's member at the standard-normal quantile ``z``: a times
    exp(-z spread), the bed-to-bed spread of :func:`fit_speed_tail` (z > 0: a heavier tail, more
    fast impacts, as the member's frequency and speed law); None stays None."""
    if tail is None:
        return None
    first, a, beta, spread = tail
    return first, a * float(np.exp(-z * spread)), beta, spread


def law_fractions(laws) -> list[np.ndarray]:
    """Bin fractions of several models' speed laws with their pooled tails, each entry ``(speed
    law, tip speeds, mu, sigma, shape or None, tail or None)`` (the pairs' and the walls' of
    ``CollisionSurrogate.impacts``): the laws of one name in one
    :func:`~.velocity.speed_fractions` call and the tails that start at one bin in one
    :func:`with_speed_tail` call, each row with its model's a and beta. Both evaluate row by row,
    element by element: the same numbers as a call per model, their fixed cost paid once."""
    out = [None] * len(laws)
    for law in dict.fromkeys(entry[0] for entry in laws):
        idx = [i for i, entry in enumerate(laws) if entry[0] == law]
        mu, sigma, shape = ([laws[i][2 + p] for i in idx] for p in range(3))
        shape = None if any(q is None for q in shape) else np.concatenate(shape)
        frac = speed_fractions(np.concatenate(mu), np.concatenate(sigma), law, shape)
        tails, start = {}, 0  # first bin of a tail -> the rows, tip speeds, a and beta of its models
        for i in idx:
            tip, rows, tail = laws[i][1], len(laws[i][2]), laws[i][5]
            if tail is not None:
                first, a, beta = tail[:3]
                part = tails.setdefault(first, ([], [], [], []))
                part[0].append(np.arange(start, start + rows))
                part[1].append(tip)
                part[2].append(np.full(rows, a))
                part[3].append(np.full(rows, beta))
            start += rows
        for first, (rows, tip, a, beta) in tails.items():
            rows = np.concatenate(rows)
            tail = (first, np.concatenate(a)[:, None], np.concatenate(beta)[:, None])
            frac[rows] = with_speed_tail(frac[rows], np.concatenate(tip), tail)
        start = 0
        for i in idx:
            out[i] = frac[start : start + len(laws[i][2])]
            start += len(out[i])
    return out
