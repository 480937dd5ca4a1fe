"""The PBM's compiled breakage selection from impacts (numba): the critical impact speed v* of
every pivot (strength by size and porosity), the breaking probability per velocity bin, and the
selection rate summed over the impacts of pairs and walls. ``_compiled`` re-exports these for its
callers (``impact_breakage.ImpactSelection``, the compiled step loop ``_compiled_steps``).
Imported with ``_compiled``, never inside a run (explicit signatures, numba's on-disk cache).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# ----------------------------------------------------------------- breakage selection from impacts
# ``impact_breakage.ImpactSelection`` evaluates these at every refresh of the selection (about once
# per step); the numpy form (``pbmdem.impact.breaking_probability``, ``impact_breakage.selection_rates``)
# stays the readable definition and the test oracle (tests/test_impact_breakage.py).

_SQRT_HALF = math.sqrt(0.5)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
#: |z| beyond which Phi(z) is taken as 0 or 1 (Phi(-20) = 2.8e-89): the breaking probability of a
#: bin far below or above v* is 0 or 1 to 88 digits, and the transcendental functions are skipped
_Z_SATURATED = 20.0


@njit("f8(f8)", cache=True, nogil=True)
def _phi(z):
    """The standard normal distribution function Phi(z) (0 below -20, 1 above 20)."""
    if z <= -_Z_SATURATED:
        return 0.0
    if z >= _Z_SATURATED:
        return 1.0
    return 0.5 * math.erfc(-z * _SQRT_HALF)


@njit("f8(f8)", cache=True, nogil=True)
def _phi_integral(z):
    """The antiderivative of Phi: z Phi(z) + phi(z) (0 below -20, z above 20)."""
    if z <= -_Z_SATURATED:
        return 0.0
    if z >= _Z_SATURATED:
        return z
    return z * 0.5 * math.erfc(-z * _SQRT_HALF) + math.exp(-0.5 * z * z) * _INV_SQRT_2PI


@njit("void(f8[::1], f8, f8[::1], f8[:, ::1])", cache=True, nogil=True)
def breaking_probability(v_star, spread, edges, out):
    """``out[i, b]``: the mean probability that an impact of velocity bin b (``edges``, m/s: bin 0
    [0, edges[1]), log bins above) breaks a granule whose median critical speed is ``v_star[i]``
    (m/s), with log-normal strengths of standard deviation ``spread`` of ln Y (0: the sharp
    criterion); :func:`pbmdem.impact.breaking_probability`. Impacts spread evenly in log v inside
    a log bin (the bin mean of Phi(a ln(v / v*)) is then exact: the difference of the antiderivative
    at the bin's edges over their distance in z), evenly in v in bin 0 (64-point midpoint rule);
    the last bin ends at its upper edge. The logarithms of the edges are taken once per call (of
    bin 0's 64 points only if a granule needs them) and the antiderivative once per edge. Bin 0
    of a granule whose Phi is saturated (0) at its fastest midpoint is 0 without its 64 points
    (they rise with m, and so does z: all saturated, their sum 0)."""
    V = edges.size - 1
    log_edges = np.empty(V + 1)
    for e in range(1, V + 1):
        log_edges[e] = math.log(edges[e])
    log_v0 = np.empty(64)  # taken when a granule first needs them (bin 0 not saturated: rare)
    have_v0 = False
    top = math.log((63 + 0.5) / 64 * edges[1])  # log_v0[63]
    integral = np.empty(V + 1)
    z = np.empty(V + 1)
    for i in range(v_star.size):
        s = v_star[i]
        if i > 0 and s == v_star[i - 1]:  # the same v* as the granule before (empty pivots: v* of eps_ref)
            for b in range(V):
                out[i, b] = out[i - 1, b]
            continue
        if spread == 0.0:
            for b in range(V):
                lo = edges[b]
                hi = edges[b + 1]
                if s <= lo:
                    out[i, b] = 1.0
                elif s < hi:
                    out[i, b] = math.log(hi / s) / math.log(hi / lo) if lo > 0 else (hi - s) / hi
                else:
                    out[i, b] = 0.0
            continue
        a = 2.0 / spread
        log_s = math.log(s)
        first = 0.0
        if a * (top - log_s) > -_Z_SATURATED:
            if not have_v0:
                for m in range(64):
                    log_v0[m] = math.log((m + 0.5) / 64 * edges[1])
                have_v0 = True
            for m in range(64):
                first += _phi(a * (log_v0[m] - log_s))
        out[i, 0] = min(max(first / 64, 0.0), 1.0)
        for e in range(1, V + 1):
            z[e] = a * (log_edges[e] - log_s)
            integral[e] = _phi_integral(z[e])
        for b in range(1, V):
            p = (integral[b + 1] - integral[b]) / (z[b + 1] - z[b])
            out[i, b] = min(max(p, 0.0), 1.0)


@njit(
    "void(f8[:, ::1], f8[:, :, ::1], i8[::1], f8[:, ::1], f8[:, :, ::1], f8[:, ::1], f8[::1], b1, f8[::1])",
    cache=True,
    nogil=True,
)
def impact_selection(frequency, fractions, columns, wall_frequency, wall_fractions, probability, numbers, pairs, out):
    """``out[i]``: the breaking impacts per granule and second of class i (1/s),

        S_i = sum_j c_ij max(N_j - delta_ij, 0) sum_b f_ijb P_ib  +  sum_w f_wi sum_b f_wib P_ib,

    with the pair encounter ``frequency`` (K, K) per pair and its velocity ``fractions`` (K, K, V)
    (only if ``pairs``), the impacts per granule on the walls ``wall_frequency`` (W, K) and their
    ``wall_fractions`` (W, K, V), and the breaking ``probability`` (K, V) of
    :func:`breaking_probability`; ``numbers`` (K,) the granules of each class. ``columns`` (K,):
    for each partner j the first partner whose fractions ``fractions[:, j, :]`` are the same to the
    bit (:func:`fraction_columns`; a coupling interval's bins take the fractions of
    their nearest class, so a few classes serve all bins): the sum over the velocity bins is taken once per
    such column and row, the same operations on the same numbers, so the same result to the bit.
    The sums of four such columns run side by side over the bins (each in the bins' order, from
    0; every distinct column of the partners present, used or not): the same sums, about 25 %
    faster than one after the other (a refresh of the default batch's 46 bins)."""
    K = numbers.size
    V = probability.shape[1]
    W = wall_frequency.shape[0]
    present = np.empty(K, dtype=np.int64)
    n_present = 0
    for j in range(K):
        if not numbers[j] <= 0.0:
            present[n_present] = j
            n_present += 1
    used = np.empty(K, dtype=np.int64)  # the distinct columns of the partners present
    n_used = 0
    if pairs:
        seen = np.zeros(K, dtype=np.bool_)
        for jj in range(n_present):
            c = columns[present[jj]]
            if not seen[c]:
                seen[c] = True
                used[n_used] = c
                n_used += 1
    dots = np.empty(K)
    walls = np.empty(max(W, 1))
    for i in range(K):
        # four sums over the bins side by side (each in the bins' order, from 0.0)
        for u0 in range(0, n_used, 4):
            n4 = min(4, n_used - u0)
            c0 = used[u0]
            c1 = used[u0 + 1] if n4 > 1 else c0
            c2 = used[u0 + 2] if n4 > 2 else c0
            c3 = used[u0 + 3] if n4 > 3 else c0
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            s3 = 0.0
            for b in range(V):
                p = probability[i, b]
                s0 += fractions[i, c0, b] * p
                s1 += fractions[i, c1, b] * p
                s2 += fractions[i, c2, b] * p
                s3 += fractions[i, c3, b] * p
            dots[c0] = s0
            if n4 > 1:
                dots[c1] = s1
            if n4 > 2:
                dots[c2] = s2
            if n4 > 3:
                dots[c3] = s3
        for w in range(W):
            breaking = 0.0
            for b in range(V):
                breaking += wall_fractions[w, i, b] * probability[i, b]
            walls[w] = breaking
        total = 0.0
        if pairs:
            for jj in range(n_present):
                j = present[jj]
                partners = numbers[j] - 1.0 if i == j else numbers[j]
                if partners <= 0.0 or frequency[i, j] == 0.0:
                    continue
                total += frequency[i, j] * dots[columns[j]] * partners
        for w in range(W):
            total += wall_frequency[w, i] * walls[w]
        out[i] = total


@njit("i8[::1](f8[:, :, ::1])", cache=True, nogil=True)
def fraction_columns(fractions):
    """For each partner j of the pair velocity ``fractions`` (K, K, V) the first partner of the run
    of neighbours j' <= j whose columns ``fractions[:, j', :]`` equal column j to the bit, each pair
    of neighbours compared until they differ (the numpy form, the test oracle in
    tests/test_impact_breakage.py, compares every entry: about 0.1 ms per coupling interval)."""
    K = fractions.shape[1]
    out = np.empty(K, dtype=np.int64)
    start = 0
    for j in range(K):
        if j > 0:
            for i in range(fractions.shape[0]):
                differ = False
                for b in range(fractions.shape[2]):
                    if not fractions[i, j, b] == fractions[i, j - 1, b]:
                        differ = True
                        break
                if differ:
                    start = j
                    break
        out[j] = start
    return out


#: the strength parameters of :func:`selection_of_impacts`, in this order
STRENGTH_FIELDS = ("speed", "size_exponent", "reference_diameter", "porosity_exponent", "reference_porosity", "limit")


@njit("void(f8[::1], f8[::1], f8[::1], f8[::1])", cache=True, nogil=True)
def critical_speeds(diameters, porosity, strength, out):
    """``out[i]``: v* (m/s) of a granule of ``diameters[i]`` and ``porosity[i]`` (``porosity``
    empty: every granule at the reference porosity; NaN: a pivot without granules, the reference
    porosity), with ``strength`` of :data:`STRENGTH_FIELDS`: v*_ref (Y at d_ref, eps_ref) scaled by
    (d / d_ref)^(-e/2) and [((1 - eps) / eps) / ((1 - eps_ref) / eps_ref)]^(n/2), eps clipped to
    [limit, 1 - limit] (the numpy form: ``critical_speeds`` in tests/test_impact_breakage.py)."""
    speed, e, d_ref, n, eps_ref, limit = strength[0], strength[1], strength[2], strength[3], strength[4], strength[5]
    ref = (1.0 - eps_ref) / eps_ref
    for i in range(diameters.size):
        v = speed
        if e != 0.0:
            v = speed * (diameters[i] / d_ref) ** (-0.5 * e)
        if n != 0.0 and porosity.size > 0:
            eps = porosity[i] if np.isfinite(porosity[i]) else eps_ref
            eps = min(max(eps, limit), 1.0 - limit)
            ratio = ((1.0 - eps) / eps) / ref
            # n = 2 (the default): ratio ** 1 is ratio (pow within 1 ULP of an exact result), without the call
            v = v * (ratio if n == 2.0 else ratio ** (0.5 * n))
        out[i] = v


@njit(
    "void(f8[::1], f8[::1], f8[::1], f8, f8[::1], f8[:, ::1], f8[:, :, ::1], i8[::1], f8[:, ::1], f8[:, :, ::1], "
    "f8[::1], b1, f8[::1], f8[:, ::1], f8[::1])",
    cache=True,
    nogil=True,
)
def selection_of_impacts(
    diameters,
    porosity,
    strength,
    spread,
    edges,
    frequency,
    fractions,
    columns,
    wall_frequency,
    wall_fractions,
    numbers,
    pairs,
    speeds,
    probability,
    out,
):
    """The breakage selection rate of every pivot from its impacts in one call: :func:`critical_speeds`
    into ``speeds``, :func:`breaking_probability` into ``probability`` and :func:`impact_selection`
    into ``out`` (``ImpactSelection.__call__``)."""
    critical_speeds(diameters, porosity, strength, speeds)
    breaking_probability(speeds, spread, edges, probability)
    impact_selection(frequency, fractions, columns, wall_frequency, wall_fractions, probability, numbers, pairs, out)
