"""The batch granulator population balance and its adaptive explicit time integration.

State: numbers N_k, liquid L_k and gas (pore) G_k volume totals per bin of a :class:`Grid`
(solid S_k = N_k x_k). Balances (aggregation A: a scheme of ``aggregation.SCHEMES``, by default
the cell-average technique):

    dN_k/dt = A_N,k
    dL_k/dt = A_L,k + Q w_k [t_start <= t < t_end]
    dG_k/dt = A_G,k - c (G_k - eps_min / (1 - eps_min) S_k)

Time integration: strong-stability-preserving explicit Runge-Kutta, ``"ssp3"`` (SSP-RK3 with
an embedded Heun estimate, default), ``"heun"`` (SSP-RK2 with an embedded Euler estimate) or
``"euler"``; dt = min(safety x min over depleting entries (rate < 0) of value / |rate|, the
error-controlled step, ``max_step``, the next output time or spray-window edge) (so every step
sees a constant spray rate). What limited each step is counted in ``result.info["step_limits"]``.
A step that would leave a negative entry is repeated with half the step; after ``MAX_HALVINGS``
the run stops with NegativePopulationError naming the time and bin. A NaN stops the run at once;
``max_steps`` / ``max_wall_time`` stop it with SolverLimitError. Internally volumes are in units
of the first pivot (unit independence; docs/pbm.md, "Time integration"). ``run(t_start, t_end,
state)`` resumes from any :class:`State`, so a coupled
loop can swap the collision-frequency source between intervals.

Feed granules (``separate_feed=True``, default): the feed granules that have not aggregated yet
are classes of their own (:class:`FeedGranules`): at their own solid volume (not split onto the
pivots), with their own number, liquid and gas, so that aggregates born near a feed size do not
share their liquid with the feed granules (docs/pbm.md, "Feed granules"). The State's per-bin
totals include them, put on the pivots by the lever rule as the initial distribution is.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from pbmdem.config import Solver

from .aggregation import SCHEMES
from .errors import (
    GridOverflowError,
    KernelShapeError,
    NegativePopulationError,
    PBMInputError,
    SolverLimitError,
    positive,
)
from .grid import Grid, diameter_of
from .kernels import Kernel, KernelInput
from .processes import Consolidation, LiquidAddition
from .results import Result
from .state import FeedGranules, State, surface_fraction

TIME_EPS = 1e-12
#: time integrators (strong-stability-preserving explicit Runge-Kutta with an embedded lower order)
METHODS = ("ssp3", "heun", "euler")
#: relative size below which state entries are flushed to zero (see GranulationPBM.run)
FLUSH = 1e-100
#: step reductions of one step (halvings after a negative entry) before a run gives up
MAX_HALVINGS = 60
#: success models of a factored kernel, as ``_compiled`` numbers them (ALWAYS, STEP, LOGISTIC)
_SUCCESS_CODES = {"always": 0, "step": 1, "logistic": 2}


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
class _Records:
    times: list = field(default_factory=list)
    number: list = field(default_factory=list)
    liquid: list = field(default_factory=list)
    gas: list = field(default_factory=list)
    liquid_added: list = field(default_factory=list)
    refused: list = field(default_factory=list)
    steps: list = field(default_factory=list)

    def add(self, s: State):
        self.times.append(s.t)
        self.number.append(s.number.copy())
        self.liquid.append(s.liquid.copy())
        self.gas.append(s.gas.copy())
        self.liquid_added.append(s.liquid_added)
        self.refused.append(s.refused_volume)
        self.steps.append(s.steps)


class GranulationPBM:
    """Batch granulator PBM: aggregation (+ optional liquid addition and consolidation).

    ``kernel``: any :class:`Kernel`; ``liquid``/``consolidation``: the processes or None (off);
    ``rpm``: impeller speed handed to the kernel's collision-frequency source; ``scheme``: the
    aggregation discretisation, ``"cell_average"`` (default) or ``"fixed_pivot"``;
    ``separate_feed``: :meth:`initial_state` keeps the feed granules apart from the aggregates
    of their bins (:class:`FeedGranules`; default True), False: they share the bin's liquid and gas.
    """

    def __init__(
        self,
        grid: Grid,
        kernel: Kernel,
        liquid: LiquidAddition | None = None,
        consolidation: Consolidation | None = None,
        solver: Solver | None = None,
        rpm: float = 0.0,
        scheme: str = "cell_average",
        separate_feed: bool = True,
    ):
        self.grid = grid
        self.kernel = kernel
        self.liquid = liquid
        self.consolidation = consolidation
        self.solver = check_solver(solver if solver is not None else Solver.defaults())
        self.rpm = positive("impeller speed (rpm)", rpm, allow_zero=True)
        if scheme not in SCHEMES:
            raise PBMInputError(f"aggregation scheme = {scheme!r}; allowed: {sorted(SCHEMES)}")
        if not isinstance(separate_feed, (bool, np.bool_)):
            raise PBMInputError(f"separate_feed = {separate_feed!r}; allowed: true or false")
        self.separate_feed = bool(separate_feed)
        # building the operator imports the compiled evaluation (numba, ``_compiled``): it is loaded
        # from numba's cache, or compiled, here and not in a run
        self.aggregation = SCHEMES[scheme](grid.x, grid.edges[1:-1])
        from . import _compiled

        self._jit = _compiled
        self._operators = {(): self.aggregation}
        # internal unit of volume: the first pivot x_0 (pivots 1, r, r^2, ...)
        self._flush_n = self._flush_v = 0.0
        self._xr = grid.x / grid.x[0]
        self._spray_rate = liquid.rate / grid.x[0] if liquid is not None else 0.0
        self._consolidation_rate = consolidation.rate if consolidation is not None else 0.0
        self._use_classes(np.zeros(0))

    def __repr__(self) -> str:
        return (
            f"GranulationPBM({self.grid!r}, {self.kernel!r}, liquid={self.liquid!r}, "
            f"consolidation={self.consolidation!r}, rpm={self.rpm:g}, scheme={self.aggregation.name!r}, "
            f"separate_feed={self.separate_feed})"
        )

    def _use_classes(self, feed_volumes: np.ndarray) -> None:
        """Set up the classes of a run: the K pivots (aggregates, or everything without feed
        classes) followed by one class per feed volume (m3)."""
        key = tuple(float(v) for v in feed_volumes)
        if key == getattr(self, "_classes_key", None):
            return  # the classes of the last run (a coupled loop's intervals)
        self._classes_key = key
        op = self._operators.get(key)
        if op is None:
            op = self._operators[key] = type(self.aggregation)(self.grid.x, self.grid.edges[1:-1], extra=key)
        self._op = op
        self._M = op.M
        g = self.grid
        self._xc = op.class_volumes  # class volumes in units of x_0
        self._vc = np.concatenate([g.x, op.extra])  # class volumes (m3)
        self._dc = np.concatenate([g.d, diameter_of(op.extra)])  # class diameters (m)
        if key:
            # lever rule of the feed classes onto the pivots: numbers, and solid (liquid, gas)
            self._feed_number_w, self._feed_solid_w = g.lever_weights(op.extra)
        else:
            self._feed_number_w = self._feed_solid_w = None
        self._spray_weight = self._xc
        if self.liquid is not None and self.liquid.rule == "surface_area":
            self._spray_weight = (self._dc / g.d[0]) ** 2
        self._gas_min = (
            self.consolidation.gas_per_solid * self._xc if self.consolidation is not None else np.zeros(self._M)
        )
        # the compiled rates of a factored kernel (_use_factors)
        self._factored = self._factors_of = self._factors_key = None
        self._vectors = np.ascontiguousarray(np.stack([self._xc, self._spray_weight, self._gas_min]), dtype=float)
        self._params = (np.zeros(6), np.zeros(6))
        self._pw = np.zeros((2, self._M))
        self._stage, self._k2, self._k3 = np.empty(3 * self._M), np.empty((3, self._M)), np.empty((3, self._M))
        self._op_arrays = op.compiled_arrays()

    def _pivot_totals(self, u: np.ndarray) -> np.ndarray:
        """(3, K) per-bin totals of the class state u = [N, L, G] (3M,): the aggregates of each bin
        plus the feed classes put on the pivots by the lever rule."""
        K, M = self.grid.bins, self._M
        v = u.reshape(3, M)
        tot = v[:, :K].copy()
        if M > K:
            tot[0] += v[0, K:] @ self._feed_number_w
            tot[1:] += v[1:, K:] @ self._feed_solid_w
        return tot

    # ----------------------------------------------------------------- state helpers
    def particle_classes(self, state: State) -> tuple[np.ndarray, np.ndarray]:
        """(solid volumes (m3), numbers) of the particle classes of `state`, in ascending volume:
        the aggregates of every bin at its pivot and the feed granules not yet aggregated at their
        own sizes (without separate feed: the bins). The representative DEM sample of a coupled
        loop is made from these, so that at the start it is the feed itself."""
        if state.feed is None:
            return self.grid.x.copy(), np.asarray(state.number, float).copy()
        feed = state.feed
        wn, _ = self.grid.lever_weights(feed.volumes)
        aggregates = np.maximum(np.asarray(state.number, float) - feed.number @ wn, 0.0)
        volumes = np.concatenate([self.grid.x, feed.volumes])
        numbers = np.concatenate([aggregates, feed.number])
        order = np.argsort(volumes, kind="stable")
        return volumes[order], numbers[order]

    def initial_state(
        self,
        volumes,
        numbers,
        liquid_content: float = 0.0,
        porosity: float = 0.0,
        t: float = 0.0,
        what: str = "initial distribution",
    ) -> State:
        """State from particle classes of solid ``volumes`` (m3) and ``numbers``, each with liquid
        ``liquid_content`` x solid volume and pore volume such that G / (S + G) = ``porosity``."""
        lc = positive("initial liquid_content", liquid_content, allow_zero=True)
        eps = positive("initial porosity", porosity, allow_zero=True)
        if eps >= 1:
            raise PBMInputError(f"initial porosity = {porosity!r}; allowed: 0 <= porosity < 1")
        if self.consolidation is not None and eps < self.consolidation.min_porosity:
            raise PBMInputError(
                f"initial porosity = {eps:g} is below the minimum porosity "
                f"{self.consolidation.min_porosity:g}; allowed: porosity >= min_porosity"
            )
        N, frac = self.grid.map_particles(volumes, numbers, what=what)
        solid = np.asarray(volumes, float) * np.asarray(numbers, float)
        S_bins = solid @ frac
        state = State(float(t), N, lc * S_bins, eps / (1.0 - eps) * S_bins)
        if self.separate_feed:
            # every particle of the initial distribution is a feed granule, at its own size; classes
            # of equal volume are one feed class
            u, inverse = np.unique(np.asarray(volumes, float), return_inverse=True)
            n = np.bincount(inverse, np.asarray(numbers, float), minlength=u.size)
            keep = n > 0
            s_f = u[keep] * n[keep]
            state.feed = FeedGranules(u[keep], n[keep], lc * s_f, eps / (1.0 - eps) * s_f)
            # the bin totals exactly as a run writes them (aggregates 0 + the feed's lever rule)
            wn, ws = self.grid.lever_weights(u[keep])
            f = state.feed
            state.number, state.liquid, state.gas = f.number @ wn, f.liquid @ ws, f.gas @ ws
        return state

    def kernel_input(self, t: float, N, L, G) -> KernelInput:
        """Kernel input at (t, N, L, G); L and G in m3 or in any unit (only ratios are used)."""
        S = N * self.grid.x
        return KernelInput(
            t=t,
            volumes=self.grid.x,
            diameters=self.grid.d,
            numbers=N,
            surface_fraction=surface_fraction(S, L, G),
            rpm=self.rpm,
        )

    def rates(self, t: float, N, L, G, spraying: bool):
        """Rates (dN, dL, dG) in m3 and the refused solid-volume rate (m3/s) at (t, N, L, G)
        (per-bin totals, no feed classes)."""
        self._use_classes(np.zeros(0))
        x0 = self.grid.x[0]
        u = np.concatenate([N, np.asarray(L, float) / x0, np.asarray(G, float) / x0])
        inp = self.kernel_input(t, N, L, G)
        self.kernel.prepare(inp)
        self._use_factors(inp)
        d, refused = self._rates(t, u, spraying)
        K = self.grid.bins
        return d[:K], d[K : 2 * K] * x0, d[2 * K :] * x0, refused * x0

    def _rates(self, t: float, u: np.ndarray, spraying: bool, beta: np.ndarray | None = None):
        """Rates (3M,) of the scaled class state u = [N, L/x_0, G/x_0] (M classes: the K pivots and the
        feed classes of the run, :meth:`_use_classes`) and the refused solid rate (x_0 units).

        Volumes enter only as ratios to the first pivot x_0, so the same problem in m3, mm3 or
        units of x_0 gives the same numbers (up to the rounding of the unit conversion).
        ``beta``: the kernel matrix if the caller has it for this state.
        """
        M = self._M
        if self._factored is not None:
            # a factored kernel (Kernel.factors): flush, kernel, aggregation, spraying and
            # consolidation in one compiled call
            d = np.empty((3, M))
            refused = self._jit.class_rates(
                u,
                self._factored,
                self._success_code,
                self._vectors,
                self._params[1] if spraying else self._params[0],
                *self._op_arrays,
                self._pw,
                d,
            )
            return d.reshape(-1), refused
        if self._flush_n > 0 and self._jit.below_flush(u, self._flush_vec):
            # entries below the flush level count as zero (they are zeroed after every step; here
            # also inside a step, so no event rate can underflow)
            u = u.copy()
            self._jit.flush(u, M, self._flush_n, self._flush_v)  # a class flushed loses L, G too
            beta = None
        nlg = u.reshape(3, M)
        if beta is None:
            beta = self.kernel(self._input(t, nlg))
        d, refused = self._op.totals_stacked(beta, nlg)
        # spraying (Q shared in proportion to N_k w_k) and consolidation -c (G_k - G_min,k)
        self._jit.add_processes(
            d, nlg, self._spray_rate if spraying else 0.0, self._spray_weight, self._consolidation_rate, self._gas_min
        )
        return d.reshape(-1), refused

    def _stages(self, t: float, u: np.ndarray, k1: np.ndarray, r1: float, dt: float, order: int, spraying: bool):
        """The stages of one step of size dt from u (rates k1, refused rate r1): (new state, the
        embedded lower-order state or None, refused rate of the step). A stage with a negative
        entry ends the step with that stage as the new state (the caller halves the step). With a
        factored kernel one compiled call (``_compiled.ssp_stages``, the same operations)."""
        if self._factored is not None:
            n = u.size
            u_new, u_low = np.empty(n), np.empty(n)
            refused_rate, _ = self._jit.ssp_stages(
                u,
                k1,
                r1,
                dt,
                order,
                self._factored,
                self._success_code,
                self._vectors,
                self._params[1] if spraying else self._params[0],
                *self._op_arrays,
                self._pw,
                u_new,
                u_low,
                self._stage,
                self._k2,
                self._k3,
            )
            return u_new, u_low, refused_rate
        jit = self._jit
        u1 = u + dt * k1
        if order == 1 or jit.any_negative(u1):
            return u1, None, r1
        k2, r2 = self._rates(t + dt, u1, spraying)
        # increment forms of the Shu-Osher stages: zero rates leave u exactly unchanged
        k12 = k1 + k2
        u_h = u + (0.5 * dt) * k12  # Heun (SSP-RK2)
        if order == 2:
            return u_h, u1, 0.5 * (r1 + r2)
        u2 = u + (0.25 * dt) * k12  # SSP-RK3 (Shu & Osher 1988)
        if jit.any_negative(u2):
            return u2, u_h, r1
        k3, r3 = self._rates(t + 0.5 * dt, u2, spraying)
        return u + (dt / 6.0) * (k12 + 4.0 * k3), u_h, (r1 + r2 + 4.0 * r3) / 6.0

    def _use_factors(self, inp: KernelInput) -> None:
        """Ask the kernel for its factors at this step (after ``prepare``): the compiled rates use
        them until the next step; None: :meth:`_rates` calls the kernel."""
        factors = getattr(self.kernel, "factors", None)  # kernels need not derive from Kernel
        f = factors(inp) if factors is not None else None
        if f is None:
            self._factored = self._factors_of = None
            return
        S, model, threshold, width = f
        key = (model, threshold, width, self._flush_n, self._flush_v)
        if S is self._factors_of and key == self._factors_key:
            return  # the kernel's factors of the last step
        if np.shape(S) != (self._M, self._M):
            raise KernelShapeError(
                f"kernel {self.kernel!r} returned factors of shape {np.shape(S)}; expected "
                f"({self._M}, {self._M}) for the {self._M} classes"
            )
        self._factors_of, self._factors_key = S, key
        self._factored = np.ascontiguousarray(S, dtype=float)
        self._success_code = _SUCCESS_CODES[model]
        base = [self._flush_n, self._flush_v, float(threshold), float(width), 0.0, self._consolidation_rate]
        self._params[0][:] = base
        self._params[1][:] = base
        self._params[1][4] = self._spray_rate

    def _input(self, t: float, nlg: np.ndarray) -> KernelInput:
        """KernelInput of the scaled class state (3, M): surface-liquid fraction from class totals."""
        phi = np.empty(nlg.shape[1])
        self._jit.surface_fraction(nlg, self._xc, phi)  # max(L - G, 0) / (S + max(L, G)), 0 if empty
        return KernelInput(
            t=t,
            volumes=self._vc,
            diameters=self._dc,
            numbers=nlg[0],
            surface_fraction=phi,
            rpm=self.rpm,
            feed_weights=self._feed_number_w,
        )

    def check_state(self, s: State, where: str = "") -> None:
        arrays = [("number", s.number, None), ("liquid", s.liquid, None), ("gas", s.gas, None)]
        if s.feed is not None:
            d = diameter_of(s.feed.volumes)
            arrays += [
                ("feed number", s.feed.number, d),
                ("feed liquid", s.feed.liquid, d),
                ("feed gas", s.feed.gas, d),
            ]
        for name, arr, d in arrays:
            bad = ~np.isfinite(arr) | (arr < 0)
            if bad.any():
                k = int(np.argmax(bad))
                where_k = (
                    f"bin {k} (diameter {self.grid.d[k]:.4g} m)"
                    if d is None
                    else f"the feed class of diameter {d[k]:.4g} m"
                )
                raise NegativePopulationError(
                    f"{name} of {where_k} is {float(arr[k])!r} at t = {s.t:.6g} s{where}; allowed: finite values >= 0"
                )

    def _check_feed(self, s: State) -> np.ndarray:
        """Volumes of the state's feed classes (checked: distinct, on the grid, shapes; their
        share of every bin at most the bin's total)."""
        f = s.feed
        if f is None:
            return np.zeros(0)
        g = self.grid
        v = np.asarray(f.volumes, float)
        P = v.size
        if (
            v.ndim != 1
            or np.unique(v).size != P
            or not np.all(np.isfinite(v))
            or (P and (v.min() < g.x[0] * (1 - 1e-12) or v.max() > g.x[-1] * (1 + 1e-12)))
        ):
            raise PBMInputError(
                f"state.feed.volumes = {v.tolist()}; allowed: distinct solid volumes within the "
                f"grid, {g.x[0]:.4g} .. {g.x[-1]:.4g} (x_0 .. x_(K-1))"
            )
        for name in ("number", "liquid", "gas"):
            if np.shape(getattr(f, name)) != (P,):
                raise PBMInputError(f"state.feed.{name} has shape {np.shape(getattr(f, name))}; expected ({P},)")
        wn, ws = g.lever_weights(v)
        for name, w in (("number", wn), ("liquid", ws), ("gas", ws)):
            part, total = np.asarray(getattr(f, name), float) @ w, getattr(s, name)
            over = part > total * (1.0 + 1e-9) + 1e-300
            if over.any():
                k = int(np.argmax(over))
                raise PBMInputError(
                    f"state.feed.{name} puts {part[k]!r} into bin {k}, more than the bin's total "
                    f"{total[k]!r}; the feed granules are part of the bin totals"
                )
        return v

    # ----------------------------------------------------------------- integration
    #: what can limit a step (``result.info["step_limits"]`` counts them; ``rejected_*`` count retries)
    STEP_LIMITS = ("positivity", "error", "max_step", "event", "rejected_negative", "rejected_error")

    def _raise_bad(self, t: float, arr: np.ndarray, why: str, scale: float = 1.0):
        K, M = self.grid.bins, self._M
        bad = ~np.isfinite(arr) | (arr < 0)
        idx = int(np.argmax(bad))
        name = ("number", "liquid", "gas")[idx // M]
        c = idx % M
        what = (
            f"bin {c} (diameter {self.grid.d[c]:.4g} m)" if c < K else f"the feed class of diameter {self._dc[c]:.4g} m"
        )
        value = float(arr[idx]) * (scale if idx >= M else 1.0)
        raise NegativePopulationError(
            f"{name} of {what} became {value!r} at t = {t:.6g} s ({why}); populations must stay finite and >= 0"
        )

    def run(self, t_start: float, t_end: float, state: State, output_times=None):
        """Integrate from ``t_start`` (= ``state.t``) to ``t_end``; returns a :class:`Result`.

        ``output_times``: times in [t_start, t_end] to record (t_start and t_end always are).
        The input state is not modified; ``result.state`` is the state at ``t_end``.

        Internally volumes are in units of the first pivot x_0 (the state is [N, L/x_0, G/x_0]),
        so the steps and the result do not depend on the unit of volume. Entries below
        ``FLUSH`` (1e-100) of the total number (numbers) or of the total solid (liquid, gas) are
        set to zero after every step: they cannot matter, and keeping them would let event rates
        of far-tail bins underflow to subnormal floats.
        """
        t_start, t_end = float(t_start), float(t_end)
        if not t_end > t_start:
            raise PBMInputError(f"run: t_end = {t_end} must be > t_start = {t_start}")
        if abs(state.t - t_start) > TIME_EPS * max(1.0, abs(t_start)):
            raise PBMInputError(f"run: the state is at t = {state.t}, not at t_start = {t_start}")
        K = self.grid.bins
        for name, arr in (("number", state.number), ("liquid", state.liquid), ("gas", state.gas)):
            if np.shape(arr) != (K,):
                raise PBMInputError(f"state.{name} has shape {np.shape(arr)}; expected ({K},) for this grid")
        s = state.copy()
        s.t = t_start
        feed_volumes = self._check_feed(s)
        self.check_state(s, " (start of run)")
        self._use_classes(feed_volumes)
        M = self._M
        self.kernel.reset()
        wall0 = _time.perf_counter()
        opt = self.solver

        outs = set()
        if output_times is not None:
            outs = {float(o) for o in np.atleast_1d(output_times) if t_start < float(o) < t_end}
        events = {t_end} | outs
        if self.liquid is not None:
            events.update(e for e in self.liquid.edges() if t_start < e < t_end)
        events = sorted(events)
        record_at = outs | {t_end}
        rec = _Records()
        rec.add(s)

        x0 = float(self.grid.x[0])
        xr = self._xc
        if feed_volumes.size:
            # classes [aggregates of the K bins, feed classes]: aggregates = bin totals - feed
            parts = []
            for total, part, scale, w in (
                (s.number, s.feed.number, 1.0, self._feed_number_w),
                (s.liquid, s.feed.liquid, x0, self._feed_solid_w),
                (s.gas, s.feed.gas, x0, self._feed_solid_w),
            ):
                feed = np.asarray(part, float) / scale
                parts += [np.maximum(total / scale - feed @ w, 0.0), feed]
            u = np.concatenate(parts)
        else:
            u = np.concatenate([s.number, s.liquid / x0, s.gas / x0])
        total_solid = float(np.sum(u[:M] * xr))  # x_0 units
        allowed_refused = opt.max_overflow_fraction * total_solid
        refused = s.refused_volume / x0
        # error scale of entry k: rtol |u_k| + atol x total solid / w_k, where number entries count
        # by their solid volume (w = x_k / x_0) and liquid and gas as volumes (w = 1)
        err_floor = opt.atol * max(total_solid, 1e-300) / np.concatenate([xr, np.ones(2 * M)])
        flush_n = self._flush_n = FLUSH * float(np.sum(s.number))
        flush_v = self._flush_v = FLUSH * total_solid
        self._flush_vec = np.concatenate([np.full(M, flush_n), np.full(2 * M, flush_v)])
        jit = self._jit
        jit.flush(u, M, flush_n, flush_v)
        rtol = opt.rtol
        order = {"euler": 1, "heun": 2, "ssp3": 3}[opt.method]
        expo = 1.0 / order
        limits = dict.fromkeys(self.STEP_LIMITS, 0)
        refresh0 = getattr(self.kernel, "evaluations", None)
        t = t_start
        steps = s.steps
        taken = 0
        ev = 0
        dt_prop = opt.max_step
        spraying_rate = self.liquid.rate if self.liquid is not None else 0.0
        while t < t_end:
            while events[ev] <= t:
                ev += 1
            t_next = events[ev]
            spraying = self.liquid is not None and self.liquid.active(t)
            inp = self._input(t, u.reshape(3, M))
            self.kernel.prepare(inp)
            self._use_factors(inp)
            k1, r1 = self._rates(t, u, spraying, None if self._factored is not None else self.kernel(inp))
            if not np.isfinite(k1).all():
                self._raise_bad(t, np.where(np.isfinite(k1), u, np.nan), "non-finite rate", x0)
            dt_pos = opt.safety * jit.depletion_time(u, k1)  # min u / -rate over rate < 0
            cands = (dt_pos, dt_prop, opt.max_step, t_next - t)
            dt = min(cands)
            why = cands.index(dt)
            rejected = 0
            for _ in range(MAX_HALVINGS + 1):
                u_new, u_low, refused_rate = self._stages(t, u, k1, r1, dt, order, spraying)
                err = 0.0
                if not jit.all_nonnegative(u_new):
                    if np.isnan(u_new).any():
                        self._raise_bad(t, u_new, "NaN after a step", x0)
                    dt *= 0.5
                    limits["rejected_negative"] += 1
                    why = 0
                    continue
                if order > 1:
                    # embedded error estimate, relative to each entry (floor: atol x total solid)
                    err = jit.error_norm(u_new, u_low, rtol, err_floor)
                    if err > 1.0:
                        # a second rejection in a row: the error did not fall as dt^order (a
                        # switch of the success probability inside the step): shrink as for a
                        # first-order error
                        dt *= max(0.1, 0.9 * err ** -(1.0 if rejected else expo))
                        rejected += 1
                        limits["rejected_error"] += 1
                        why = 1
                        continue
                break
            else:
                self._raise_bad(t, u_new, f"negative even after {MAX_HALVINGS} step reductions", x0)
            limits[("positivity", "error", "max_step", "event")[why]] += 1
            if order > 1:
                # no growth right after a rejection (Hairer, Norsett & Wanner, Solving ODE I, II.4)
                dt_prop = dt * min(1.0 if rejected else 5.0, 0.9 * max(err, 1e-300) ** -expo)
            capped = dt == t_next - t
            t = t_next if capped else t + dt
            u = u_new
            jit.flush(u, M, flush_n, flush_v)
            steps += 1
            taken += 1
            refused += refused_rate * dt
            if spraying:
                s.liquid_added += spraying_rate * dt
            if refused > allowed_refused:
                raise GridOverflowError(
                    f"aggregation beyond the last bin (pivot {self.grid.x[-1]:.4g} m3, diameter "
                    f"{self.grid.d[-1]:.4g} m): by t = {t:.6g} s aggregates carrying {refused * x0:.4g} m3 of solid "
                    f"were refused, {refused / total_solid:.3g} of the total solid volume {total_solid * x0:.4g} m3; "
                    f"allowed: at most max_overflow_fraction = {opt.max_overflow_fraction:g} of the total solid. "
                    "Raise the top of the grid (pbm.grid.max_diameter, or bins / ratio)"
                )
            if taken >= opt.max_steps and t < t_end:
                raise SolverLimitError(
                    f"run stopped at t = {t:.6g} s of [{t_start:g}, {t_end:g}] s after {taken} steps "
                    f"(solver max_steps = {opt.max_steps}); step limits so far: {limits}"
                )
            if taken % 64 == 0 and _time.perf_counter() - wall0 > opt.max_wall_time and t < t_end:
                raise SolverLimitError(
                    f"run stopped at t = {t:.6g} s of [{t_start:g}, {t_end:g}] s after {taken} steps and "
                    f"{_time.perf_counter() - wall0:.3g} s of wall time (solver max_wall_time = "
                    f"{opt.max_wall_time:g} s); step limits so far: {limits}"
                )
            if capped and t in record_at:
                s.t, s.steps = t, steps
                self._store(s, u, x0)
                s.refused_volume = refused * x0
                rec.add(s)
        s.t, s.steps = t_end, steps
        self._store(s, u, x0)
        s.refused_volume = refused * x0
        if refresh0 is not None:
            limits["kernel_refreshes"] = int(self.kernel.evaluations - refresh0)
        info = {
            "kernel": repr(self.kernel),
            "liquid_addition": repr(self.liquid),
            "consolidation": repr(self.consolidation),
            "rpm": self.rpm,
            "steps": taken,
            "wall_time_s": _time.perf_counter() - wall0,
            "method": opt.method,
            "aggregation_scheme": self.aggregation.name,
            "safety": opt.safety,
            "step_limits": limits,
            # the kernel evaluated inside the compiled rates (Kernel.factors), or called per evaluation
            "kernel_evaluation": "compiled" if self._factored is not None else "called",
            "feed_volumes": feed_volumes.tolist(),
        }
        return Result(self.grid, rec, s, info)

    def _store(self, s: State, u: np.ndarray, x0: float) -> None:
        """Write the class state u (x_0 units) into ``s``: per-bin totals and the feed classes."""
        tot = self._pivot_totals(u)
        s.number, s.liquid, s.gas = tot[0], tot[1] * x0, tot[2] * x0
        if self._M > self.grid.bins:
            K, M = self.grid.bins, self._M
            v = u.reshape(3, M)[:, K:]
            s.feed = FeedGranules(self._op.extra.copy(), v[0].copy(), v[1] * x0, v[2] * x0)
