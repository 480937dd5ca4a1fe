"""The PBM's time integration, compiled (numba): the stages of one explicit SSP Runge-Kutta step
(:func:`ssp_stage`; :func:`ssp_step` runs them with the rates of ``_compiled.class_rates`` in one
call, for a factored kernel; for any other kernel ``GranulationPBM`` calls the stages one by one
with the kernel called between them), the small vector operations of the step control (depletion
time, error norm, sign checks), and the step loop: the steps of ``GranulationPBM.run`` in one call
(:func:`advance`, the states at its output times recorded into buffers), for a run whose kernel
and breakage selection need no Python between steps (``pbm.fast_steps``: a factored kernel whose frequencies
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

import hashlib
import os
from pathlib import Path

import numpy as np
from numba import njit

from . import _compiled, _compiled_selection
from ._compiled import class_rates, flush, granule_porosity
from ._compiled_selection import selection_of_impacts


def drop_stale_cache(module_file: str, *dependencies: str) -> None:
    """Remove numba's cached code of the functions of ``module_file`` if the source of a module
    they call (``dependencies``) changed since it was cached. numba invalidates a cached function
    when its own file changes, not when a compiled function it calls from another file does, and
    the stale code runs silently: a change of ``_compiled.class_rates`` left the cached ``advance``
    computing the old rates (measured 2026-12-06; tests/test_numba_cache.py). The dependencies'
    hash is kept beside the cache (``__pycache__/<module>.deps``). A read-only source tree, whose
    cache numba keeps elsewhere, is not checked."""
    source = Path(module_file)
    folder, stem = source.parent / "__pycache__", source.stem
    digest = hashlib.sha256(b"".join(Path(d).read_bytes() for d in dependencies)).hexdigest()
    stamp = folder / f"{stem}.deps"
    try:
        if stamp.read_text() == digest:
            return
    except OSError:
        pass  # no stamp yet: whatever is cached may be stale
    try:
        for cached in folder.glob(f"{stem}.*.nb[ic]"):
            cached.unlink(missing_ok=True)
        folder.mkdir(exist_ok=True)
        partial = folder / f"{stem}.deps.{os.getpid()}.tmp"  # written whole, then moved into place
        partial.write_text(digest)
        partial.replace(stamp)
    except OSError:
        pass  # a read-only tree: numba caches elsewhere (not checked)


drop_stale_cache(__file__, _compiled.__file__, _compiled_selection.__file__)

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


# ----------------------------------------------------------------- the small vector operations of the step control


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
def all_finite(u):
    """True if no entry is NaN or infinite."""
    for k in range(u.size):
        if not np.isfinite(u[k]):
            return False
    return True


@njit("b1(f8[::1])", cache=True, nogil=True)
def all_nonnegative(u):
    """True if every entry is >= 0 (False for a NaN)."""
    for k in range(u.size):
        if not u[k] >= 0:
            return False
    return True


# ----------------------------------------------------------------- the stages of one step


@njit("void(f8[:, ::1], i8, i8, i8, f8)", cache=True, nogil=True)
def _combine(r, a, b, c, weight):
    """The tallies of a step, ``r[3]``: r[a] (``weight`` 0), (r[a] + r[b]) / 2 (``weight`` 1:
    Heun) or (r[a] + r[b] + 4 r[c]) / 6 (``weight`` 4: SSP-RK3)."""
    for q in range(r.shape[1]):
        if weight == 0:
            r[3, q] = r[a, q]
        elif weight == 1:
            r[3, q] = 0.5 * (r[a, q] + r[b, q])
        else:
            r[3, q] = (r[a, q] + r[b, q] + 4.0 * r[c, q]) / 6.0


@njit("b1(f8[::1], f8[::1], f8[:, ::1])", cache=True, nogil=True)
def _stage_ends_step(stage, u_new, r):
    """The step ends with ``stage`` as its new state (Euler, or an intermediate stage with a
    negative entry), the tallies those of its first rates; True."""
    for i in range(stage.size):
        u_new[i] = stage[i]
    _combine(r, 0, 0, 0, 0)
    return True


@njit("b1(i8, i8, f8, f8[::1], f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8[::1])", cache=True, nogil=True)
def ssp_stage(j, order, dt, u, k, r, stage, u_new, u_low):
    """Stage ``j`` (1, 2, 3) of one explicit SSP Runge-Kutta step of size ``dt`` from u, given
    the rates ``k[0 .. j-1]`` (3, 3M) and tallies ``r[0 .. j-1]`` (r: (4, 3): the refused solid,
    merged fragment and merged solid rates of :func:`class_rates`) of the stages before.

    Returns True if the step ends at this stage, with the new state in ``u_new`` (for ``order``
    > 1 also the embedded lower-order state in ``u_low``) and the step's refused rate in
    ``r[3]``; else False: the caller evaluates the rates ``k[j]``, ``r[j]`` at ``stage`` (at time t + dt for
    j = 1, t + dt/2 for j = 2) and calls stage j + 1. Euler (``order`` 1), SSP-RK2 (Heun, with an
    embedded Euler estimate) and SSP-RK3 (Shu & Osher 1988, with an embedded Heun estimate), in
    increment forms (zero rates leave u unchanged to the bit). An intermediate stage with a
    negative entry ends the step with that stage as ``u_new`` (the caller then halves the step)."""
    n = u.size
    k1 = k[0]
    if j == 1:
        for i in range(n):
            stage[i] = u[i] + dt * k1[i]  # u1 (Euler)
        return (order == 1 or any_negative(stage)) and _stage_ends_step(stage, u_new, r)
    k2 = k[1]
    if j == 2:
        h = 0.5 * dt
        if order == 2:
            for i in range(n):
                u_low[i] = stage[i]
                u_new[i] = u[i] + h * (k1[i] + k2[i])  # Heun (SSP-RK2)
            _combine(r, 0, 1, 0, 1)
            return True
        q = 0.25 * dt
        for i in range(n):
            k12 = k1[i] + k2[i]
            u_low[i] = u[i] + h * k12  # Heun: the embedded estimate
            stage[i] = u[i] + q * k12  # u2 of SSP-RK3
        return any_negative(stage) and _stage_ends_step(stage, u_new, r)
    k3 = k[2]
    c = dt / 6.0
    for i in range(n):
        u_new[i] = u[i] + c * ((k1[i] + k2[i]) + 4.0 * k3[i])
    _combine(r, 0, 1, 2, 4)
    return True


@njit(
    "void(f8[::1], f8[:, ::1], f8[:, ::1], f8, i8, f8[:, ::1], i8, f8[:, ::1], f8[::1], i8, b1, i8[::1], "
    "f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1], f8[:, :, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1], "
    "f8[::1], f8[::1])",
    cache=True,
    nogil=True,
)
def ssp_step(u, k, r, dt, order, beta, model, vectors, params, K, cell_average, target, weight, factors, work, sel,
             tab, bf, below, pw, u_new, u_low, stage):  # fmt: skip
    """One step of :func:`ssp_stage` with the rates of a factored kernel (:func:`class_rates`) in
    one compiled call; ``k[0]``, ``r[0]``: the rates and tallies at u. The step's tallies (refused
    solid, merged fragments, merged solid rates) are left in ``r[3]``."""
    M = vectors.shape[1]
    for j in range(1, 4):
        if ssp_stage(j, order, dt, u, k, r, stage, u_new, u_low):
            return
        class_rates(stage, beta, model, vectors, params, K, cell_average, target, weight, factors, work, sel, tab, bf,
                    below, pw, k[j].reshape((3, M)), r[j])  # fmt: skip


# ----------------------------------------------------------------- the step loop


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
