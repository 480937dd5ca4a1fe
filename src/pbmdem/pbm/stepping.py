"""The PBM's explicit time integration: the run loop of a model (:class:`TimeIntegration`, the base
of ``GranulationPBM``) and its step control (docs/pbm.md, "Time integration"). What limited each
step is counted (``STEP_LIMITS``, ``result.info["step_limits"]``)."""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field, fields

import numpy as np

from pbmdem.config import Solver

from .errors import GridOverflowError, NegativePopulationError, PBMInputError, SolverLimitError
from .fast_steps import FastSteps
from .results import Result
from .state import State, check_state, feed_volumes

TIME_EPS = 1e-12
#: time integrators (strong-stability-preserving explicit Runge-Kutta with an embedded lower order)
METHODS = ("ssp3", "heun", "euler")
#: the order of each integrator
ORDERS = {"euler": 1, "heun": 2, "ssp3": 3}
#: relative size below which state entries are flushed to zero (see GranulationPBM.run)
FLUSH = 1e-100
#: step reductions of one step (halvings after a negative entry) before a run gives up
MAX_HALVINGS = 60
#: what can limit a step (``result.info["step_limits"]`` counts them; ``rejected_*`` count retries)
STEP_LIMITS = ("positivity", "error", "max_step", "event", "rejected_negative", "rejected_error")


@dataclass
class Records:
    """The states recorded at the output times of a run (columns of the :class:`Result`)."""

    times: list = field(default_factory=list)
    number: list = field(default_factory=list)
    liquid: list = field(default_factory=list)
    gas: list = field(default_factory=list)
    liquid_added: list = field(default_factory=list)
    refused: list = field(default_factory=list)
    steps: list = field(default_factory=list)
    merged_number: list = field(default_factory=list)
    merged_volume: list = field(default_factory=list)

    def add(self, s: State):
        self.append(s.t, s.number.copy(), s.liquid.copy(), s.gas.copy(), s.liquid_added, s.refused_volume, s.steps,
                    s.merged_number, s.merged_volume)  # fmt: skip

    def append(self, *values):
        """Record a state given by its parts, in the order of the fields (arrays kept as given: the
        caller's to not modify)."""
        for f, value in zip(_RECORD_FIELDS, values, strict=True):
            getattr(self, f).append(value)

    def extend(self, *values):
        """Record several states given by their parts, each a list over the states, in the order
        of the fields (arrays kept as given)."""
        for f, value in zip(_RECORD_FIELDS, values, strict=True):
            getattr(self, f).extend(value)


_RECORD_FIELDS = tuple(f.name for f in fields(Records))


class StepControl:
    """The step sizes of one run on [t_start, t_end] with solver settings ``opt``.

    ``error_floor`` (3M,): atol x total solid / w_k, the absolute part of the error scale of
    every entry (numbers count by their solid volume, liquid and gas as volumes); ``stages(t, u,
    dt, order, spraying)`` -> (new state, embedded lower-order state, tallies (3,)) of a step of
    size dt; ``bad(t, u, why)`` raises NegativePopulationError for the entry of u that is negative
    or not finite."""

    def __init__(self, opt: Solver, t_start: float, t_end: float, error_floor: np.ndarray, stages, bad):
        from . import _compiled_steps  # lazy: numba + compiled cache ~3 s (measured), loaded when a model is built

        self._jit = _compiled_steps
        self.opt, self.t_start, self.t_end = opt, t_start, t_end
        self.order = ORDERS[opt.method]
        self.expo = 1.0 / self.order
        self.error_floor, self.stages, self.bad = error_floor, stages, bad
        self.limits = dict.fromkeys(STEP_LIMITS, 0)
        self.dt_prop = opt.max_step
        self.taken = 0
        self.wall0 = _time.perf_counter()

    def step(self, t: float, t_next: float, u: np.ndarray, k1: np.ndarray, spraying: bool):
        """One accepted step from the state u at t with rates k1, not beyond t_next: (new state,
        dt, tallies of the step (``stages``'s: refused solid, merged fragments, merged solid rates))."""
        opt, jit, stages, order = self.opt, self._jit, self.stages, self.order
        cands = (opt.safety * jit.depletion_time(u, k1), self.dt_prop, opt.max_step, t_next - t)
        dt = min(cands)
        why = cands.index(dt)
        rejected = 0
        for _ in range(MAX_HALVINGS + 1):
            u_new, u_low, tally = stages(t, u, dt, order, spraying)
            err = 0.0
            if not jit.all_nonnegative(u_new):
                if np.isnan(u_new).any():
                    self.bad(t, u_new, "NaN after a step")
                dt *= 0.5
                self.limits["rejected_negative"] += 1
                why = 0
                continue
            if self.order > 1:
                # embedded error estimate, relative to each entry (floor: atol x total solid)
                err = jit.error_norm(u_new, u_low, opt.rtol, self.error_floor)
                if err > 1.0:
                    # a second rejection in a row: the error did not fall as dt^order (a switch of
                    # the success probability inside the step): shrink as for a first-order error
                    dt *= max(0.1, 0.9 * err ** -(1.0 if rejected else self.expo))
                    rejected += 1
                    self.limits["rejected_error"] += 1
                    why = 1
                    continue
            break
        else:
            self.bad(t, u_new, f"negative even after {MAX_HALVINGS} step reductions")
        self.limits[STEP_LIMITS[why]] += 1
        if self.order > 1:
            # no growth right after a rejection (Hairer, Norsett & Wanner, Solving ODE I, II.4)
            self.dt_prop = dt * min(1.0 if rejected else 5.0, 0.9 * max(err, 1e-300) ** -self.expo)
        self.taken += 1
        return u_new, dt, tally

    def check_limits(self, t: float) -> None:
        """SolverLimitError if the run is not done at t and has used up max_steps or max_wall_time."""
        opt, taken = self.opt, self.taken
        if t >= self.t_end or (taken < opt.max_steps and (taken % 64 or self.wall_time() <= opt.max_wall_time)):
            return
        span = f"run stopped at t = {t:.6g} s of [{self.t_start:g}, {self.t_end:g}] s after {taken} steps"
        if taken >= opt.max_steps:
            raise SolverLimitError(f"{span} (solver max_steps = {opt.max_steps}); step limits so far: {self.limits}")
        raise SolverLimitError(
            f"{span} and {self.wall_time():.3g} s of wall time (solver max_wall_time = "
            f"{opt.max_wall_time:g} s); step limits so far: {self.limits}"
        )

    def wall_time(self) -> float:
        return _time.perf_counter() - self.wall0


