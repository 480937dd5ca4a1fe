"""Compiled (numba) aggregation rates: the sparse-map evaluation of ``aggregation.PivotAggregation``
in one call instead of about 25 numpy operations.

At the default grid (37 pivots + 3 feed classes) one evaluation is 4800 ordered-pair rates and a
sparse product of about 11000 entries: a few microseconds of arithmetic, but about 25 numpy
calls of 1-2 us each. This module does the same arithmetic, in the same order (so the result is
bit-for-bit that of the numpy path: ``tests/test_pbm_solver.py`` compares them), in one compiled
function.

It is imported by ``aggregation`` when an operator is built (so ``import pbmdem.pbm`` does not
import numba), and its functions have explicit signatures: they are compiled, or loaded from
numba's on-disk cache (``cache=True``, in ``__pycache__`` beside this file), when this module is
imported, never inside a run.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_SIGNATURE = ("f8(f8[:, ::1], f8[:, ::1], i8[::1], i8[::1], f8[::1], i8, b1, "
              "f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[:, ::1], f8[:, ::1])")


@njit(_SIGNATURE, cache=True, nogil=True)
def aggregation_totals(beta, nlg, indptr, indices, data, K, cell_average, cu, ncd, ru, rd, U, y, split, d):
    """Rates of change ``d`` (3, M) of number, liquid and gas of the M classes, and the refused
    solid rate (returned, x_0 units), from the kernel ``beta`` (M, M) and the class totals ``nlg``
    (3, M). ``indptr``, ``indices``, ``data``: the CSR map of ``aggregation.PivotAggregation``
    (3 (2K + M + 1) rows, 3 M^2 columns); ``cu``, ``ncd``, ``ru``, ``rd`` (K,): the cell-average
    split factors; ``U`` (3 M^2,), ``y`` (3 (2K + M + 1),) and ``split`` (6, K): work arrays."""
    M = nlg.shape[1]
    MM = M * M
    # ordered-pair rates R_ij = beta_ij N_i N_j, RL_ij = beta_ij L_i N_j, RG_ij = beta_ij G_i N_j,
    # formed as nlg_bi * (beta_ij * N_j) like the numpy path
    for b in range(3):
        for i in range(M):
            a = nlg[b, i]
            off = b * MM + i * M
            for j in range(M):
                U[off + j] = a * (beta[i, j] * nlg[0, j])
    # the sparse map, row by row and in the order of the row's entries (scipy's csr_matvec)
    n_rows = indptr.size - 1
    for r in range(n_rows):
        s = 0.0
        for k in range(indptr[r], indptr[r + 1]):
            s += data[k] * U[indices[k]]
        y[r] = s
    R = n_rows // 3
    for b in range(3):
        for i in range(M):
            d[b, i] = -y[b * R + 2 * K + i]          # deaths
    if not cell_average:
        # fixed pivot: the map's first K rows are the births
        for b in range(3):
            for c in range(K):
                d[b, c] += y[b * R + c]
        return y[2 * K + M]
    # cell average: the births B_c of cell c, with first moment D_c about its pivot, move up
    # (D_c > 0) or down (D_c < 0); liquid and gas follow the solid each pivot receives.
    # split[b] / split[3 + b]: what moves up / down of quantity b
    for c in range(K):
        D = y[K + c]
        up = max(D, 0.0) * cu[c]
        down = min(D, 0.0) * ncd[c]
        V = y[c] + D
        inv = 1.0 / V if V > 0 else 0.0
        split[0, c] = up
        split[3, c] = down
        fu = up * ru[c] * inv
        fd = down * rd[c] * inv
        for b in (1, 2):
            A = y[b * R + c]
            split[b, c] = A * fu
            split[3 + b, c] = A * fd
    for b in range(3):
        for c in range(K):
            o = (y[b * R + c] - split[b, c]) - split[3 + b, c]
            if c > 0:
                o += split[b, c - 1]
            if c < K - 1:
                o += split[3 + b, c + 1]
            d[b, c] += o
    return y[2 * K + M]


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
