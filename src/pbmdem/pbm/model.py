"""The batch granulator population balance and its adaptive explicit time integration.

State: numbers N_k, liquid L_k and gas (pore) G_k volume totals per bin of a :class:`Grid`
(solid S_k = N_k x_k). Balances (aggregation A: a scheme of ``aggregation.SCHEMES``, by default
the cell average; breakage B, optional: ``breakage.Breakage``):

    dN_k/dt = A_N,k + B_N,k
    dL_k/dt = A_L,k + B_L,k + Q w_k [t_start <= t < t_end]
    dG_k/dt = A_G,k + B_G,k - c (G_k - eps_min / (1 - eps_min) S_k)

Time integration: strong-stability-preserving explicit Runge-Kutta, ``"ssp3"`` (SSP-RK3 with
an embedded Heun estimate, default), ``"heun"`` (SSP-RK2 with an embedded Euler estimate) or
``"euler"``, with positivity- and error-controlled steps (``stepping``). Internally volumes are
in units of the first pivot (unit independence; docs/pbm.md, "Time integration"). ``run(t_start,
t_end, state)`` resumes from any :class:`State`, so a coupled loop can swap the
collision-frequency source between intervals.

Every rate and every stage is computed by the compiled backend (``_compiled``,
``_compiled_steps``): a factored
kernel (``Kernel.factors``) inside it, any other kernel called here and its matrix passed in.

Feed granules (``separate_feed=True``, default): the feed granules not yet aggregated are classes
of their own (:class:`FeedGranules`, docs/pbm.md, "Feed granules"), in the State's per-bin totals
by the lever rule.
"""

from __future__ import annotations

import numpy as np

from pbmdem.config import Solver

from .aggregation import SCHEMES, operator
from .breakage import Breakage, breakage_arrays
from .errors import GridOverflowError, KernelShapeError, NegativePopulationError, PBMInputError, positive
from .fast_steps import FastSteps
from .grid import Grid, diameter_of
from .kernels import Kernel, KernelInput
from .processes import Consolidation, LiquidAddition
from .results import Result
from .state import FeedGranules, State, check_state, feed_volumes
from .stepping import FLUSH, STEP_LIMITS, TIME_EPS, Records, StepControl, check_solver

__all__ = ["GranulationPBM", "check_solver"]


