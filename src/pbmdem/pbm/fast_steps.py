"""The compiled step loop of a run (``_compiled_steps.advance``) and when it may be used: when
neither the kernel nor the breakage selection can change anything inside the run (a factored
:class:`~pbmdem.pbm.kernels.CollisionKernel` whose source is ``fixed_for_diameters``, and no
breakage or a selection with ``compiled_steps``), the whole run is one compiled call; otherwise the
Python loop takes one step at a time. Both give the same results to the bit
(tests/test_pbm_fast_steps.py)."""

from __future__ import annotations

import numpy as np

from pbmdem.impact import VELOCITY_EDGES

from .kernels import CollisionKernel

_NO_IMPACTS = (np.zeros((0, 0)), np.zeros((0, 0, 0)), np.zeros((0, 0)), np.zeros((0, 0, 0)))


class FastSteps:
    """The compiled steps of one run of ``model`` with step control ``ctl`` (stepping.StepControl),
    or :meth:`of` None when the run's kernel or selection need Python between steps."""

    @classmethod
    def of(cls, model, ctl, events: list, outs: set, allowed_refused: float) -> FastSteps | None:
        kernel, brk = model.kernel, model.breakage
        if type(kernel) is not CollisionKernel or kernel.success.velocity_dependent:
            return None
        if not getattr(kernel.source, "fixed_for_diameters", False):
            return None
        # the selection's own class (not a subclass) declares that the compiled loop may evaluate it
        if brk is not None and not type(brk.selection).__dict__.get("compiled_steps", False):
            return None
        return cls(model, ctl, events, outs, allowed_refused)

    def __init__(self, model, ctl, events: list, outs: set, allowed_refused: float):
        from . import _compiled_steps  # numba: imported with the model's compiled rates, not by pbmdem.pbm

        self._cs = cs = _compiled_steps
        self.DONE, self.CHECK, self.OVERFLOW, self.FALLBACK = cs.DONE, cs.CHECK, cs.OVERFLOW, cs.FALLBACK
        self.model, self.ctl = model, ctl
        self.allowed_refused = float(allowed_refused)
        opt = ctl.opt
        self.state = np.array([opt.safety, ctl.dt_prop, opt.max_step, opt.rtol, ctl.expo, 0.0, 0.0])
        self.acc = np.zeros(6)
        self.counts = np.zeros(7, dtype=np.int64)
        M, K = model._M, model.grid.bins
        self.work = (np.empty(3 * M), np.empty(3 * M), np.empty(3 * M))
        self.eps, self.nbin, self.sel_new = np.empty(M), np.empty(K), np.empty(K)
        w = model._feed_number_w if model._feed_number_w is not None else np.zeros((0, K))
        self.feed_w = np.ascontiguousarray(w, dtype=float)
        self.diameters = np.ascontiguousarray(model.grid.d, dtype=float)
        self.events = np.array(events, dtype=float)
        self.is_out = np.array([e in outs or e == events[-1] for e in events])
        self.rec_u, self.rec_s = np.empty((len(events), 3 * M)), np.empty((len(events), 6))
        liquid = model.liquid
        self.spray = np.array([liquid.t_start, liquid.t_end, liquid.rate] if liquid is not None else [0.0, 0.0, 0.0])

    def advance(self, u: np.ndarray, t: float, tallies: list) -> int:
        """Steps of the model from u at t (prepared in Python for this step) to the end of the run,
        u in place; ``tallies`` [refused, merged number, merged solid (x_0 units), liquid added (m3)]
        updated. Returns the code of ``_compiled_steps`` (``self.t``: the time reached; at each
        output time reached a row of ``self.records``, the tallies and the steps taken (6,), and
        of ``self.states``, the class state (3M,): views of the buffers, valid until the next call)."""
        m, ctl, cs = self.model, self.ctl, self._cs
        brk, sel = m.breakage, None
        state, acc, counts = self.state, self.acc, self.counts
        state[cs.DT_PROP] = ctl.dt_prop
        state[cs.INTERVAL] = getattr(m.kernel, "update_interval", 0.0)
        if brk is not None:
            sel = brk.selection
            state[cs.T_EVAL] = brk._t_eval
            impacts, columns, strength = sel._arrays, sel._columns, sel._strength
            speeds, probability = sel._work
            porous, spread = sel.porosity_exponent != 0.0, sel.strength_spread
        else:
            impacts, strength, speeds, probability = _NO_IMPACTS, np.zeros(6), np.zeros(0), np.zeros((0, 0))
            columns = np.zeros(0, dtype=np.int64)
            porous, spread = False, 0.0
        acc[:5] = (t, *tallies)
        acc[cs.ROWS] = 0.0
        counts[:] = 0
        counts[cs.TAKEN] = ctl.taken
        code = cs.advance(
            u, self.events, self.is_out, self.events[-1], ctl.order, state, acc, counts, ctl.error_floor, m._k, m._r,
            m._factored, m._success_code, m._vectors, np.stack(m._params), *m._op_arrays, *m._brk_arrays, m._pw,
            *self.work, m._flush_n, m._flush_v, self.spray, self.allowed_refused, ctl.opt.max_steps, self.feed_w,
            self.eps,
            self.nbin, porous, self.diameters, strength, spread, VELOCITY_EDGES, impacts, columns,
            sel.pairs if sel is not None else False, speeds, probability, self.sel_new, self.rec_u, self.rec_s,
        )  # fmt: skip
        ctl.dt_prop = float(state[cs.DT_PROP])
        ctl.taken = int(counts[cs.TAKEN])
        for name, n in zip(ctl.limits, counts[:6].tolist(), strict=False):
            ctl.limits[name] += n
        if brk is not None:
            brk._t_eval = float(state[cs.T_EVAL])
        self.t = float(acc[cs.TIME])
        rows = int(acc[cs.ROWS])
        self.records, self.states = self.rec_s[:rows], self.rec_u[:rows]
        tallies[:] = acc[1:5].tolist()
        return int(code)
