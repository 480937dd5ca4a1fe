"""The batch granulator population balance and its adaptive explicit time integration.

State: numbers N_k, liquid L_k and gas (pore) G_k volume totals per bin of a :class:`Grid`
(solid S_k = N_k x_k). Balances (aggregation A: a scheme of ``aggregation.SCHEMES``, by default
the cell-average technique):

    dN_k/dt = A_N,k
    dL_k/dt = A_L,k + Q w_k [t_start <= t < t_end]
    dG_k/dt = A_G,k - c (G_k - eps_min / (1 - eps_min) S_k)

Time integration: strong-stability-preserving explicit Runge-Kutta, ``"heun"`` (SSP-RK2, default)
or ``"euler"``, with dt = safety x min over depleting entries (rate < 0) of value / |rate|,
capped by ``max_step``, output times and the spray window edges (so every step sees a constant
spray rate). A step that would leave a negative entry is repeated with half the step; after
``max_halvings`` the run stops with NegativePopulationError naming the time and bin. A NaN stops
the run at once. ``run(t_start, t_end, state)`` resumes from any :class:`State`, so a coupled
loop can swap the collision-frequency source between intervals.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from .aggregation import SCHEMES
from .errors import GridOverflowError, NegativePopulationError, PBMInputError, positive
from .grid import Grid
from .kernels import Kernel, KernelInput
from .processes import Consolidation, LiquidAddition

TIME_EPS = 1e-12


@dataclass
class State:
    """Resumable PBM state at time ``t``: per-bin number, liquid and gas (pore) volume (m3).

    ``refused_volume``: solid volume of aggregates refused beyond the last bin so far (m3);
    ``liquid_added``: binder sprayed so far (m3); ``steps``: time steps taken so far.
    """

    t: float
    number: np.ndarray
    liquid: np.ndarray
    gas: np.ndarray
    refused_volume: float = 0.0
    liquid_added: float = 0.0
    steps: int = 0

    def copy(self) -> "State":
        return State(self.t, self.number.copy(), self.liquid.copy(), self.gas.copy(),
                     self.refused_volume, self.liquid_added, self.steps)


@dataclass
class SolverSettings:
    method: str = "heun"
    safety: float = 0.25
    max_step: float = np.inf
    max_overflow_fraction: float = 1e-6
    max_halvings: int = 60
    rtol: float = 1e-3
    atol: float = 1e-9

    def __post_init__(self):
        if self.method not in ("heun", "euler"):
            raise PBMInputError(f"solver method = {self.method!r}; allowed: 'heun', 'euler'")
        self.safety = positive("solver safety", self.safety)
        if self.safety > 1:
            raise PBMInputError(f"solver safety = {self.safety!r}; allowed: 0 < safety <= 1 (fraction of the "
                                "fastest depletion time)")
        if self.max_step != np.inf:
            self.max_step = positive("solver max_step (s)", self.max_step)
        self.rtol = positive("solver rtol", self.rtol)
        self.atol = positive("solver atol", self.atol)
        self.max_overflow_fraction = positive("solver max_overflow_fraction", self.max_overflow_fraction,
                                              allow_zero=True)


def surface_fraction(S: np.ndarray, L: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Surface-liquid volume fraction of the granules of each bin.

    Liquid fills the pores first; the excess is surface liquid: l_surf = max(l - g, 0). The granule
    volume is s + max(l, g) (pores, wet or dry, plus the surface layer). Ratios of bin totals
    equal ratios of per-particle values, so no division by N is needed.
    """
    S, L, G = np.broadcast_arrays(*(np.asarray(a, float) for a in (S, L, G)))
    V = S + np.maximum(L, G)
    return np.divide(np.maximum(L - G, 0.0), V, out=np.zeros(V.shape), where=V > 0)


