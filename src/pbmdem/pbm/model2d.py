"""The two-dimensional PBM: granules classed by solid volume and by liquid-to-solid volume ratio
(docs/pbm.md, "Two-dimensional PBM").

A :class:`GranulationPBM` with another class state: its rates and stages are ``_compiled2d``'s;
runs start from a :class:`State2D`; ``result.classes`` holds the (T, 3, Mx, J) class totals
(number, liquid m3, gas m3) at the recorded times beside the size marginal."""

from __future__ import annotations

import numpy as np

from .errors import NegativePopulationError, PBMInputError
from .grid import Grid, diameter_of
from .liquid_grid import LiquidGrid
from .model import GranulationPBM
from .results import Result
from .state import FeedGranules, State2D
from .stepping import Records, StepControl

__all__ = ["GranulationPBM2D"]


class GranulationPBM2D(GranulationPBM):
    """Batch granulator PBM on (solid volume) x (liquid-to-solid ratio): the arguments of
    :class:`GranulationPBM`, and ``liquid_grid`` the liquid classes (default: steps of 0.02 up to 1,
    the schema's ``pbm.grid.liquid_step`` / ``liquid_max``). The kernel must offer
    ``factors`` (every kernel of the library except the Stokes criterion's)."""

    def __init__(self, grid: Grid, kernel, *args, liquid_grid: LiquidGrid | None = None, **kwargs):
        self.liquid_grid = LiquidGrid.uniform(0.02, 1.0) if liquid_grid is None else liquid_grid
        from . import _compiled2d  # lazy: numba + compiled cache ~2.6 s (measured)

        self._jit2 = _compiled2d
        super().__init__(grid, kernel, *args, **kwargs)

    def __repr__(self) -> str:
        return "GranulationPBM2D" + super().__repr__()[len("GranulationPBM") : -1] + f", {self.liquid_grid!r})"

    def _use_classes(self, feed_volumes: np.ndarray) -> None:
        """The 1-D model's size classes, and the (size x liquid) classes of a run."""
        same = tuple(float(v) for v in feed_volumes) == getattr(self, "_classes_key", None)
        super()._use_classes(feed_volumes)
        if same and hasattr(self, "_M2"):
            return
        Mx, J = self._M, self.liquid_grid.classes
        M2 = self._M2 = Mx * J
        self._J = J

        def rep(v):
            return np.repeat(np.asarray(v, float), J)

        self._vectors2 = np.ascontiguousarray(np.stack([rep(self._xc), rep(self._spray_weight), rep(self._gas_min)]))
        self._xcc = np.ascontiguousarray(self._xc, dtype=float)
        K, cell_average, target, weight, factors, _ = self._op_arrays
        self._dims = np.array([K, Mx, J, int(cell_average)], dtype=np.int64)
        self._pair = (target, weight, factors)
        # the work of the stages on these classes, in place of the 1-D model's
        self._k, self._r, self._stage = np.empty((3, 3 * M2)), np.zeros((4, 3)), np.empty(3 * M2)
        self._k_rows = [k.reshape(3, M2) for k in self._k]
        self._work2 = (
            np.empty((Mx, J + 1), dtype=np.int64),
            np.empty((4, Mx, J)),
            np.empty((4, max(K, Mx))),
            np.empty((9, K, J)),
            np.zeros((2, M2)),
        )
        self._rebin_work = np.empty(3 * M2)

    def _use_factors(self, inp) -> None:
        super()._use_factors(inp)
        if self._factored is None:
            raise PBMInputError(
                f"the two-dimensional PBM (pbm.dimensions: 2) evaluates the kernel per (size, liquid) class "
                f"inside its compiled rates and needs a kernel with factors; {self.kernel!r} has none "
                "(the Stokes criterion: pbm.aggregation.success.velocity_model = stokes); allowed: "
                "velocity_model none, or pbm.dimensions: 1"
            )

    def _marginal(self, u: np.ndarray) -> np.ndarray:
        """(3, Mx) size-class totals of the scaled class state u (3 M2,)."""
        return np.ascontiguousarray(u.reshape(3, self._M, self._J).sum(axis=2))

    def _rates(self, t: float, u: np.ndarray, spraying: bool, j: int) -> None:
        """Rates of the class state u into ``self._k[j]``, its tallies (refused solid, merged
        fragments and their solid, x_0 units) into ``self._r[j]``."""
        lg = self.liquid_grid
        self._jit2.class_rates2d(
            u, self._factored, self._success_code, self._vectors2, self._xcc,
            self._params[1] if spraying else self._params[0], self._dims, lg.step, lg.centres, *self._pair,
            *self._brk_arrays, *self._work2, self._k_rows[j], self._r[j],
        )  # fmt: skip

    def _stages(self, t: float, u: np.ndarray, dt: float, order: int, spraying: bool):
        """(new state, embedded lower-order state, tallies (3,) of the step) of one step: one compiled call."""
        n = u.size
        u_new, u_low = np.empty(n), np.empty(n)
        lg = self.liquid_grid
        self._jit2.ssp_step2d(
            u, self._k, self._r, dt, order, u_new, u_low, self._stage, self._factored, self._success_code,
            self._vectors2, self._xcc, self._params[1] if spraying else self._params[0], self._dims, lg.step,
            lg.centres, *self._pair, *self._brk_arrays, *self._work2,
        )  # fmt: skip
        return u_new, u_low, self._r[3]

    # ----------------------------------------------------------------- states
    def initial_state(self, volumes, numbers, liquid_content=0.0, porosity=0.0, t=0.0, what="initial distribution"):
        """The one-dimensional model's initial state (:meth:`GranulationPBM.initial_state`), every
        granule in the liquid class of ``liquid_content``."""
        base = super().initial_state(volumes, numbers, liquid_content, porosity, t, what)
        K, J = self.grid.bins, self.liquid_grid.classes
        e0 = int(self.liquid_grid.classify([liquid_content])[0])
        if base.feed is not None:
            f = base.feed
            vols = np.concatenate([self.grid.x, f.volumes])
            parts = (f.number, f.liquid, f.gas)
        else:
            vols = self.grid.x.copy()
            parts = (base.number, base.liquid, base.gas)
        classes = np.zeros((3, vols.size, J))
        for q, part in enumerate(parts):
            classes[q, vols.size - part.size :, e0] = part
        return self.make_state(t, classes, vols[K:])

    def make_state(self, t: float, classes, feed_volumes=()) -> State2D:
        """A :class:`State2D` at ``t`` from the class totals ``classes`` (3, K + P, J): number,
        liquid (m3), gas (m3) of the K pivots and the P feed classes of solid volumes
        ``feed_volumes`` (m3) in every liquid class; the per-bin totals by the lever rule."""
        feed = np.asarray(feed_volumes, float).reshape(-1)
        vols = np.concatenate([self.grid.x, feed])
        c = np.asarray(classes, float)
        if c.shape != (3, vols.size, self.liquid_grid.classes):
            raise PBMInputError(
                f"state classes of shape {c.shape}; expected (3, {vols.size}, {self.liquid_grid.classes}) "
                "(number, liquid, gas x size classes x liquid classes)"
            )
        self._use_classes(feed)
        x0 = float(self.grid.x[0])
        u = np.concatenate([c[0].ravel(), c[1].ravel() / x0, c[2].ravel() / x0])
        s = State2D(float(t), np.zeros(self.grid.bins), np.zeros(self.grid.bins), np.zeros(self.grid.bins))
        self._store(s, float(t), u, 0.0, (0.0, 0.0))
        return s

    def _check_start(self, state) -> None:
        if not isinstance(state, State2D) or state.classes is None or state.class_volumes is None:
            raise PBMInputError(
                f"run: the two-dimensional PBM starts from a State2D (GranulationPBM2D.initial_state or "
                f"make_state), not {type(state).__name__}"
            )

    def _known_classes(self, state: State2D) -> np.ndarray:
        return self._start_classes(state)  # the size classes of the state: read (and checked) as they enter

    def _start_classes(self, state: State2D) -> np.ndarray:
        K, J = self.grid.bins, self.liquid_grid.classes
        vols = np.asarray(state.class_volumes, float)
        if vols.size < K or not np.allclose(vols[:K], self.grid.x, rtol=1e-12, atol=0):
            raise PBMInputError("run: the state's size classes do not start with this grid's pivots")
        if np.shape(state.classes) != (3, vols.size, J):
            raise PBMInputError(f"state.classes has shape {np.shape(state.classes)}; expected (3, {vols.size}, {J})")
        if not np.all(np.isfinite(state.classes)) or np.any(state.classes < 0):
            q, i, e = np.argwhere(~(np.isfinite(state.classes) & (state.classes >= 0)))[0]
            raise NegativePopulationError(
                f"{('number', 'liquid', 'gas')[q]} of size class {i} (diameter {float(diameter_of(vols[i])):.4g} m), "
                f"liquid class {e} is {state.classes[q, i, e]!r} at t = {state.t:.6g} s (start of run); "
                "allowed: finite values >= 0"
            )
        return vols[K:]

    def _class_state(self, s: State2D) -> np.ndarray:
        x0 = float(self.grid.x[0])
        c = s.classes
        return np.concatenate([c[0].ravel(), c[1].ravel() / x0, c[2].ravel() / x0])

    def _store(self, s: State2D, t: float, u: np.ndarray, refused: float, merged: tuple) -> None:
        """Write time t, the class state u, the refused solid and the fragments merged into the
        first pivot (number, solid; x_0 units) into ``s``."""
        x0 = float(self.grid.x[0])
        K, Mx, J = self.grid.bins, self._M, self._J
        s.t = t
        v = u.reshape(3, Mx, J)
        s.classes = np.stack([v[0], v[1] * x0, v[2] * x0])
        s.class_volumes = self._vc.copy()
        m = self._marginal(u)
        tot = self._pivot_totals(m.ravel())
        s.number, s.liquid, s.gas = tot[0], tot[1] * x0, tot[2] * x0
        s.feed = FeedGranules(self._op.extra.copy(), m[0, K:], m[1, K:] * x0, m[2, K:] * x0) if Mx > K else None
        s.refused_volume = refused * x0
        s.merged_number, s.merged_volume = float(merged[0]), float(merged[1]) * x0

    def _raise_bad(self, t: float, arr: np.ndarray, why: str):
        M2, J = self._M2, self._J
        bad = ~np.isfinite(arr) | (arr < 0)
        idx = int(np.argmax(bad))
        q, a = divmod(idx, M2)
        i, e = divmod(a, J)
        value = float(arr[idx]) * (self.grid.x[0] if q else 1.0)
        raise NegativePopulationError(
            f"{('number', 'liquid', 'gas')[q]} of size class {i} (diameter {self._dc[i]:.4g} m), liquid class {e} "
            f"became {value!r} at t = {t:.6g} s ({why}); populations must stay finite and >= 0"
        )

    # ----------------------------------------------------------------- integration
    fast_steps = False  # the compiled step loop is the 1-D model's

    def _run_classes(self) -> tuple[int, np.ndarray]:
        return self._M2, self._vectors2[0]

    def _number_total(self, s: State2D, u: np.ndarray) -> float:
        return float(np.sum(u[: self._M2]))

    def _after_step(self, u: np.ndarray) -> None:
        lg = self.liquid_grid
        self._moved += self._jit2.rebin(
            u, self._M, self._J, self._xcc, lg.step, lg.bounds, lg.centres, self._rebin_work
        )

    def _record(self, rec: Records, s: State2D) -> None:
        rec.add(s)
        self._classes_of_run.append(s.classes.copy())

    def _info(self, ctl: StepControl) -> dict:
        info = super()._info(ctl)
        info.update({"dimensions": 2, "liquid_grid": repr(self.liquid_grid), "classes_moved": int(self._moved)})
        return info

    def run(self, t_start: float, t_end: float, state, output_times=None, *, checked: bool = False) -> Result:
        """Integrate as :meth:`GranulationPBM.run` does (the same step control, flush and records),
        the classes rebinned after every step; ``result.classes`` (T, 3, Mx, J) at the recorded times."""
        self._classes_of_run, self._moved = [], 0
        res = super().run(t_start, t_end, state, output_times, checked=checked)
        res.classes = np.stack(self._classes_of_run)
        res.class_volumes = self._vc.copy()
        return res
