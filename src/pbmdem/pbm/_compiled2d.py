"""The compiled backend of the two-dimensional PBM (numba): the rates of a class state on
(size class) x (liquid class) and the stages of a step, written once. docs/pbm.md ("Two-dimensional
PBM") gives the balance; ``model2d.GranulationPBM2D`` calls these.

Class a = i J + e: size class i (the K pivots, then the feed classes) and liquid class e (a band of
liquid-to-solid volume ratio, ``liquid_grid.LiquidGrid``), each with its number N, liquid L and gas
G totals. The state is u = [N, L, G] (3 M2,), M2 = Mx J, volumes in units of the first pivot.

The size axis is the one-dimensional model's: the same pair map (``aggregation``: target cell and
weights of every pair of size classes) and, for the cell average, the split of the births of every
size cell pooled over the liquid classes (``_split_rows``), so that with a kernel and success that
do not depend on liquid the size marginal obeys the one-dimensional model's equations. Spraying,
consolidation, the flush and the success models are ``_compiled``'s own functions on the 2-D classes.
"""

from __future__ import annotations

from numba import njit

from . import _compiled, _compiled_selection, _compiled_steps
from ._compiled import ALWAYS, add_processes, class_totals
from ._compiled_steps import drop_stale_cache, ssp_stage

drop_stale_cache(__file__, _compiled.__file__, _compiled_steps.__file__, _compiled_selection.__file__)


@njit("i8(f8, f8[::1])", cache=True, nogil=True)
def _count_at_or_below(w, values):
    """The number of the ascending ``values`` <= w (bisection)."""
    lo, hi = 0, values.size
    while lo < hi:
        mid = (lo + hi) // 2
        if values[mid] <= w:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit("i8(f8, f8, f8[::1])", cache=True, nogil=True)
def ratio_class(w, step, bounds):
    """The liquid class of the liquid-to-solid ratio ``w``: the number of inner ``bounds`` <= w
    (classes [0, b_0), [b_0, b_1), ..., [b_(J-2), inf)); ``step`` > 0: bounds step, 2 step, ..."""
    n = bounds.size
    if step > 0.0:
        if w >= bounds[n - 1]:
            return n
        e = int(w / step)
        # the division may land one class off at a bound: settle it against the bounds themselves
        if e > 0 and w < bounds[e - 1]:
            e -= 1
        elif e < n and w >= bounds[e]:
            e += 1
        return e
    return _count_at_or_below(w, bounds)


@njit("void(f8[:, ::1], f8[:, :, ::1], f8[:, ::1], f8[::1], i8, i8, b1, f8[:, ::1])", cache=True, nogil=True)
def _split_rows(pooled, rows, factors, xr, K, J, cell_average, d):
    """Add the births ``rows`` (solid, liquid, gas of every size cell c and liquid class e, x_0
    units; rows 3-5 are work) to the rates ``d`` (3, M2). Cell average: the births of cell c, pooled
    over the liquid classes (number B_c = ``pooled[0]``, first moment D_c = ``pooled[1]`` about the
    pivot in units of x_c), are split as ``_compiled._split_cells`` splits them: the shares fu / fd
    of the solid that move up / down, applied to the solid, liquid and gas of every liquid class
    (a granule keeps its liquid class); number = solid / pivot. Fixed pivot: the rows are the
    pivots' already."""
    out = rows[3:]
    out[:3] = 0.0
    for c in range(K):
        fu = 0.0
        fd = 0.0
        if cell_average:
            D = pooled[1, c]
            up = max(D, 0.0) * factors[0, c]
            down = min(D, 0.0) * factors[1, c]
            V = pooled[0, c] + D
            inv = 1.0 / V if V > 0 else 0.0
            fu = up * factors[2, c] * inv
            fd = down * factors[3, c] * inv
        for q in range(3):
            for e in range(J):
                v = rows[q, c, e]
                if v == 0.0:
                    continue
                vu = v * fu
                vd = v * fd
                out[q, c, e] += (v - vu) - vd
                if c < K - 1:
                    out[q, c + 1, e] += vu
                if c > 0:
                    out[q, c - 1, e] += vd
    for c in range(K):
        inv_x = 1.0 / xr[c]
        for e in range(J):
            a = c * J + e
            d[0, a] += out[0, c, e] * inv_x
            d[1, a] += out[1, c, e]
            d[2, a] += out[2, c, e]


