"""The PBM's step loop, compiled: the steps of ``GranulationPBM.run`` in one call (the states at
its output times recorded into buffers), for a run whose kernel and breakage selection need no
Python between steps (``pbm.fast_steps``: a factored kernel whose frequencies
stay fixed in the run, and no breakage or an impact selection from fixed impacts).

Per step it does what the Python loop does (``model.run``, ``stepping.StepControl.step``), in the
same order and with the same arithmetic: the selection refreshed at its update interval
(``_compiled.selection_of_impacts`` of the bins' numbers and porosities), the rates at the start
(``_compiled.class_rates``), the step size (depletion, error control, max_step, the event), the
stages (``_compiled.ssp_step``) with their halvings and rejections, the flush and the tallies.
Anything out of the ordinary (a selection or rate not finite or negative, a NaN after a step, a
step that cannot be made positive) returns ``FALLBACK`` before the step changes anything, so the
Python loop repeats that step and raises its error. The results are those of the Python loop to
the bit (tests/test_pbm_fast_steps.py, against the Python loop kept in tests/step_oracle.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._compiled import (
    all_finite,
    all_nonnegative,
    class_rates,
    depletion_time,
    error_norm,
    flush,
    granule_porosity,
    selection_of_impacts,
    ssp_step,
)

#: why ``advance`` returned: the event reached, a check of the run's limits due, refused solid over
#: the allowed share, a step for the Python loop (it raises the error of the step)
DONE, CHECK, OVERFLOW, FALLBACK = 0, 1, 2, 3
#: ``ctl`` entries: safety, proposed step, max_step, rtol, 1/order, selection interval, last selection time
SAFETY, DT_PROP, MAX_STEP, RTOL, EXPO, INTERVAL, T_EVAL = range(7)
#: ``acc`` entries: time, refused solid, merged fragments, their solid (x_0 units), liquid added (m3),
#: the states recorded (rows of the buffers); a row of ``rec_s`` holds the first five and the steps
TIME, REFUSED, MERGED_N, MERGED_V, LIQUID, ROWS = range(6)
#: ``counts`` entries: the step limits of ``stepping.STEP_LIMITS``, then the steps taken
TAKEN = 6
MAX_HALVINGS = 60


@njit(cache=True, nogil=True)
def _refresh_selection(u, M, K, xc, feed_w, eps, nbin, porous, diameters, strength, spread, edges, impacts, columns,
                       pairs, speeds, probability, out):  # fmt: skip
    """The breakage selection of the bins at the class state u into ``out`` (``Breakage.rates`` of
    ``ImpactSelection``): False if a rate is not finite or negative."""
    nlg = u.reshape((3, M))
    for i in range(K):
        nbin[i] = nlg[0, i]
    if M > K:  # the bin totals: the aggregates and the feed classes by the lever rule
        for j in range(K):
            s = 0.0
            for q in range(M - K):
                s += nlg[0, K + q] * feed_w[q, j]
            nbin[j] = nlg[0, j] + s
    if porous:
        granule_porosity(nlg, xc, eps)
        por = eps[:K].copy()
    else:
        por = np.zeros(0)
    selection_of_impacts(diameters, por, strength, spread, edges, impacts[0], impacts[1], columns, impacts[2],
                         impacts[3], nbin, pairs, speeds, probability, out)  # fmt: skip
    for i in range(K):
        if not (np.isfinite(out[i]) and out[i] >= 0):
            return False
    return True


@njit(cache=True, nogil=True)
def advance(u, events, is_out, t_end, order, ctl, acc, counts, floor, k, r, beta, model, vectors, params, K,
            cell_average, target, weight, factors, work, sel, tab, bf, below, pw, u_new, u_low, stage, flush_n, flush_v,
            spray, allowed_refused, max_steps, feed_w, eps, nbin, porous, diameters, strength, spread, edges,
            impacts, columns, pairs, speeds, probability, sel_new, rec_u, rec_s):  # fmt: skip
    """Steps from the class state u at ``acc[TIME]`` to ``t_end``, in place (u, ``acc``, ``ctl``
    [DT_PROP, T_EVAL], ``counts``, ``sel``); the selection of the first step is the one in ``sel``
    (prepared in Python). ``events``: the run's sorted event times, ``is_out``: 1 where the state is
    recorded (into row ``acc[ROWS]`` of ``rec_u`` (3M) and ``rec_s``); ``params`` (2, 6): the rates'
    parameters not spraying and spraying; ``spray``: window start, end and rate (m3/s). Returns DONE,
    CHECK, OVERFLOW or FALLBACK (module doc)."""
    M = vectors.shape[1]
    expo = ctl[EXPO]
    first = True
    ev = 0
    while acc[TIME] < t_end:
        t = acc[TIME]
        while events[ev] <= t:
            ev += 1
        t_next = events[ev]
        spraying = spray[0] <= t < spray[1]
        par = params[1] if spraying else params[0]
        if not first and sel.size > 0 and t >= ctl[T_EVAL] + ctl[INTERVAL]:
            if not _refresh_selection(u, M, K, vectors[0], feed_w, eps, nbin, porous, diameters, strength, spread,
                                      edges, impacts, columns, pairs, speeds, probability, sel_new):  # fmt: skip
                return FALLBACK
            sel[:] = sel_new
            ctl[T_EVAL] = t
        first = False
        k1 = k[0]
        class_rates(u, beta, model, vectors, par, K, cell_average, target, weight, factors, work, sel, tab, bf,
                    below, pw, k1.reshape((3, M)), r[0])  # fmt: skip
        if not all_finite(k1):
            return FALLBACK
        # the step size (StepControl.step): the first of the smallest candidates limits it
        c0 = ctl[SAFETY] * depletion_time(u, k1)
        c1 = ctl[DT_PROP]
        c2 = ctl[MAX_STEP]
        c3 = t_next - t
        dt = min(min(min(c0, c1), c2), c3)
        why = 0 if c0 == dt else (1 if c1 == dt else (2 if c2 == dt else 3))
        rejected = 0
        neg = 0
        err = 0.0
        ok = False
        for _ in range(MAX_HALVINGS + 1):
            ssp_step(u, k, r, dt, order, beta, model, vectors, par, K, cell_average, target, weight, factors, work,
                     sel, tab, bf, below, pw, u_new, u_low, stage)  # fmt: skip
            err = 0.0
            if not all_nonnegative(u_new):
                for q in range(u_new.size):
                    if np.isnan(u_new[q]):
                        return FALLBACK
                dt *= 0.5
                neg += 1
                why = 0
                continue
            if order > 1:
                err = error_norm(u_new, u_low, ctl[RTOL], floor)
                if err > 1.0:
                    dt *= max(0.1, 0.9 * err ** -(1.0 if rejected else expo))
                    rejected += 1
                    why = 1
                    continue
            ok = True
            break
        if not ok:
            return FALLBACK
        counts[4] += neg
        counts[5] += rejected
        counts[why] += 1
        if order > 1:
            ctl[DT_PROP] = dt * min(1.0 if rejected else 5.0, 0.9 * max(err, 1e-300) ** -expo)
        counts[TAKEN] += 1
        u[:] = u_new
        capped = dt == t_next - t
        t = t_next if capped else t + dt
        acc[TIME] = t
        flush(u, M, flush_n, flush_v)
        tally = r[3]
        acc[REFUSED] += tally[0] * dt
        acc[MERGED_N] += tally[1] * dt
        acc[MERGED_V] += tally[2] * dt
        if spraying:
            acc[LIQUID] += spray[2] * dt
        if acc[REFUSED] > allowed_refused:
            return OVERFLOW
        taken = counts[TAKEN]
        check = t < t_end and (taken >= max_steps or taken % 64 == 0)
        if capped and is_out[ev]:
            row = int(acc[ROWS])
            rec_u[row] = u
            rec_s[row, :5] = acc[:5]
            rec_s[row, 5] = taken
            acc[ROWS] = row + 1
        if check:
            return CHECK
    return DONE