class TimeIntegration:
    """The run loop of a PBM (the base of ``model.GranulationPBM``): :meth:`run` integrates from a
    state through the output times and spray-window edges, step by step with :class:`StepControl`
    (or in one compiled call, ``fast_steps.FastSteps``), flushes, tallies and records. The model
    supplies its classes and conversions (``_use_classes``, ``_class_state``, ``_store``,
    ``_pivot_totals``), its kernel preparation (``_prepare``, ``_input``) and its rates and stages
    (``_rates``, ``_stages``); the two-dimensional model overrides the hooks marked below."""

    #: run the steps between events in one compiled call where the kernel and selection allow it
    #: (``fast_steps``; False: the Python loop, step by step, as the tests' reference)
    fast_steps = True

    #: what can limit a step (``result.info["step_limits"]`` counts them; ``rejected_*`` count retries)
    STEP_LIMITS = STEP_LIMITS

    def _raise_bad(self, t: float, arr: np.ndarray, why: str):
        """NegativePopulationError naming the first entry of the class state ``arr`` that is
        negative or not finite."""
        K, M = self.grid.bins, self._M
        bad = ~np.isfinite(arr) | (arr < 0)
        idx = int(np.argmax(bad))
        name = ("number", "liquid", "gas")[idx // M]
        c = idx % M
        what = (
            f"bin {c} (diameter {self.grid.d[c]:.4g} m)" if c < K else f"the feed class of diameter {self._dc[c]:.4g} m"
        )
        value = float(arr[idx]) * (self.grid.x[0] if idx >= M else 1.0)
        raise NegativePopulationError(
            f"{name} of {what} became {value!r} at t = {t:.6g} s ({why}); populations must stay finite and >= 0"
        )

    def _begin(self, t_start: float, t_end: float, state: State, checked: bool = False) -> State:
        """A copy of the checked start ``state`` at t_start (``checked``: a state this model made,
        its entries not checked again); sets up the run's classes."""
        if not t_end > t_start:
            raise PBMInputError(f"run: t_end = {t_end} must be > t_start = {t_start}")
        if not checked:
            self._check_start(state)
        if abs(state.t - t_start) > TIME_EPS * max(1.0, abs(t_start)):
            raise PBMInputError(f"run: the state is at t = {state.t}, not at t_start = {t_start}")
        s = state.copy()
        s.t = t_start
        self._use_classes(self._known_classes(s) if checked else self._start_classes(s))
        self.kernel.reset()
        if self.breakage is not None:
            self.breakage.reset()
        return s

    def _check_start(self, state: State) -> None:
        """PBMInputError unless ``state`` is a state of this model's grid (the 2-D model: a State2D)."""
        K = self.grid.bins
        for name, arr in (("number", state.number), ("liquid", state.liquid), ("gas", state.gas)):
            if np.shape(arr) != (K,):
                raise PBMInputError(f"state.{name} has shape {np.shape(arr)}; expected ({K},) for this grid")

    def _known_classes(self, s: State) -> np.ndarray:
        """The feed-class volumes (m3) of the run from a start state this model made (not checked)."""
        return np.asarray(s.feed.volumes, float) if s.feed is not None else np.zeros(0)

    def _start_classes(self, s: State) -> np.ndarray:
        """The feed-class volumes (m3) of the run from its (copied) start state, checked."""
        volumes = feed_volumes(self.grid, s)
        check_state(self.grid, s, " (start of run)")
        return volumes

    def run(self, t_start: float, t_end: float, state: State, output_times=None, *, checked: bool = False):
        """Integrate from ``t_start`` (= ``state.t``) to ``t_end``; returns a :class:`Result`.

        ``output_times``: times in [t_start, t_end] to record (t_start and t_end always are).
        The input state is not modified; ``result.state`` is the state at ``t_end``. ``checked``:
        the state is one this model made (its initial state, the state of a run), whose entries
        and feed classes were checked where they entered: not checked again (a coupled loop's
        intervals; a state read from disk is checked).

        Internally volumes are in units of the first pivot x_0 (the state is [N, L/x_0, G/x_0]),
        so the steps and the result do not depend on the unit of volume. Entries below
        ``FLUSH`` (1e-100) of the total number (numbers) or of the total solid (liquid, gas) are
        set to zero after every step: they cannot matter, and keeping them would let event rates
        of far-tail bins underflow to subnormal floats.
        """
        t_start, t_end = float(t_start), float(t_end)
        s = self._begin(t_start, t_end, state, checked)
        (M, xc), x0, opt, jit = self._run_classes(), float(self.grid.x[0]), self.solver, self._jit
        outs = set()
        if output_times is not None:
            outs = {o for o in np.atleast_1d(np.asarray(output_times, float)).tolist() if t_start < o < t_end}
        edges = self.liquid.edges() if self.liquid is not None else ()
        events = sorted({t_end} | outs | {e for e in edges if t_start < e < t_end})
        rec = Records()
        self._record(rec, s)
        u = self._class_state(s)
        total_solid = float(np.sum(u[:M] * xc))  # x_0 units
        refused = s.refused_volume / x0
        merged_n, merged_v = s.merged_number, s.merged_volume / x0  # fragments merged into x_0 so far
        allowed_refused = opt.max_overflow_fraction * total_solid
        # error scale of entry k: rtol |u_k| + atol x total solid / w_k, where number entries count
        # by their solid volume (w = x_k / x_0) and liquid and gas as volumes (w = 1)
        floor = opt.atol * max(total_solid, 1e-300) / np.concatenate([xc, np.ones(2 * M)])
        ctl = StepControl(opt, t_start, t_end, floor, self._stages, self._raise_bad)
        flush_n = self._flush_n = FLUSH * self._number_total(s, u)
        flush_v = self._flush_v = FLUSH * total_solid
        jit.flush(u, M, flush_n, flush_v)
        refresh0 = getattr(self.kernel, "evaluations", None)
        t, ev = t_start, 0
        fast = FastSteps.of(self, ctl, events, outs, allowed_refused) if self.fast_steps else None
        python_step = False  # the next step is the Python loop's (the compiled one left it to it)
        while t < t_end:
            while events[ev] <= t:
                ev += 1
            t_next = events[ev]
            spraying = self.liquid is not None and self.liquid.active(t)
            self._prepare(self._input(t, self._marginal(u)))
            if fast is not None and self._factored is not None and not python_step:
                # the rest of the run in one compiled call (fast_steps); a step it leaves to Python
                # (FALLBACK) is taken below and raises its error
                tallies = [refused, merged_n, merged_v, s.liquid_added]
                code = self._advance_compiled(fast, s, rec, t, u, tallies)
                t, (refused, merged_n, merged_v, s.liquid_added) = fast.t, tallies
                if code == fast.OVERFLOW:
                    self._overflow(t, refused, total_solid)
                if code == fast.CHECK:
                    ctl.check_limits(t)
                python_step = code == fast.FALLBACK
                continue
            python_step = False
            self._rates(t, u, spraying, 0)
            k1 = self._k[0]
            if not self._steps.all_finite(k1):
                self._raise_bad(t, np.where(np.isfinite(k1), u, np.nan), "non-finite rate")
            u, dt, tally = ctl.step(t, t_next, u, k1, spraying)
            capped = dt == t_next - t
            t = t_next if capped else t + dt
            jit.flush(u, M, flush_n, flush_v)
            self._after_step(u)
            s.steps += 1
            refused_rate, merged_n_rate, merged_v_rate = tally.tolist()  # r[3], overwritten by the next step
            refused += refused_rate * dt
            merged_n += merged_n_rate * dt
            merged_v += merged_v_rate * dt
            if spraying:
                s.liquid_added += self.liquid.rate * dt
            if refused > allowed_refused:
                self._overflow(t, refused, total_solid)
            ctl.check_limits(t)
            if capped and (t in outs or t == t_end):
                self._store(s, t, u, refused, (merged_n, merged_v))
                self._record(rec, s)
        self._store(s, t_end, u, refused, (merged_n, merged_v))
        if refresh0 is not None:
            ctl.limits["kernel_refreshes"] = int(self.kernel.evaluations - refresh0)
        res = Result(self.grid, rec, s, self._info(ctl))
        res.info["grid_floor"] = res.grid_floor()  # fragments merged into the first pivot since the batch began
        return res

    # the run's class state (GranulationPBM2D: its size x liquid classes)
    def _run_classes(self) -> tuple[int, np.ndarray]:
        """(number of classes M of the run's state, their solid volumes in x_0 units)."""
        return self._M, self._xc

    def _marginal(self, u: np.ndarray) -> np.ndarray:
        """(3, M) class totals of the kernel's classes in the scaled state u."""
        return u.reshape(3, self._M)

    def _number_total(self, s: State, u: np.ndarray) -> float:
        return float(np.sum(s.number))

    def _after_step(self, u: np.ndarray) -> None:
        """What follows every step's flush (GranulationPBM2D: the classes move to their liquid band)."""

    def _record(self, rec: Records, s: State) -> None:
        rec.add(s)

    def _advance_compiled(self, fast: FastSteps, s: State, rec: Records, t: float, u: np.ndarray, tallies: list):
        """The compiled steps from u at t (``fast.advance``, u in place): the states at the output
        times it reached stored into ``s`` and added to ``rec`` as the Python loop does. Returns its code."""
        base = s.steps - fast.ctl.taken  # the start state's steps (a resumed run)
        code = fast.advance(u, t, tallies)
        x0 = float(self.grid.x[0])
        last = len(fast.records) - 1
        if last > 0:  # what _store and rec.add would record, without the state in between
            tot = self._pivot_totals_of(fast.states[:last])
            values = fast.records[:last]
            # (T, 6): time, refused solid, merged fragments, their solid (x_0 units), liquid added, steps
            rec.extend(
                values[:, 0].tolist(), list(tot[:, 0]), list(tot[:, 1] * x0), list(tot[:, 2] * x0),
                values[:, 4].tolist(), (values[:, 1] * x0).tolist(), (base + values[:, 5].astype(np.int64)).tolist(),
                values[:, 2].tolist(), (values[:, 3] * x0).tolist(),
            )  # fmt: skip
        if last >= 0:
            t_out, refused, merged_n, merged_v, liquid, taken = fast.records[last].tolist()
            s.liquid_added, s.steps = liquid, base + int(taken)
            self._store(s, t_out, fast.states[last], refused, (merged_n, merged_v))
            rec.add(s)
        s.steps = base + fast.ctl.taken
        return code

    def _overflow(self, t: float, refused: float, total_solid: float) -> None:
        """GridOverflowError: the refused solid (x_0 units) exceeds the allowed fraction."""
        allowed = self.solver.max_overflow_fraction
        x0 = self.grid.x[0]
        raise GridOverflowError(
            f"aggregation beyond the last bin (pivot {self.grid.x[-1]:.4g} m3, diameter "
            f"{self.grid.d[-1]:.4g} m): by t = {t:.6g} s aggregates carrying {refused * x0:.4g} m3 of solid "
            f"were refused, {refused / total_solid:.3g} of the total solid volume {total_solid * x0:.4g} m3; "
            f"allowed: at most max_overflow_fraction = {allowed:g} of the total solid. "
            "Raise the top of the grid (pbm.grid.max_diameter, or bins / ratio)"
        )

    def _info(self, ctl: StepControl) -> dict:
        """``result.info`` of a run."""
        return {
            "kernel": repr(self.kernel),
            "liquid_addition": repr(self.liquid),
            "consolidation": repr(self.consolidation),
            "breakage": repr(self.breakage),
            "rpm": self.rpm,
            "steps": ctl.taken,
            "wall_time_s": ctl.wall_time(),
            "method": self.solver.method,
            "aggregation_scheme": self.aggregation.name,
            "safety": self.solver.safety,
            "step_limits": ctl.limits,
            # the kernel evaluated inside the compiled rates (Kernel.factors), or called per evaluation
            "kernel_evaluation": "compiled" if self._factored is not None else "called",
            "feed_volumes": self._op.extra.tolist() if self._M > self.grid.bins else [],
        }