@njit("UniTuple(f8, 2)(f8, f8, f8, f8, f8[::1])", cache=True, nogil=True)
def _locate(l_sum, inv_vol, kz, step, centres):
    """(e, f): the aggregate of liquid ``l_sum`` and solid 1 / ``inv_vol`` (ratio w) goes to liquid
    class e with the share 1 - f and to e + 1 with f, e and e + 1 the classes whose centres enclose
    w (f = 0 below the first centre and above the last); ``kz`` = inv_vol / step (uniform classes)."""
    top = centres.size - 1
    if step > 0.0:
        z = l_sum * kz - 0.5  # (w - centre_0) / step
        if z <= 0.0:
            return 0.0, 0.0
        if z >= top:
            return float(top), 0.0
        e = int(z)
        return float(e), z - e
    w = l_sum * inv_vol
    e = _count_at_or_below(w, centres) - 1  # the last centre at or below w (-1: below the first)
    if e < 0:
        return 0.0, 0.0
    if e >= top:
        return float(top), 0.0
    return float(e), (w - centres[e]) / (centres[e + 1] - centres[e])


@njit("void(f8[:, :], f8, f8, f8, f8, f8)", cache=True, nogil=True)
def _deposit(tmp, e, f, R, RL, RG):
    """Births (number rate R, liquid RL, gas RG) to liquid class e (share 1 - f) and e + 1 (f)."""
    k = int(e)
    if f == 0.0:
        tmp[0, k] += R
        tmp[1, k] += RL
        tmp[2, k] += RG
    else:
        tmp[0, k] += R - R * f
        tmp[1, k] += RL - RL * f
        tmp[2, k] += RG - RG * f
        tmp[0, k + 1] += R * f
        tmp[1, k + 1] += RL * f
        tmp[2, k + 1] += RG * f