class GranulationPBM:
    """Batch granulator PBM: aggregation (+ optional liquid addition, consolidation, breakage).

    ``kernel``: any :class:`Kernel`; ``liquid``/``consolidation``: the processes or None (off);
    ``rpm``: impeller speed handed to the kernel's collision-frequency source; ``scheme``: the
    aggregation discretisation, ``"cell_average"`` (default) or ``"fixed_pivot"``;
    ``separate_feed``: :meth:`initial_state` keeps the feed granules apart from the aggregates
    of their bins (:class:`FeedGranules`; default True), False: they share the bin's liquid and gas;
    ``breakage``: a :class:`Breakage` or None (aggregation only).
    """

    #: run the steps between events in one compiled call where the kernel and selection allow it
    #: (``fast_steps``; False: the Python loop, step by step, as the tests' reference)
    fast_steps = True

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
        breakage: Breakage | None = None,
    ):
        self.grid = grid
        self.kernel = kernel
        self.liquid = liquid
        self.consolidation = consolidation
        self.solver = check_solver(solver if solver is not None else Solver.defaults())
        self.set_rpm(rpm)
        if scheme not in SCHEMES:
            raise PBMInputError(f"aggregation scheme = {scheme!r}; allowed: {sorted(SCHEMES)}")
        if not isinstance(separate_feed, (bool, np.bool_)):
            raise PBMInputError(f"separate_feed = {separate_feed!r}; allowed: true or false")
        self.separate_feed = bool(separate_feed)
        self.breakage = breakage
        self._brk_arrays = breakage_arrays(breakage, grid.x, grid.edges)  # None: an empty selection
        # building the operator imports the compiled evaluation (numba, ``_compiled``): it is loaded
        # from numba's cache, or compiled, here and not in a run
        self.aggregation = operator(SCHEMES[scheme], grid, ())
        from . import _compiled, _compiled_steps  # lazy: numba + compiled cache ~3 s (measured), at model build

        self._jit, self._steps = _compiled, _compiled_steps
        self._operators = {(): self.aggregation}
        # internal unit of volume: the first pivot x_0 (pivots 1, r, r^2, ...)
        self._flush_n = self._flush_v = 0.0
        self._xr = grid.x / grid.x[0]
        self._spray_rate = liquid.rate / grid.x[0] if liquid is not None else 0.0
        self._consolidation_rate = consolidation.rate if consolidation is not None else 0.0
        self._use_classes(np.zeros(0))

    def set_rpm(self, rpm: float) -> None:
        """The impeller speed of the next runs (the kernel's input; a model reused at another speed)."""
        self.rpm = positive("impeller speed (rpm)", rpm, allow_zero=True)

    def __repr__(self) -> str:
        return (
            f"GranulationPBM({self.grid!r}, {self.kernel!r}, liquid={self.liquid!r}, "
            f"consolidation={self.consolidation!r}, rpm={self.rpm:g}, scheme={self.aggregation.name!r}, "
            f"separate_feed={self.separate_feed}, breakage={self.breakage!r})"
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
            op = self._operators[key] = operator(type(self.aggregation), self.grid, key)
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
        # the arguments of the compiled rates (_use_factors: the kernel's factors and success model)
        self._factored = self._factors_of = self._factors_key = None
        self._success_code = 0
        self._vectors = np.ascontiguousarray(np.stack([self._xc, self._spray_weight, self._gas_min]), dtype=float)
        self._params = (np.zeros(6), np.zeros(6))
        self._set_params(0.0, 1.0)
        self._pw = np.zeros((2, self._M))
        # work of the stages: the rates k (3, 3M) and tallies r (4, 3: refused solid, merged
        # fragments, merged solid; ``_compiled.class_rates``) of the stages, a stage
        self._k, self._r, self._stage = np.empty((3, 3 * self._M)), np.zeros((4, 3)), np.empty(3 * self._M)
        self._k_rows = [k.reshape(3, self._M) for k in self._k]  # the rates of stage j as (3, M)
        self._r_rows = list(self._r)  # the tallies of stage j (views, made once)
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

    def _rates(self, t: float, u: np.ndarray, spraying: bool, j: int) -> None:
        """Rates of the scaled class state u = [N, L/x_0, G/x_0] (M classes: the K pivots and the
        feed classes of the run, :meth:`_use_classes`) into ``self._k[j]`` (3M,), and its tallies
        (refused solid, fragments merged into the first pivot and their solid, x_0 units) into
        ``self._r[j]``. One compiled call (``_compiled.class_rates``: flush, kernel,
        aggregation, breakage, spraying, consolidation); a kernel without factors is called here,
        at the flushed state, and its matrix passed in.

        Volumes enter only as ratios to the first pivot x_0, so the same problem in m3, mm3 or
        units of x_0 gives the same numbers (up to the rounding of the unit conversion).
        """
        beta = self._factored
        if beta is None:
            if self._flush_n > 0:  # the kernel sees the state as the compiled rates do
                u = self._jit.flushed(u, self._M, self._flush_n, self._flush_v)
            beta = np.ascontiguousarray(self.kernel(self._input(t, u.reshape(3, self._M))), dtype=float)
            self._check_shape("shape", beta)
        self._jit.class_rates(
            u,
            beta,
            self._success_code,
            self._vectors,
            self._params[1] if spraying else self._params[0],
            *self._op_arrays,
            *self._brk_arrays,
            self._pw,
            self._k_rows[j],
            self._r_rows[j],
        )

    def _stages(self, t: float, u: np.ndarray, dt: float, order: int, spraying: bool):
        """The stages of one step of size dt from u (rates ``self._k[0]``, tallies
        ``self._r[0]``): (new state, embedded lower-order state, tallies of the step (3,): refused
        solid, merged fragments and merged solid rates; ``self._r[3]``, valid until the next
        step), by the
        compiled stages (``_compiled_steps.ssp_stage``): in one compiled call with a factored kernel,
        else stage by stage with the kernel called between them."""
        n = u.size
        u_new, u_low = np.empty(n), np.empty(n)
        jit, k, r, stage = self._steps, self._k, self._r, self._stage
        params = self._params[1] if spraying else self._params[0]
        if self._factored is not None:
            jit.ssp_step(
                u, k, r, dt, order, self._factored, self._success_code, self._vectors, params, *self._op_arrays,
                *self._brk_arrays, self._pw, u_new, u_low, stage,
            )  # fmt: skip
            return u_new, u_low, r[3]
        for j, at in ((1, t + dt), (2, t + 0.5 * dt), (3, t)):
            if jit.ssp_stage(j, order, dt, u, k, r, stage, u_new, u_low):
                break
            self._rates(at, stage, spraying, j)
        return u_new, u_low, r[3]

    def _set_params(self, threshold: float, width: float) -> None:
        """The compiled rates' parameters, not spraying ([0]) and spraying ([1])."""
        base = [self._flush_n, self._flush_v, float(threshold), float(width), 0.0, self._consolidation_rate]
        self._params[0][:] = base
        self._params[1][:] = base
        self._params[1][4] = self._spray_rate

    def _prepare(self, inp: KernelInput) -> None:
        """Start of a step: the kernel's prepare and factors, the selection (at its update interval)."""
        self.kernel.prepare(inp)
        self._use_factors(inp)
        if self.breakage is not None:
            self.breakage.prepare(inp, self._brk_arrays[0], getattr(self.kernel, "update_interval", 0.0))

    def _use_factors(self, inp: KernelInput) -> None:
        """Ask the kernel for its factors at this step (after ``prepare``): the compiled rates use
        them until the next step; None: :meth:`_rates` calls the kernel."""
        factors = getattr(self.kernel, "factors", None)  # kernels need not derive from Kernel
        f = factors(inp) if factors is not None else None
        if f is None:
            self._factored = self._factors_of = None
            self._success_code = self._jit.ALWAYS  # the kernel's matrix as it is
            self._set_params(0.0, 1.0)
            return
        S, model, threshold, width = f
        key = (model, threshold, width, self._flush_n, self._flush_v)
        if S is self._factors_of and key == self._factors_key:
            return  # the kernel's factors of the last step
        self._check_shape("factors of shape", S)
        self._factors_of, self._factors_key = S, key
        self._factored = np.ascontiguousarray(S, dtype=float)
        self._success_code = self._jit.SUCCESS_CODES[model]
        self._set_params(threshold, width)

    def _check_shape(self, what: str, matrix) -> None:
        """KernelShapeError unless the kernel's ``matrix`` is (M, M) for the M classes of the run."""
        if np.shape(matrix) != (self._M, self._M):
            raise KernelShapeError(
                f"kernel {self.kernel!r} returned {what} {np.shape(matrix)}; expected ({self._M}, {self._M}) "
                f"for the {self._M} classes"
            )

    def _input(self, t: float, nlg: np.ndarray) -> KernelInput:
        """KernelInput of the scaled class state (3, M): surface-liquid fraction from class totals."""
        phi, eps = np.empty(nlg.shape[1]), np.empty(nlg.shape[1])
        self._jit.surface_fraction(nlg, self._xc, phi)  # max(L - G, 0) / (S + max(L, G)), 0 if empty
        self._jit.granule_porosity(nlg, self._xc, eps)  # G / (S + G) in units of x_0, NaN if empty
        return KernelInput(
            t=t,
            volumes=self._vc,
            diameters=self._dc,
            numbers=nlg[0],
            surface_fraction=phi,
            rpm=self.rpm,
            feed_weights=self._feed_number_w,
            porosity=eps,
        )

    # ----------------------------------------------------------------- integration
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

    def _begin(self, t_start: float, t_end: float, state: State) -> State:
        """A copy of the checked start ``state`` at t_start; sets up the run's classes."""
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
        volumes = feed_volumes(self.grid, s)
        check_state(self.grid, s, " (start of run)")
        self._use_classes(volumes)
        self.kernel.reset()
        if self.breakage is not None:
            self.breakage.reset()
        return s

    def _class_state(self, s: State) -> np.ndarray:
        """The scaled class state u = [N, L/x_0, G/x_0] (3M,) of ``s``: with feed classes, the
        aggregates of every bin (bin totals - feed) followed by the feed classes."""
        x0 = float(self.grid.x[0])
        if self._M == self.grid.bins:
            return np.concatenate([s.number, s.liquid / x0, s.gas / x0])
        parts = []
        for total, part, scale, w in (
            (s.number, s.feed.number, 1.0, self._feed_number_w),
            (s.liquid, s.feed.liquid, x0, self._feed_solid_w),
            (s.gas, s.feed.gas, x0, self._feed_solid_w),
        ):
            feed = np.asarray(part, float) / scale
            parts += [np.maximum(total / scale - feed @ w, 0.0), feed]
        return np.concatenate(parts)

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
        s = self._begin(t_start, t_end, state)
        (M, xc), x0, opt, jit = self._run_classes(), float(self.grid.x[0]), self.solver, self._jit
        outs = set()
        if output_times is not None:
            outs = {float(o) for o in np.atleast_1d(output_times) if t_start < float(o) < t_end}
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
        for j, (v, (t_out, refused, merged_n, merged_v, liquid, taken)) in enumerate(fast.records):
            if j < last:  # what _store and rec.add would record, without the state in between
                tot = self._pivot_totals(v)
                rec.append(t_out, tot[0], tot[1] * x0, tot[2] * x0, liquid, refused * x0, base + int(taken),
                           float(merged_n), float(merged_v) * x0)  # fmt: skip
                continue
            s.liquid_added, s.steps = liquid, base + int(taken)
            self._store(s, t_out, v, refused, (merged_n, merged_v))
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

    def _store(self, s: State, t: float, u: np.ndarray, refused: float, merged: tuple) -> None:
        """Write time t, the class state u, the refused solid and the fragments merged into the
        first pivot (number, solid; x_0 units) into ``s``: per-bin totals and the feed classes."""
        x0 = float(self.grid.x[0])
        s.t = t
        tot = self._pivot_totals(u)
        s.number, s.liquid, s.gas = tot[0], tot[1] * x0, tot[2] * x0
        if self._M > self.grid.bins:
            K, M = self.grid.bins, self._M
            v = u.reshape(3, M)[:, K:]
            s.feed = FeedGranules(self._op.extra.copy(), v[0].copy(), v[1] * x0, v[2] * x0)
        s.refused_volume = refused * x0
        s.merged_number, s.merged_volume = float(merged[0]), float(merged[1]) * x0