def _per_particle(total: np.ndarray, N: np.ndarray) -> np.ndarray:
    return np.divide(total, N, out=np.zeros_like(total), where=N > 0)


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
    aggregation discretisation, ``"cell_average"`` (default) or ``"fixed_pivot"``.
    """

    def __init__(self, grid: Grid, kernel: Kernel, liquid: LiquidAddition | None = None,
                 consolidation: Consolidation | None = None, solver: SolverSettings | None = None,
                 rpm: float = 0.0, scheme: str = "cell_average"):
        self.grid = grid
        self.kernel = kernel
        self.liquid = liquid
        self.consolidation = consolidation
        self.solver = solver or SolverSettings()
        self.rpm = positive("impeller speed (rpm)", rpm, allow_zero=True)
        if scheme not in SCHEMES:
            raise PBMInputError(f"aggregation scheme = {scheme!r}; allowed: {sorted(SCHEMES)}")
        self.aggregation = SCHEMES[scheme](grid.x, grid.edges[1:-1])

    def __repr__(self) -> str:
        return (f"GranulationPBM({self.grid!r}, {self.kernel!r}, liquid={self.liquid!r}, "
                f"consolidation={self.consolidation!r}, rpm={self.rpm:g}, scheme={self.aggregation.name!r})")

    # ----------------------------------------------------------------- state helpers
    def initial_state(self, volumes, numbers, liquid_content: float = 0.0, porosity: float = 0.0,
                      t: float = 0.0, what: str = "initial distribution") -> State:
        """State from particle classes of solid ``volumes`` (m3) and ``numbers``, each with liquid
        ``liquid_content`` x solid volume and pore volume such that G / (S + G) = ``porosity``."""
        lc = positive("initial liquid_content", liquid_content, allow_zero=True)
        eps = positive("initial porosity", porosity, allow_zero=True)
        if eps >= 1:
            raise PBMInputError(f"initial porosity = {porosity!r}; allowed: 0 <= porosity < 1")
        if self.consolidation is not None and eps < self.consolidation.min_porosity:
            raise PBMInputError(f"initial porosity = {eps:g} is below the minimum porosity "
                                f"{self.consolidation.min_porosity:g}; allowed: porosity >= min_porosity")
        N, frac = self.grid.map_particles(volumes, numbers, what=what)
        solid = np.asarray(volumes, float) * np.asarray(numbers, float)
        S_bins = solid @ frac
        return State(float(t), N, lc * S_bins, eps / (1.0 - eps) * S_bins)

    def kernel_input(self, t: float, N, L, G) -> KernelInput:
        S = N * self.grid.x
        return KernelInput(t=t, volumes=self.grid.x, diameters=self.grid.d, numbers=N,
                           surface_fraction=surface_fraction(S, L, G), rpm=self.rpm)

    def rates(self, t: float, N, L, G, spraying: bool):
        """Rates (dN, dL, dG) and the refused solid-volume rate at (t, N, L, G)."""
        inp = self.kernel_input(t, N, L, G)
        beta = self.kernel(inp)
        dN, dL, dG, refused = self.aggregation.rates(beta, N, _per_particle(L, N), _per_particle(G, N))
        if spraying:
            dL = dL + self.liquid.rates(N, self.grid.x, self.grid.d)
        if self.consolidation is not None:
            dG = dG + self.consolidation.rates(N * self.grid.x, G)
        return dN, dL, dG, refused

    def check_state(self, s: State, where: str = "") -> None:
        for name, arr in (("number", s.number), ("liquid", s.liquid), ("gas", s.gas)):
            bad = ~np.isfinite(arr) | (arr < 0)
            if bad.any():
                k = int(np.argmax(bad))
                raise NegativePopulationError(
                    f"{name} of bin {k} (diameter {self.grid.d[k]:.4g} m) is {float(arr[k])!r} at t = {s.t:.6g} s"
                    f"{where}; allowed: finite values >= 0")

    # ----------------------------------------------------------------- integration
    def _depletion_step(self, u: np.ndarray, du: np.ndarray) -> float:
        mask = (du < 0) & (u > 0)
        if not mask.any():
            return np.inf
        return self.solver.safety * float(np.min(u[mask] / -du[mask]))

    def _raise_bad(self, t: float, arr: np.ndarray, why: str):
        K = self.grid.bins
        bad = ~np.isfinite(arr) | (arr < 0)
        idx = int(np.argmax(bad))
        name = ("number", "liquid", "gas")[idx // K]
        k = idx % K
        raise NegativePopulationError(
            f"{name} of bin {k} (diameter {self.grid.d[k]:.4g} m) became {float(arr[idx])!r} at t = {t:.6g} s "
            f"({why}); populations must stay finite and >= 0")

    def run(self, t_start: float, t_end: float, state: State, output_times=None):
        """Integrate from ``t_start`` (= ``state.t``) to ``t_end``; returns a :class:`Result`.

        ``output_times``: times in [t_start, t_end] to record (t_start and t_end always are).
        The input state is not modified; ``result.state`` is the state at ``t_end``.
        """
        from .results import Result

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
        self.check_state(s, " (start of run)")
        self.kernel.reset()
        wall0 = _time.perf_counter()

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

        x = self.grid.x
        total_solid = float(np.sum(s.number * x))
        allowed_refused = self.solver.max_overflow_fraction * total_solid
        u = np.concatenate([s.number, s.liquid, s.gas])
        # error weights: number entries count by their solid volume, liquid and gas as volumes
        w = np.concatenate([x, np.ones(K), np.ones(K)])
        err_floor = self.solver.atol * max(total_solid, 1e-300)
        rtol = self.solver.rtol
        t = t_start
        steps = s.steps
        ev = 0
        heun = self.solver.method == "heun"
        dt_prop = self.solver.max_step
        while t < t_end:
            while events[ev] <= t:
                ev += 1
            t_next = events[ev]
            N, L, G = u[:K], u[K:2 * K], u[2 * K:]
            spraying = self.liquid is not None and self.liquid.active(t)
            self.kernel.prepare(self.kernel_input(t, N, L, G))
            dN, dL, dG, r1 = self.rates(t, N, L, G, spraying)
            k1 = np.concatenate([dN, dL, dG])
            if not np.all(np.isfinite(k1)):
                self._raise_bad(t, np.where(np.isfinite(k1), u, np.nan), "non-finite rate")
            dt = min(self._depletion_step(u, k1), dt_prop, self.solver.max_step, t_next - t)
            for _ in range(self.solver.max_halvings + 1):
                u1 = u + dt * k1
                refused_rate = r1
                err = 0.0
                if heun and np.all(u1 >= 0):
                    dN2, dL2, dG2, r2 = self.rates(t + dt, u1[:K], u1[K:2 * K], u1[2 * K:], spraying)
                    u_new = 0.5 * (u + u1 + dt * np.concatenate([dN2, dL2, dG2]))
                    refused_rate = 0.5 * (r1 + r2)
                    # embedded Euler-Heun error estimate, relative to each entry (floor: atol x solid)
                    err = float(np.max(np.abs(u_new - u1) * w / (np.abs(u_new) * w + err_floor)))
                else:
                    u_new = u1
                if np.isnan(u_new).any():
                    self._raise_bad(t, u_new, "NaN after a step")
                if not np.all(u_new >= 0):
                    dt *= 0.5
                    continue
                if err > rtol:
                    dt *= max(0.2, 0.9 * np.sqrt(rtol / err))
                    continue
                break
            else:
                self._raise_bad(t, u_new, f"negative even after {self.solver.max_halvings} step reductions")
            if heun:
                dt_prop = dt * min(5.0, 0.9 * np.sqrt(rtol / max(err, 1e-300)))
            capped = dt == t_next - t
            t = t_next if capped else t + dt
            u = u_new
            steps += 1
            s.refused_volume += refused_rate * dt
            if spraying:
                s.liquid_added += self.liquid.rate * dt
            if s.refused_volume > allowed_refused:
                raise GridOverflowError(
                    f"aggregation beyond the last bin (pivot {x[-1]:.4g} m3, diameter {self.grid.d[-1]:.4g} m): "
                    f"by t = {t:.6g} s aggregates carrying {s.refused_volume:.4g} m3 of solid were refused, "
                    f"{s.refused_volume / total_solid:.3g} of the total solid volume {total_solid:.4g} m3; "
                    f"allowed: at most max_overflow_fraction = {self.solver.max_overflow_fraction:g}. "
                    "Use more bins or a larger grid ratio (pbm.grid.bins / pbm.grid.ratio)")
            if capped and t in record_at:
                s.t, s.number, s.liquid, s.gas, s.steps = t, u[:K].copy(), u[K:2 * K].copy(), u[2 * K:].copy(), steps
                rec.add(s)
        s.t, s.number, s.liquid, s.gas, s.steps = t_end, u[:K].copy(), u[K:2 * K].copy(), u[2 * K:].copy(), steps
        info = {"kernel": repr(self.kernel), "liquid_addition": repr(self.liquid),
                "consolidation": repr(self.consolidation), "rpm": self.rpm, "steps": steps - state.steps,
                "wall_time_s": _time.perf_counter() - wall0, "method": self.solver.method,
                "aggregation_scheme": self.aggregation.name,
                "safety": self.solver.safety}
        return Result(self.grid, rec, s, info)