@njit(
    "f8(f8[:, ::1], f8[::1], b1, f8[:, ::1], i8[::1], f8[::1], f8, f8[::1], i8[::1], f8[:, ::1], f8[:, ::1], "
    "i8[:, ::1], f8[:, :, ::1], f8[:, ::1], f8[:, :, ::1], f8[:, ::1])",
    cache=True,
    nogil=True,
)
def aggregation_totals2d(S, p, use_p, nlg, dims, xc, step, centres, target, weight, factors, act, cw, xw, rw, d):
    """Aggregation rates ``d`` (3, M2) of the classes ``nlg`` (3, M2) = (N, L, G), and the refused
    solid rate (returned, x_0 units). ``dims`` = (K, Mx, J, cell_average); ``S`` (Mx, Mx): the kernel
    of the size classes, times p(phi_a) p(phi_b) of the two classes with ``use_p``; ``xc`` (Mx,)
    the size classes' volumes; ``step``, ``centres``: the liquid classes' centres (``LiquidGrid``);
    ``target``, ``weight``, ``factors``: the size axis' pair map (``_compiled.aggregation_totals``).
    Work: ``act`` (Mx, J + 1), ``cw`` (4, Mx, J), ``xw`` (4, max(K, Mx)), ``rw`` (9, K, J).

    Event rate of classes a != b: beta_ab N_a N_b (a = b: half of beta_aa N_a^2), beta_ab = S_ij p_a
    p_b. Deaths need only P_i = sum_e p N of every size class: class a loses N_a p_a sum_j S_ij P_j
    (over the pairs within the grid; its liquid and gas in proportion). Births loop over the pairs of
    classes that can aggregate (N > 0, p > 0), grouped by their size classes (i, j): the aggregate of
    (x_i, l_a) and (x_j, l_b) (l the liquid per granule) has solid x_i + x_j in the size cell of the
    pair map, carries the liquid and gas of both partners, and goes to the liquid classes of the two
    centres around its ratio w = (l_a + l_b) / (x_i + x_j), shared linearly between them (all of it
    to the first or last class beyond their centres), so that the births change continuously with
    the state (a class taken by w alone would switch within a step and force tiny steps)."""
    K, Mx, J, cell_average = dims[0], dims[1], dims[2], dims[3] != 0
    # the classes that can aggregate, packed per size class i (act[i, J] of them): cw[:, i, k] =
    # N p, L p, G p and the liquid per granule of the k-th one (its liquid class is not needed)
    A, AL, AG, lpp = cw[0], cw[1], cw[2], cw[3]
    P, death, pooled = xw[0], xw[1], xw[2:4]
    tmp = rw[6:9, 0]  # (3, J): the births of one pair of size classes
    for i in range(Mx):
        P[i] = 0.0
        n = 0
        for e in range(J):
            a = i * J + e
            N = nlg[0, a]
            pa = p[a] if use_p else 1.0
            if N > 0 and pa > 0:
                A[i, n] = N * pa
                AL[i, n] = nlg[1, a] * pa
                AG[i, n] = nlg[2, a] * pa
                lpp[i, n] = nlg[1, a] / N
                P[i] += A[i, n]
                n += 1
        act[i, J] = n
    refused = 0.0
    for i in range(Mx):
        s = 0.0
        row = i * Mx
        for j in range(Mx):
            if target[row + j] < 0:
                refused += 0.5 * weight[0, row + j] * S[i, j] * P[i] * P[j]
            else:
                s += S[i, j] * P[j]
        death[i] = s
    for i in range(Mx):
        f = death[i]
        for e in range(J):
            a = i * J + e
            pa = p[a] if use_p else 1.0
            q = pa * f if nlg[0, a] > 0 else 0.0
            d[0, a] = -nlg[0, a] * q
            d[1, a] = -nlg[1, a] * q
            d[2, a] = -nlg[2, a] * q
    rw[:3] = 0.0
    tmp[:] = 0.0
    pooled[:, :K] = 0.0
    inv_step = 1.0 / step if step > 0.0 else 0.0
    top = J - 1
    for i in range(Mx):
        ni = act[i, J]
        if ni == 0:
            continue
        for j in range(i, Mx):
            nj = act[j, J]
            t = target[i * Mx + j]
            if nj == 0 or t < 0:
                continue
            s_ij = S[i, j]
            vol = xc[i] + xc[j]
            inv_vol = 1.0 / vol
            kz = inv_vol * inv_step
            total = 0.0
            e_lo, e_hi = J, -1
            Aj, ALj, AGj, lj = A[j], AL[j], AG[j], lpp[j]
            for ka in range(ni):
                sA = s_ij * A[i, ka]
                sAL = s_ij * AL[i, ka]
                sAG = s_ij * AG[i, ka]
                la = lpp[i, ka]
                for kb in range(ka if i == j else 0, nj):
                    # a class with itself: half the events, beta N^2 / 2 (h x exact for h = 1 and 1/2)
                    h = 0.5 if kb == ka and i == j else 1.0
                    Ab = Aj[kb]
                    R = h * sA * Ab
                    total += R
                    e, f = _locate(la + lj[kb], inv_vol, kz, step, centres)
                    _deposit(tmp, e, f, R, h * (sAL * Ab + sA * ALj[kb]), h * (sAG * Ab + sA * AGj[kb]))
                    e_lo, e_hi = min(e_lo, e), max(e_hi, min(e + 1, top))
            lo, hi = int(e_lo), int(e_hi)
            w0 = weight[0, i * Mx + j]
            if cell_average:
                pooled[0, t] += total
                pooled[1, t] += total * w0
                for e in range(lo, hi + 1):
                    rw[0, t, e] += tmp[0, e] * vol
                    rw[1, t, e] += tmp[1, e]
                    rw[2, t, e] += tmp[2, e]
            else:
                fu = weight[1, i * Mx + j]  # the upper pivot's share of the solid
                for e in range(lo, hi + 1):
                    for q in range(3):
                        v = tmp[q, e] * vol if q == 0 else tmp[q, e]
                        rw[q, t, e] += v - v * fu
                        rw[q, t + 1, e] += v * fu
            tmp[:, lo : hi + 1] = 0.0
    _split_rows(pooled, rw, factors, xc, K, J, cell_average, d)
    return refused


