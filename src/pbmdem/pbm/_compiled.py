"""The PBM's compiled rates (numba): every loop of the rate processes, written once.
``GranulationPBM`` calls these primitives for every kernel: a factored kernel (``Kernel.factors``:
beta_ij = S_ij p(phi_i) p(phi_j)) is evaluated inside :func:`class_rates`, any other kernel is
evaluated in Python and its matrix passed to the same :func:`class_rates` (success model ALWAYS).
The time integration on these rates (the Runge-Kutta stages, the step control's vector
operations, the step loop) is ``_compiled_steps``.

| primitive | what it computes |
| --- | --- |
| :func:`success_probability` | p(phi) of the success models (also ``SuccessProbability.per_particle``) |
| :func:`surface_fraction` | the surface-liquid fraction of every class |
| :func:`aggregation_totals` | aggregation: deaths and births of the M classes over the M^2 ordered pairs |
| :func:`breakage_totals` | breakage: deaths of the pivot classes and the cell-average births of their fragments |
| :func:`add_processes` | binder spraying and consolidation |
| :func:`class_rates` | all rates of a class state: flush, success, aggregation, breakage, spraying, consolidation |
| :func:`flush`, :func:`flushed` | entries below their flush level set to zero |
| :func:`bilinear_outer` | a table's linear interpolation at every pair of a set of points (``bilinear.Bilinear``) |

The breakage selection from impacts is ``_compiled_selection``. Breakage (a selection rate per
pivot and the fragment tables of ``breakage.Breakage``) is one
more loop called from :func:`class_rates`, after :func:`aggregation_totals`; every kernel and
every stage sees it, and without breakage (an empty selection) the rates are those of
aggregation alone, to the bit.

The slow numpy formulation of the same rates (the sparse map of ordered-pair rates, numpy
spraying, consolidation and stages) is a test oracle, ``tests/pbm_oracle.py``; the compiled
rates equal it to the bit (``tests/test_pbm_compiled.py``).

It is imported when a model or an aggregation operator is built (so ``import pbmdem.pbm`` does
not import numba), and its functions have explicit signatures: they are compiled, or loaded from
numba's on-disk cache (``cache=True``, in ``__pycache__`` beside this file), when this module is
imported, never inside a run.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: success models of a factored kernel (``Kernel.factors``): p = 1, the step, the logistic
ALWAYS, STEP, LOGISTIC = 0, 1, 2
#: the success models by name (``SuccessProbability.model``), their codes above
SUCCESS_CODES = {"always": ALWAYS, "step": STEP, "logistic": LOGISTIC}

_SIGNATURE = "f8(f8[:, ::1], f8[::1], b1, f8[:, ::1], i8, b1, i8[::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1])"


@njit("void(f8[::1], f8[:, ::1], f8[::1], f8[:, ::1])", cache=True, nogil=True)
def bilinear_outer(grid, values, a, out):
    """``bilinear.Bilinear.outer``: ``out[p, q]`` the linear interpolation of the table ``values``
    (n, n) on the square ``grid`` (n,) at the pair (a_p, a_q), extrapolated linearly beyond it.
    The cell of each point as ``Bilinear._cell`` finds it (``searchsorted(grid, a, "right") - 1``
    clipped to the cells; NaN beyond the last) with its normalised distance from the lower node,
    and the four corner terms with the operations of the numpy form, in its order: the same
    numbers to the bit (about 5x faster on a coupling interval's 46 bins)."""
    n = grid.size
    m = a.size
    cell = np.empty(m, dtype=np.int64)
    y = np.empty(m)
    for p in range(m):
        k = 0
        while k < n and not a[p] < grid[k]:
            k += 1
        i = min(max(k - 1, 0), n - 2)
        cell[p] = i
        y[p] = (a[p] - grid[i]) / (grid[i + 1] - grid[i])
    for p in range(m):
        i = cell[p]
        y0 = y[p]
        a0 = 1.0 - y0
        for q in range(m):
            j = cell[q]
            y1 = y[q]
            b0 = 1.0 - y1
            o = 0.0 + values[i, j] * a0 * b0
            o = o + values[i, j + 1] * a0 * y1
            o = o + values[i + 1, j] * y0 * b0
            out[p, q] = o + values[i + 1, j + 1] * y0 * y1


@njit("void(f8[:, ::1], i8, f8, f8, f8, f8)", cache=True, nogil=True)
def _collect_births(born, t, h, RL, RG, moment):
    """Cell average: an event (rate h, liquid RL, gas RG) is born in cell t; ``moment``: its
    volume about the pivot, s/x_t - 1."""
    born[0, t] += h
    born[3, t] += h * moment
    born[1, t] += RL
    born[2, t] += RG


@njit("void(f8[:, ::1], i8, f8, f8, f8, f8, f8)", cache=True, nogil=True)
def _place_births(born, t, h, RL, RG, up_number, up_solid):
    """Fixed pivot: an event (rate h, liquid RL, gas RG) is born on the pivots t and t + 1, the
    upper one receiving ``up_number`` of the number and ``up_solid`` of the solid (liquid, gas)."""
    born[0, t] += h * (1.0 - up_number)
    born[0, t + 1] += h * up_number
    born[1, t] += RL * (1.0 - up_solid)
    born[1, t + 1] += RL * up_solid
    born[2, t] += RG * (1.0 - up_solid)
    born[2, t + 1] += RG * up_solid


@njit("void(f8[:, ::1], f8[:, ::1], f8[:, ::1], i8)", cache=True, nogil=True)
def _split_cells(born, factors, split, K):
    """Cell average: the births B_c of every cell c, with first moment D_c about its pivot (in
    units of x_c), move up (D_c > 0) or down (D_c < 0) so that number and solid are exact; liquid
    and gas follow the solid each pivot receives. Replaces ``born[:3]`` by what every pivot
    receives; ``split[b]`` / ``split[3 + b]``: what moves up / down of b."""
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
            born[b, c] = o


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

    With ``use_p`` (a factored kernel: beta finite, checked where it enters) a pair with N_j = 0,
    p_j = 0 or p_i = 0 has q = 0 and adds exact zeros to every sum (a sum never is -0, so x + 0 =
    x to the bit): its partners j are skipped, and so are the rows of p_i = 0 (deaths -0, as
    before). The same rates to the bit, fewer pairs (empty classes, dry granules).
    """
    M = nlg.shape[1]
    born = work[:4]  # rows: number, liquid, gas born per cell, first moment D_c
    born[:] = 0.0
    refused = 0.0
    partners = np.empty(M, dtype=np.int64)  # the j whose q may be nonzero
    n_partners = 0
    for j in range(M):
        if not use_p or (nlg[0, j] != 0.0 and p[j] != 0.0):
            partners[n_partners] = j
            n_partners += 1
    for i in range(M):
        Ni = nlg[0, i]
        Li = nlg[1, i]
        Gi = nlg[2, i]
        dN = 0.0  # deaths: sum over the pairs within the grid of R_ij, RL_ij, RG_ij
        dL = 0.0
        dG = 0.0
        row = i * M
        pi = p[i]
        for jj in range(n_partners if not use_p or pi != 0.0 else 0):
            j = partners[jj]
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
            # every ordered pair counts half an event
            if cell_average:
                _collect_births(born, t, 0.5 * R, RL, RG, weight[0, row + j])
            else:
                _place_births(born, t, 0.5 * R, RL, RG, weight[0, row + j], weight[1, row + j])
        d[0, i] = -dN
        d[1, i] = -dL
        d[2, i] = -dG
    if cell_average:
        _split_cells(born, factors, work[4:], K)
    for b in range(3):
        for c in range(K):
            d[b, c] += born[b, c]
    return refused


@njit(
    "void(f8[::1], f8[:, ::1], i8, f8[:, :, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1])",
    cache=True,
    nogil=True,
)
def breakage_totals(sel, nlg, K, tab, factors, below, work, d, tally):
    """Add breakage to the rates ``d`` (3, M) of the class totals ``nlg`` (3, M): the granules of
    pivot k (k < K; feed classes do not break) break at the selection rate ``sel[k]`` (1/s),
    each breakage removing one granule with its liquid and gas; its fragments are born in the
    cells i <= k as ``tab`` (3, K, K) gives them (``Breakage.fragment_tables``: number, first
    moment about x_i, share of the parent's solid, which is also the share of its liquid and
    gas), and the births of every cell are split onto the pivots by the cell average
    (:func:`_split_cells`, ``factors`` of ``aggregation.cell_average_factors``), so that number
    and solid volume are exact. ``work`` (10, K): work array.

    The fragments smaller than the first pivot are merged into it (``tab`` counts them as
    granules of x_0 with their solid): ``below`` (2, K) holds, per breakage of pivot k, their
    number and solid (x_0 units) (``Breakage.below_floor``), and their rates are added to
    ``tally[1]`` (fragments merged per second) and ``tally[2]`` (their solid, x_0 units).
    ``below`` rows 2 and 3 (``Breakage.compiled_arrays``; without them, 0 and k + 1): the first
    row and one past the last of column k of ``tab`` with a nonzero entry; the rows outside, and
    a pivot with no breakage (R, RL, RG 0), add exact zeros (a sum never is -0): skipped, the same
    rates to the bit (binary fragments fill one row of each column)."""
    born = work[:4]  # rows: number, liquid, gas born per cell, first moment D_c
    born[:] = 0.0
    merged_n = 0.0
    merged_v = 0.0
    ranged = below.shape[0] >= 4
    for k in range(K):
        s = sel[k]
        R = s * nlg[0, k]
        RL = s * nlg[1, k]
        RG = s * nlg[2, k]
        if R == 0.0 and RL == 0.0 and RG == 0.0:
            continue
        d[0, k] -= R
        d[1, k] -= RL
        d[2, k] -= RG
        merged_n += R * below[0, k]
        merged_v += R * below[1, k]
        lo, hi = (int(below[2, k]), int(below[3, k])) if ranged else (0, k + 1)
        for i in range(lo, hi):
            born[0, i] += R * tab[0, i, k]
            born[3, i] += R * tab[1, i, k]
            born[1, i] += RL * tab[2, i, k]
            born[2, i] += RG * tab[2, i, k]
    _split_cells(born, factors, work[4:], K)
    for b in range(3):
        for c in range(K):
            d[b, c] += born[b, c]
    tally[1] += merged_n
    tally[2] += merged_v


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


# ----------------------------------------------------------------- vector helpers
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


@njit("void(f8[:, ::1], f8[::1], f8[::1])", cache=True, nogil=True)
def granule_porosity(nlg, xc, out):
    """Intra-granular porosity G / (N x + G) of every class (NaN where a class holds no solid; G the
    pore volume, wet or dry: docs/pbm.md); numpy form in tests/pbm_oracle.py."""
    for k in range(nlg.shape[1]):
        S = nlg[0, k] * xc[k]
        out[k] = nlg[2, k] / (S + nlg[2, k]) if S > 0 else np.nan


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


@njit("f8[::1](f8[::1], i8, f8, f8)", cache=True, nogil=True)
def flushed(u, M, flush_n, flush_v):
    """u, or if an entry lies strictly between 0 and its flush level a copy of u with the
    entries below their flush level zeroed (:func:`flush`)."""
    for k in range(3 * M):
        if 0.0 < u[k] < (flush_n if k < M else flush_v):
            v = u.copy()
            flush(v, M, flush_n, flush_v)
            return v
    return u


@njit("void(i8, f8, f8, f8[::1], f8[::1])", cache=True, nogil=True)
def success_probability(model, threshold, width, phi, p):
    """p(phi) of the success ``model`` into ``p``: ALWAYS 1, STEP 1 if phi >= threshold else 0,
    LOGISTIC 1 / (1 + exp(-(phi - threshold) / width)) (exponent clipped to +-700)."""
    for k in range(phi.size):
        if model == ALWAYS:
            p[k] = 1.0
        elif model == STEP:
            p[k] = 1.0 if phi[k] >= threshold else 0.0
        else:
            z = min(max((phi[k] - threshold) / width, -700.0), 700.0)
            p[k] = 1.0 / (1.0 + np.exp(-z))


@njit("f8[:, ::1](f8[::1], i8, f8[:, ::1], f8[::1], f8[:, ::1])", cache=True, nogil=True)
def class_totals(u, model, vectors, params, pw):
    """The class totals (3, M) of the state u = [N, L, G] (3M,), entries below the flush levels
    ``params[0]``, ``params[1]`` counting as zero, and for a success ``model`` (not ALWAYS) the
    surface-liquid fraction and p(phi) of every class in ``pw[0]``, ``pw[1]``."""
    M = vectors.shape[1]
    if params[0] > 0:
        u = flushed(u, M, params[0], params[1])
    nlg = u.reshape((3, M))
    if model != ALWAYS:
        surface_fraction(nlg, vectors[0], pw[0])
        success_probability(model, params[2], params[3], pw[0], pw[1])
    return nlg


@njit(
    "void(f8[::1], f8[:, ::1], i8, f8[:, ::1], f8[::1], i8, b1, i8[::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], "
    "f8[::1], f8[:, :, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1])",
    cache=True,
    nogil=True,
)
def class_rates(
    u, beta, model, vectors, params, K, cell_average, target, weight, factors, work, sel, tab, bf, below, pw, d, tally
):
    """All rates ``d`` (3, M) of the class state u = [N, L, G] (3M,), and the tallies ``tally``
    (3,): the refused solid rate, the rate of fragments merged into the first pivot and their
    solid (x_0 units); the one rate evaluation of the PBM. The kernel is beta_ij p(phi_i) p(phi_j)
    (success ``model``: STEP or LOGISTIC, a factored kernel) or ``beta`` itself (ALWAYS: a
    factored kernel without success model, or the matrix of a kernel called in Python).

    ``vectors`` (3, M): class volumes (x_0 units), spray weights, G_min per particle; ``params``:
    number flush level, volume flush level (0: none), success threshold and width, spray rate (0:
    not spraying), consolidation rate (0: none); ``sel`` (K,), ``tab``, ``bf``, ``below``: the
    breakage's selection rates, fragment tables, split factors and fragments below the first pivot
    (:func:`breakage_totals`; ``sel`` empty: no breakage); ``pw`` (2, M): work (phi, p)."""
    nlg = class_totals(u, model, vectors, params, pw)
    tally[0] = aggregation_totals(beta, pw[1], model != ALWAYS, nlg, K, cell_average, target, weight, factors, work, d)
    tally[1] = 0.0
    tally[2] = 0.0
    if sel.size > 0:
        breakage_totals(sel, nlg, K, tab, bf, below, work, d, tally)
    add_processes(d, nlg, params[4], vectors[1], params[5], vectors[2])
