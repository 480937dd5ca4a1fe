"""Step control of the PBM's explicit time integration: the solver settings, the step size and
its rejections, the run's limits and the records of the output times.

dt = min(safety x min over depleting entries (rate < 0) of value / |rate|, the error-controlled
step, ``max_step``, the next output time or spray-window edge). A step that would leave a
negative entry is repeated with half the step; after ``MAX_HALVINGS`` the run stops with
NegativePopulationError. A step whose embedded error estimate exceeds 1 is repeated with a
smaller step. What limited each step is counted (``STEP_LIMITS``, ``result.info["step_limits"]``).
The stages of a step are the model's (``GranulationPBM._stages``, compiled in ``_compiled_steps``).
The rates are those of every process at once (aggregation, breakage, spraying, consolidation),
so the deaths of breakage limit the step and trigger the halvings as those of aggregation do.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from pbmdem.config import Solver

from .errors import PBMInputError, SolverLimitError, positive
from .state import State

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


def check_solver(opt: Solver) -> Solver:
    """The solver settings `opt` if every value is allowed, else PBMInputError naming it (the
    schema checks a configuration; this checks settings made in code, e.g. Solver.replace)."""
    if opt.method not in METHODS:
        raise PBMInputError(f"solver method = {opt.method!r}; allowed: {list(METHODS)}")
    safety = positive("solver safety", opt.safety)
    if safety > 1:
        raise PBMInputError(
            f"solver safety = {opt.safety!r}; allowed: 0 < safety <= 1 (fraction of the fastest depletion time)"
        )
    if opt.max_step != np.inf:
        positive("solver max_step (s)", opt.max_step)
    positive("solver rtol", opt.rtol)
    positive("solver atol", opt.atol)
    positive("solver max_overflow_fraction", opt.max_overflow_fraction, allow_zero=True)
    if isinstance(opt.max_steps, bool) or int(opt.max_steps) != opt.max_steps or opt.max_steps < 1:
        raise PBMInputError(f"solver max_steps = {opt.max_steps!r}; allowed: an integer >= 1")
    positive("solver max_wall_time (s)", opt.max_wall_time)
    return opt


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

    def append(self, t, number, liquid, gas, liquid_added, refused, steps, merged_number, merged_volume):
        """Record a state given by its parts (arrays kept as given: the caller's to not modify)."""
        self.times.append(t)
        self.number.append(number)
        self.liquid.append(liquid)
        self.gas.append(gas)
        self.liquid_added.append(liquid_added)
        self.refused.append(refused)
        self.steps.append(steps)
        self.merged_number.append(merged_number)
        self.merged_volume.append(merged_volume)


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