@njit(
    "void(f8[::1], f8[:, ::1], i8[::1], f8[::1], f8[:, :, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, :, ::1], "
    "f8[:, ::1], f8[::1])",
    cache=True,
    nogil=True,
)
def breakage_totals2d(sel, nlg, dims, xc, tab, factors, below, xw, rw, d, tally):
    """Add breakage to the rates ``d`` (3, M2): a granule of pivot class (k, e) breaks at ``sel[k]``
    (feed classes do not break); its fragments (``tab``, ``breakage.Breakage.fragment_tables``) keep
    its liquid-to-solid ratio, so they stay in liquid class e; the births of every size cell are
    split over the pivots pooled over the liquid classes (:func:`_split_rows`, cell average). The
    fragments smaller than the first pivot, merged into it, are tallied as in
    ``_compiled.breakage_totals`` (``below``; ``tally[1]``, ``tally[2]``)."""
    K, J = dims[0], dims[2]
    merged_n = 0.0
    merged_v = 0.0
    pooled = xw[2:4]
    rw[:3] = 0.0
    pooled[:, :K] = 0.0
    for k in range(K):
        s = sel[k]
        if s == 0.0:
            continue
        for e in range(J):
            a = k * J + e
            if nlg[0, a] <= 0.0:
                continue
            R = s * nlg[0, a]
            RL = s * nlg[1, a]
            RG = s * nlg[2, a]
            d[0, a] -= R
            d[1, a] -= RL
            d[2, a] -= RG
            merged_n += R * below[0, k]
            merged_v += R * below[1, k]
            RS = R * xc[k]
            for i in range(k + 1):
                share = tab[2, i, k]
                pooled[0, i] += R * tab[0, i, k]
                pooled[1, i] += R * tab[1, i, k]
                rw[0, i, e] += RS * share
                rw[1, i, e] += RL * share
                rw[2, i, e] += RG * share
    _split_rows(pooled, rw, factors, xc, K, J, True, d)
    tally[1] += merged_n
    tally[2] += merged_v


_RATES = (
    "void(f8[::1], f8[:, ::1], i8, f8[:, ::1], f8[::1], f8[::1], i8[::1], f8, f8[::1], i8[::1], f8[:, ::1], "
    "f8[:, ::1], f8[::1], f8[:, :, ::1], f8[:, ::1], f8[:, ::1], i8[:, ::1], f8[:, :, ::1], f8[:, ::1], "
    "f8[:, :, ::1], f8[:, ::1], f8[:, ::1], f8[::1])"
)


