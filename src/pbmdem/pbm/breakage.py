"""Breakage of granules: selection rates, the fragment distribution and their cell-average form on
the aggregation grid (docs/pbm.md, "Breakage"). :class:`ConstantSelection` (PBM-constant) and
:class:`PowerLawSelection` (the analytical cases) live here, the selection from the DEM's impacts
in ``pbm.impact_breakage``; the rates are computed by the compiled backend
(``_compiled.breakage_totals``)."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from pbmdem.readers import first_index

from .aggregation import cell_average_factors
from .errors import PBMInputError, positive
from .kernels import KernelInput

#: fragment distributions b(v|u) by config name (``pbm.breakage.fragments``)
FRAGMENTS = ("binary", "uniform")


class SelectionRate(Protocol):
    """What a selection rate provides: ``prepare(inp)`` once per step (it may refresh cached data
    there), ``selection(inp)`` the rate (1/s per granule) of each of the K grid pivots, >= 0."""

    def prepare(self, inp: KernelInput) -> None: ...

    def __call__(self, inp: KernelInput) -> np.ndarray: ...


class ConstantSelection:
    """S = ``rate`` (1/s per granule) for every pivot."""

    def __init__(self, rate: float):
        self.rate = float(rate)

    def __repr__(self) -> str:
        return f"ConstantSelection(rate={self.rate:g})"

    def prepare(self, inp: KernelInput) -> None:
        pass

    def __call__(self, inp: KernelInput) -> np.ndarray:
        return np.full(inp.pivots, self.rate)


class PowerLawSelection:
    """S = ``coefficient`` x v^``exponent`` with v the pivot's solid volume (m3, or the unit of
    the grid): exponent 1 and 2 are the linear and quadratic cases of Ziff & McGrady (1985).
    A negative exponent (the smallest granules breaking fastest) is refused: its solutions lose
    mass to granules of zero size (the shattering transition, McGrady & Ziff 1987), which no grid
    with a smallest class holds."""

    def __init__(self, coefficient: float, exponent: float):
        self.coefficient = positive("breakage selection coefficient", coefficient, allow_zero=True)
        try:
            p = float(exponent)
        except (TypeError, ValueError):
            p = float("nan")
        if not (np.isfinite(p) and p >= 0):
            raise PBMInputError(
                f"breakage selection exponent = {exponent!r}; allowed: a finite number >= 0 (a negative "
                "exponent shatters granules to zero size, which no grid holds)"
            )
        self.exponent = p

    def __repr__(self) -> str:
        return f"PowerLawSelection(coefficient={self.coefficient:g}, exponent={self.exponent:g})"

    def prepare(self, inp: KernelInput) -> None:
        pass

    def __call__(self, inp: KernelInput) -> np.ndarray:
        volumes = np.asarray(inp.volumes[: inp.pivots], float)
        with np.errstate(over="ignore"):
            rates = self.coefficient * volumes**self.exponent
        if (k := first_index(~np.isfinite(rates))) is not None:
            raise PBMInputError(
                f"breakage selection {self!r} at pivot {k} (volume {volumes[k]:g}) = {float(rates[k])!r}; allowed: "
                "finite rates (a smaller coefficient or exponent, or the grid's volumes in another unit)"
            )
        return rates


class Breakage:
    """Breakage with a selection rate (:class:`SelectionRate`) and a fragment distribution
    (``fragments``, one of ``FRAGMENTS``). Only the granules at the grid's pivots break: with
    feed granules kept apart (docs/pbm.md, "Feed granules") those are the aggregates, and a feed
    granule, the unit the aggregates are made of, does not break."""

    def __init__(self, selection: SelectionRate, fragments: str = "binary"):
        self.selection = selection
        self.fragments = fragments
        self._t_eval: float | None = None  # time of the last evaluation of the selection in a run

    def __repr__(self) -> str:
        return f"Breakage({self.selection!r}, fragments={self.fragments!r})"

    def compiled_arrays(self, x: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, ...]:
        """(selection (K,), fragment tables (3, K, K), split factors (4, K), fragments below the
        first pivot (4, K): :meth:`below_floor`, then the first row and one past the last of each
        column of the tables with a nonzero entry): the arguments of the compiled rates
        (``_compiled.breakage_totals``) on the grid of pivots ``x`` and cell ``edges``;
        :meth:`prepare` refreshes the selection array in place."""
        x = np.asarray(x, float)
        key = (self.fragments, x.tobytes(), np.asarray(edges, float).tobytes())
        tables = _TABLES.get(key)
        if tables is None:  # the same for every model of this grid (a process builds many: design space)
            tab = np.ascontiguousarray(self.fragment_tables(x, edges))
            factors = np.ascontiguousarray(cell_average_factors(x / x[0]))
            nonzero = (tab != 0.0).any(axis=0)  # (K rows, K columns)
            rows = np.zeros((2, x.size))
            for k in range(x.size):
                at = np.flatnonzero(nonzero[:, k])
                if at.size:
                    rows[:, k] = at[0], at[-1] + 1
            tables = tab, factors, np.ascontiguousarray(np.vstack([self.below_floor(x), rows]))
            if len(_TABLES) >= 8:
                _TABLES.clear()
            _TABLES[key] = tables
        return np.zeros(x.size), *tables

    def reset(self) -> None:
        """Start of a run: the next :meth:`prepare` evaluates the selection."""
        self._t_eval = None

    def prepare(self, inp: KernelInput, out: np.ndarray, interval: float = 0.0) -> None:
        """Once per step: the selection's own ``prepare``, and its rates evaluated again into
        ``out`` (the selection array of :meth:`compiled_arrays`) at the first step of a run and
        then once ``interval`` seconds have passed (the aggregation kernel's update interval)."""
        self.selection.prepare(inp)
        if self._t_eval is None or inp.t >= self._t_eval + interval:
            out[:] = self.rates(inp)
            self._t_eval = inp.t

    def rates(self, inp: KernelInput) -> np.ndarray:
        """The selection rate (1/s) of each of the K pivots at ``inp``, checked: shape (K,),
        finite and >= 0 (PBMInputError naming the selection and the pivot)."""
        K = inp.pivots
        S = np.asarray(self.selection(inp), dtype=float)
        if S.shape != (K,):
            raise PBMInputError(
                f"breakage selection {self.selection!r} returned shape {S.shape}; expected ({K},), one "
                "rate per grid pivot"
            )
        if np.isfinite(S).all() and (S >= 0).all():
            return S
        if (k := first_index(~np.isfinite(S) | (S < 0))) is not None:
            raise PBMInputError(
                f"breakage selection {self.selection!r} gave {float(S[k])!r} 1/s for the pivot of diameter "
                f"{float(inp.diameters[k]):.4g} m at t = {inp.t:.6g} s; allowed: finite rates >= 0"
            )
        return S

    def fragment_tables(self, x: np.ndarray, edges: np.ndarray) -> np.ndarray:
        """(3, K, K) per breakage of one granule of pivot k (column k): the fragments born in
        cell i (row i) as [number, first moment sum (v/x_i - 1), share of the parent's solid],
        for pivots ``x`` (K,) and cell ``edges`` (K + 1,) in any unit of volume. Fragments below
        the first pivot count as granules of x_0 carrying their solid volume."""
        x = np.asarray(x, float)
        K = x.size
        xr = x / x[0]
        e = np.asarray(edges, float)[1:-1] / x[0]  # inner cell bounds, x_0 units
        tab = np.zeros((3, K, K))
        for k in range(K):
            number, solid, _ = _fragments_of(self.fragments, xr[k], xr, e)
            tab[0, :, k] = number
            tab[1, :, k] = solid / xr - number
            tab[2, :, k] = solid / xr[k]
        return tab

    def below_floor(self, x: np.ndarray) -> np.ndarray:
        """(2, K) per breakage of one granule of pivot k (column k): the number of its fragments
        smaller than the first pivot x_0 and their solid volume in units of x_0. The fragment
        tables merge them into x_0 (number = solid / x_0, solid exact), so a breakage of pivot k
        loses ``below[0, k] - below[1, k]`` granules; the run tallies both
        (``State.merged_number``, ``State.merged_volume``). Column 0 is zero: a granule of the
        first pivot gives back one granule of the first pivot, no change (it does not break), so
        that a fragment merged into x_0 is counted once, not again at every breakage it is denied."""
        x = np.asarray(x, float)
        xr = x / x[0]
        out = np.zeros((2, x.size))
        for k in range(1, x.size):
            out[:, k] = _fragments_of(self.fragments, xr[k], xr, xr[1:])[2]
        return out


#: the fragment tables, split factors and fragment rows of each grid (:meth:`Breakage.compiled_arrays`;
#: shared by the models of the grid: not to be modified)
_TABLES: dict = {}


def breakage_arrays(breakage: Breakage | None, x: np.ndarray, edges: np.ndarray) -> tuple:
    """The breakage's arguments of the compiled rates on the grid of pivots ``x`` and cell
    ``edges`` (:meth:`Breakage.compiled_arrays`); None: an empty selection, no breakage."""
    if breakage is None:
        return np.zeros(0), np.zeros((3, 0, 0)), np.zeros((4, 0)), np.zeros((2, 0))
    return breakage.compiled_arrays(x, edges)


def _fragments_of(fragments: str, u: float, xr: np.ndarray, inner: np.ndarray) -> tuple:
    """(number (K,), solid volume (K,), (number, solid) below x_0) of the fragments of one granule
    of volume ``u`` (units of x_0) in each cell of pivots ``xr`` with inner bounds ``inner`` (K -
    1,), cell i spanning [inner[i-1], inner[i]) and the fragments of cell k (u's own cell) reaching
    up to u. Fragments below x_0 = 1 are put in cell 0 as number = solid volume / x_0; the last
    item gives how many they were and their solid."""
    K = xr.size
    number, solid = np.zeros(K), np.zeros(K)
    if fragments == "binary":
        h = 0.5 * u
        if h < 1.0:
            number[0], solid[0] = u, u  # two fragments below x_0: u / x_0 granules of x_0
            return number, solid, (2.0, u)
        i = int(np.searchsorted(inner, h, side="right"))
        number[i], solid[i] = 2.0, u
        return number, solid, (0.0, 0.0)
    # uniform daughters b(v|u) = 2/u on (0, u): number 2 (b - a)/u, solid (b^2 - a^2)/u in [a, b]
    low = min(1.0, u)
    solid[0] = number[0] = low * low / u  # the fragments below x_0, as granules of x_0
    lower = np.concatenate([[1.0], inner])
    upper = np.minimum(np.append(inner, np.inf), u)
    a, b = lower, np.maximum(upper, lower)
    number += 2.0 * (b - a) / u
    solid += (b - a) * (b + a) / u
    return number, solid, (2.0 * low / u, low * low / u)
