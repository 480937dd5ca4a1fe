"""Compiled (numba) rates of the PBM: aggregation over the ordered class pairs, spraying and
consolidation, and the small vector operations of the step control.

At the default grid (37 pivots + 3 feed classes) an aggregation evaluation is 1600 ordered
pairs: a few microseconds of arithmetic, but about 25 numpy calls of 1-2 us each on the sparse
map of ``aggregation.PivotAggregation`` (kept as the reference, ``totals_numpy``;
``tests/test_pbm_compiled.py`` compares the two). Every sum adds the same products in the same
order as the sparse map's rows, so the two agree to the bit.

It is imported by ``aggregation`` when an operator is built (so ``import pbmdem.pbm`` does not
import numba), and its functions have explicit signatures: they are compiled, or loaded from
numba's on-disk cache (``cache=True``, in ``__pycache__`` beside this file), when this module is
imported, never inside a run.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: success models of a factored kernel (``Kernel.factors``): p = 1, the step, the logistic
ALWAYS, STEP, LOGISTIC = 0, 1, 2

_SIGNATURE = "f8(f8[:, ::1], f8[::1], b1, f8[:, ::1], i8, b1, i8[::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1])"


@njit(_SIGNATURE, cache=True, nogil=True)
def aggregation_totals(beta, p, use_p, nlg, K, cell_average, target, weight, factors, work, d):
    """Rates of change ``d`` (3, M) of number, liquid and gas of the M classes, and the refused
    solid rate (returned, x_0 units), from the kernel and the class totals ``nlg`` (3, M) =
    (N, L, G); loops over the M^2 ordered pairs, without a sparse map. The kernel is ``beta``
    (M, M), or with ``use_p`` beta_ij p_i p_j (a factored kernel, ``Kernel.factors``; formed as
    ``beta * outer(p, p)`` would be).

    Ordered pair (i, j), flat index i M + j: ``target`` the cell (cell average) or the lower pivot
    (fixed pivot) of its aggregate, -1 if beyond the grid; ``weight[0]`` s/x_c - 1 (cell
    average) or the upper pivot's number share (fixed pivot), or the aggregate volume s for a
    refused pair; ``weight[1]`` the upper pivot's solid share (fixed pivot). ``factors`` (4, K):
    the cell-average split factors x_c/(x_(c+1) - x_c), -x_c/(x_c - x_(c-1)), x_(c+1)/x_c,
    x_(c-1)/x_c. ``work`` (10, K): work array.

    The rates: an event of the pair (i, j) occurs at R_ij = beta_ij N_i N_j (i < j; R_ii / 2 for
    i = i, so every ordered pair counts half), removes one particle of each partner with its
    liquid and gas (class i loses N_i, L_i, G_i x sum_j beta_ij N_j over the pairs within the
    grid) and gives birth to an aggregate carrying l_i + l_j and g_i + g_j (sum over both orders
    of beta_ij L_i N_j is the liquid born).
    """
    M = nlg.shape[1]
    born = work[:4]  # rows: number, liquid, gas born per cell, first moment D_c
    split = work[4:]
    for r in range(4):
        for c in range(K):
            born[r, c] = 0.0
    refused = 0.0
    for i in range(M):
        Ni = nlg[0, i]
        Li = nlg[1, i]
        Gi = nlg[2, i]
        dN = 0.0  # deaths: sum over the pairs within the grid of R_ij, RL_ij, RG_ij
        dL = 0.0
        dG = 0.0
        row = i * M
        pi = p[i]
        for j in range(M):
            if use_p:
                q = (beta[i, j] * (pi * p[j])) * nlg[0, j]
            else:
                q = beta[i, j] * nlg[0, j]
            R = Ni * q  # R_ij; RL_ij = L_i q, RG_ij = G_i q
            t = target[row + j]
            if t < 0:
                refused += 0.5 * weight[0, row + j] * R
                continue
            RL = Li * q
            RG = Gi * q
            dN += R
            dL += RL
            dG += RG
            if cell_average:
                h = 0.5 * R  # every ordered pair counts half an event
                born[0, t] += h
                born[3, t] += h * weight[0, row + j]
                born[1, t] += RL
                born[2, t] += RG
            else:
                h = 0.5 * R
                up = weight[0, row + j]
                us = weight[1, row + j]
                born[0, t] += h * (1.0 - up)
                born[0, t + 1] += h * up
                born[1, t] += RL * (1.0 - us)
                born[1, t + 1] += RL * us
                born[2, t] += RG * (1.0 - us)
                born[2, t + 1] += RG * us
        d[0, i] = -dN
        d[1, i] = -dL
        d[2, i] = -dG
    if not cell_average:
        for b in range(3):
            for c in range(K):
                d[b, c] += born[b, c]
        return refused
    # cell average: the births B_c of cell c, with first moment D_c about its pivot (in units of
    # x_c), move up (D_c > 0) or down (D_c < 0) so that number and solid are exact; liquid and gas
    # follow the solid each pivot receives. split[b] / split[3 + b]: what moves up / down of b.
    cu = factors[0]
    ncd = factors[1]
    ru = factors[2]
    rd = factors[3]
    for c in range(K):
        D = born[3, c]
        up = max(D, 0.0) * cu[c]
        down = min(D, 0.0) * ncd[c]
        V = born[0, c] + D  # solid born, units of x_c
        inv = 1.0 / V if V > 0 else 0.0
        split[0, c] = up
        split[3, c] = down
        fu = up * ru[c] * inv
        fd = down * rd[c] * inv
        for b in (1, 2):
            split[b, c] = born[b, c] * fu
            split[3 + b, c] = born[b, c] * fd
    for b in range(3):
        for c in range(K):
            o = (born[b, c] - split[b, c]) - split[3 + b, c]
            if c > 0:
                o += split[b, c - 1]
            if c < K - 1:
                o += split[3 + b, c + 1]
            d[b, c] += o
    return refused


@njit("void(f8[:, ::1], f8[:, ::1], f8, f8[::1], f8, f8[::1])", cache=True, nogil=True)
def add_processes(d, nlg, spray_rate, spray_weight, consolidation_rate, gas_min):
    """Add to the rates ``d`` (3, M) the binder spraying (``spray_rate`` shared in proportion to
    N_k w_k; 0: not spraying) and the consolidation -c (G_k - gas_min_k N_k) (c = 0: none)."""
    M = nlg.shape[1]
    if spray_rate > 0:
        total = 0.0
        for k in range(M):
            total += nlg[0, k] * spray_weight[k]
        if total > 0:
            f = spray_rate / total
            for k in range(M):
                d[1, k] += f * (nlg[0, k] * spray_weight[k])
    if consolidation_rate > 0:
        for k in range(M):
            d[2, k] -= consolidation_rate * (nlg[2, k] - gas_min[k] * nlg[0, k])


# ----------------------------------------------------------------- helpers of the time integration
# Each replaces 2-6 numpy calls on the (3M,) state by one; elementwise the same operations, so
# the same result to the bit.


@njit("void(f8[:, ::1], f8[::1], f8[::1])", cache=True, nogil=True)
def surface_fraction(nlg, xc, out):
    """Surface-liquid fraction max(L - G, 0) / (N x + max(L, G)) of every class (0 if empty)."""
    for k in range(nlg.shape[1]):
        L = nlg[1, k]
        G = nlg[2, k]
        V = nlg[0, k] * xc[k] + max(L, G)
        out[k] = max(L - G, 0.0) / V if V > 0 else 0.0


@njit("b1(f8[::1], f8[::1])", cache=True, nogil=True)
def below_flush(u, level):
    """True if an entry lies strictly between 0 and its flush level."""
    for k in range(u.size):
        if 0.0 < u[k] < level[k]:
            return True
    return False


@njit("void(f8[::1], i8, f8, f8)", cache=True, nogil=True)
def flush(u, M, flush_n, flush_v):
    """Zero (in place) the entries of u = [N, L, G] (3M,) below their flush level; a class whose
    number is flushed loses its liquid and gas with it."""
    for k in range(M):
        if u[k] < flush_n:
            u[k] = 0.0
            u[M + k] = 0.0
            u[2 * M + k] = 0.0
    for k in range(M, 3 * M):
        if u[k] < flush_v:
            u[k] = 0.0


@njit("f8(f8[::1], f8[::1])", cache=True, nogil=True)
def depletion_time(u, rate):
    """min over the entries with rate < 0 of u / -rate (inf if none)."""
    t = np.inf
    for k in range(u.size):
        if rate[k] < 0:
            t = min(t, u[k] / -rate[k])
    return t


@njit("f8(f8[::1], f8[::1], f8, f8[::1])", cache=True, nogil=True)
def error_norm(u_new, u_low, rtol, floor):
    """max over the entries of |u_new - u_low| / (rtol u_new + floor) (the scaled local error)."""
    e = 0.0
    for k in range(u_new.size):
        e = max(e, abs(u_new[k] - u_low[k]) / (rtol * u_new[k] + floor[k]))
    return e


@njit("b1(f8[::1])", cache=True, nogil=True)
def any_negative(u):
    for k in range(u.size):
        if u[k] < 0:
            return True
    return False


@njit("b1(f8[::1])", cache=True, nogil=True)
def all_nonnegative(u):
    """True if every entry is >= 0 (False for a NaN)."""
    for k in range(u.size):
        if not u[k] >= 0:
            return False
    return True


@njit(
    "f8(f8[::1], f8[:, ::1], i8, f8[:, ::1], f8[::1], i8, b1, i8[::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], "
    "f8[:, ::1], f8[:, ::1])",
    cache=True,
    nogil=True,
)
def class_rates(u, beta, model, vectors, params, K, cell_average, target, weight, factors, work, pw, d):
    """All rates ``d`` (3, M) of the class state u = [N, L, G] (3M,) with a factored kernel
    beta_ij p(phi_i) p(phi_j) (success ``model``: ALWAYS, STEP or LOGISTIC), and the refused solid
    rate (returned): one call for what ``GranulationPBM._rates`` does with a generic kernel.

    ``vectors`` (3, M): class volumes (x_0 units), spray weights, G_min per particle; ``params``:
    number flush level, volume flush level (0: none), success threshold and width, spray rate (0:
    not spraying), consolidation rate (0: none); ``pw`` (2, M): work (phi, p)."""
    M = vectors.shape[1]
    flush_n = params[0]
    flush_v = params[1]
    if flush_n > 0:
        # entries below the flush level count as zero (as after every step)
        tiny = False
        for k in range(3 * M):
            if 0.0 < u[k] < (flush_n if k < M else flush_v):
                tiny = True
                break
        if tiny:
            u = u.copy()
            flush(u, M, flush_n, flush_v)
    nlg = u.reshape((3, M))
    phi = pw[0]
    p = pw[1]
    if model != ALWAYS:
        surface_fraction(nlg, vectors[0], phi)
        threshold = params[2]
        width = params[3]
        for k in range(M):
            if model == STEP:
                p[k] = 1.0 if phi[k] >= threshold else 0.0
            else:
                z = min(max((phi[k] - threshold) / width, -700.0), 700.0)
                p[k] = 1.0 / (1.0 + np.exp(-z))
    refused = aggregation_totals(beta, p, model != ALWAYS, nlg, K, cell_average, target, weight, factors, work, d)
    add_processes(d, nlg, params[4], vectors[1], params[5], vectors[2])
    return refused


@njit(
    "Tuple((f8, b1))(f8[::1], f8[::1], f8, f8, i8, f8[:, ::1], i8, f8[:, ::1], f8[::1], i8, b1, i8[::1], "
    "f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8[::1], f8[:, ::1], f8[:, ::1])",
    cache=True,
    nogil=True,
)
def ssp_stages(
    u,
    k1,
    r1,
    dt,
    order,
    beta,
    model,
    vectors,
    params,
    K,
    cell_average,
    target,
    weight,
    factors,
    work,
    pw,
    u_new,
    u_low,
    stage,
    k2,
    k3,
):
    """The stages of one explicit SSP Runge-Kutta step of size ``dt`` from u with rates ``k1``
    (refused rate ``r1``), with the compiled rates of a factored kernel (:func:`class_rates`):
    what ``GranulationPBM._stages`` does in numpy, the same operations in the same order (increment
    forms; zero rates leave u unchanged to the bit). Writes the new state ``u_new`` and, for
    ``order`` > 1, the embedded lower-order state ``u_low``; returns (refused rate of the step,
    whether ``u_low`` was written). An intermediate stage with a negative entry ends the step
    with that stage as ``u_new`` (the caller then halves the step). ``stage``, ``k2``, ``k3``: work."""
    n = u.size
    for i in range(n):
        stage[i] = u[i] + dt * k1[i]  # u1 (Euler)
    if order == 1 or any_negative(stage):
        for i in range(n):
            u_new[i] = stage[i]
        return r1, False
    r2 = class_rates(stage, beta, model, vectors, params, K, cell_average, target, weight, factors, work, pw, k2)
    k2f = k2.reshape(n)
    h = 0.5 * dt
    if order == 2:
        for i in range(n):
            u_low[i] = stage[i]
            u_new[i] = u[i] + h * (k1[i] + k2f[i])  # Heun (SSP-RK2)
        return 0.5 * (r1 + r2), True
    q = 0.25 * dt
    for i in range(n):
        k12 = k1[i] + k2f[i]
        u_low[i] = u[i] + h * k12  # Heun: the embedded estimate
        stage[i] = u[i] + q * k12  # u2 of SSP-RK3 (Shu & Osher 1988)
    if any_negative(stage):
        for i in range(n):
            u_new[i] = stage[i]
        return r1, True
    r3 = class_rates(stage, beta, model, vectors, params, K, cell_average, target, weight, factors, work, pw, k3)
    k3f = k3.reshape(n)
    c = dt / 6.0
    for i in range(n):
        u_new[i] = u[i] + c * ((k1[i] + k2f[i]) + 4.0 * k3f[i])
    return (r1 + r2 + 4.0 * r3) / 6.0, True
