"""The batch granulator population balance: numbers N_k, liquid L_k and gas G_k totals per bin of
a :class:`Grid` (the feed granules as classes of their own, :class:`FeedGranules`), aggregation,
breakage, spraying and consolidation (docs/pbm.md, "Rate processes").

Its time integration is ``stepping``'s; every rate and stage is computed by the compiled backend
(``_compiled``, ``_compiled_steps``). ``run(t_start, t_end, state)`` resumes from any
:class:`State`, so a coupled loop can swap the collision-frequency source between intervals."""

from __future__ import annotations

import numpy as np

from pbmdem.config import Solver

from .aggregation import SCHEMES, operator
from .breakage import Breakage, breakage_arrays
from .errors import KernelShapeError, PBMInputError
from .grid import Grid, diameter_of
from .kernels import Kernel, KernelInput
from .processes import Consolidation, LiquidAddition
from .state import FeedGranules, State
from .stepping import TimeIntegration

__all__ = ["GranulationPBM"]


class GranulationPBM(TimeIntegration):
    """Batch granulator PBM: aggregation (+ optional liquid addition, consolidation, breakage).

    ``kernel``: any :class:`Kernel`; ``liquid``/``consolidation``: the processes or None (off);
    ``rpm``: impeller speed handed to the kernel's collision-frequency source; ``scheme``: the
    aggregation discretisation, ``"cell_average"`` (default) or ``"fixed_pivot"``;
    ``separate_feed``: :meth:`initial_state` keeps the feed granules apart from the aggregates
    of their bins (:class:`FeedGranules`; default True), False: they share the bin's liquid and gas;
    ``breakage``: a :class:`Breakage` or None (aggregation only).
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
        breakage: Breakage | None = None,
    ):
        self.grid = grid
        self.kernel = kernel
        self.liquid = liquid
        self.consolidation = consolidation
        self.solver = solver if solver is not None else Solver()
        self.set_rpm(rpm)
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
        self.rpm = float(rpm)

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

    def _pivot_totals_of(self, states: np.ndarray) -> np.ndarray:
        """(T, 3, K) per-bin totals of T class states (T, 3M): :meth:`_pivot_totals` of each,
        the same products of each (numpy's matmul makes the same call for every matrix of a
        stack) in one call."""
        K, M = self.grid.bins, self._M
        v = states.reshape(-1, 3, M)
        tot = v[:, :, :K].copy()
        if M > K:
            tot[:, :1] += v[:, :1, K:] @ self._feed_number_w
            tot[:, 1:] += v[:, 1:, K:] @ self._feed_solid_w
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
        lc, eps = float(liquid_content), float(porosity)
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