@njit(_RATES, cache=True, nogil=True)
def class_rates2d(
    u, S, model, vectors, xc, params, dims, step, centres, target, weight, factors, sel, tab, bf, below, act, cw, xw,
    rw, pw, d, tally,
):  # fmt: skip
    """All rates ``d`` (3, M2) of the class state u = [N, L, G] (3 M2,) and the tallies ``tally`` (3,)
    of ``_compiled.class_rates`` (refused solid, merged fragments and their solid rates): flush, the
    success p(phi) of every class (``model``: ``_compiled.STEP`` / ``LOGISTIC``; ALWAYS: p = 1),
    aggregation, breakage (``sel`` empty: none), spraying and
    consolidation. ``vectors`` (3, M2): class volumes, spray weights, G_min per granule; ``params``
    as ``_compiled.class_rates``'s; ``pw`` (2, M2): work (phi, p)."""
    nlg = class_totals(u, model, vectors, params, pw)
    tally[0] = aggregation_totals2d(
        S, pw[1], model != ALWAYS, nlg, dims, xc, step, centres, target, weight, factors, act, cw, xw, rw, d
    )
    tally[1] = 0.0
    tally[2] = 0.0
    if sel.size > 0:
        breakage_totals2d(sel, nlg, dims, xc, tab, bf, below, xw, rw, d, tally)
    add_processes(d, nlg, params[4], vectors[1], params[5], vectors[2])


@njit(
    "void(f8[::1], f8[:, ::1], f8[:, ::1], f8, i8, f8[::1], f8[::1], f8[::1], f8[:, ::1], i8, f8[:, ::1], f8[::1], "
    "f8[::1], i8[::1], f8, f8[::1], i8[::1], f8[:, ::1], f8[:, ::1], f8[::1], f8[:, :, ::1], f8[:, ::1], "
    "f8[:, ::1], i8[:, ::1], f8[:, :, ::1], f8[:, ::1], f8[:, :, ::1], f8[:, ::1])",
    cache=True,
    nogil=True,
)
def ssp_step2d(
    u, k, r, dt, order, u_new, u_low, stage, S, model, vectors, xc, params, dims, step, centres, target, weight,
    factors, sel, tab, bf, below, act, cw, xw, rw, pw,
):  # fmt: skip
    """One SSP Runge-Kutta step of size ``dt`` from u (``_compiled_steps.ssp_stage``) with the rates of
    :func:`class_rates2d`; ``k[0]``, ``r[0]``: the rates and tallies at u. The step's tallies are
    ``r[3]``."""
    M2 = vectors.shape[1]
    for j in range(1, 4):
        if ssp_stage(j, order, dt, u, k, r, stage, u_new, u_low):
            return
        class_rates2d(
            stage, S, model, vectors, xc, params, dims, step, centres, target, weight, factors, sel, tab, bf,
            below, act, cw, xw, rw, pw, k[j].reshape((3, M2)), r[j],
        )  # fmt: skip


@njit("i8(f8[::1], i8, i8, f8[::1], f8, f8[::1], f8[::1], f8[::1])", cache=True, nogil=True)
def rebin(u, Mx, J, xc, step, bounds, centres, work):
    """Move (in place) every class of u = [N, L, G] whose mean liquid-to-solid ratio L / (N x) has
    passed the centre of a neighbouring class (the births a class receives lie between those
    centres, so only spraying moves a mean so far) to the class whose band holds its mean, merged
    with what is there (number, liquid and gas exact: whole classes move). Returns the number of
    classes moved."""
    M2 = Mx * J
    moved = 0
    work[:] = 0.0
    for i in range(Mx):
        for e in range(J):
            a = i * J + e
            N = u[a]
            t = a
            if N > 0:
                m = u[M2 + a] / (N * xc[i])
                if (e > 0 and m < centres[e - 1]) or (e < J - 1 and m > centres[e + 1]):
                    t = i * J + ratio_class(m, step, bounds)
                    moved += 1
            work[t] += N
            work[M2 + t] += u[M2 + a]
            work[2 * M2 + t] += u[2 * M2 + a]
    if moved:
        u[:] = work
    return moved


@njit("void(f8[::1], f8, f8[::1], i8[::1])", cache=True, nogil=True)
def ratio_classes(w, step, bounds, out):
    """:func:`ratio_class` of every ratio of ``w`` into ``out``."""
    for k in range(w.size):
        out[k] = ratio_class(w[k], step, bounds)
