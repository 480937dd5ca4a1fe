"""Aggregation on a pivot grid: the cell-average technique (default) and the fixed pivot technique
(``pbm.aggregation.scheme``); docs/pbm.md ("Rate processes", "Time integration") gives the schemes,
the refused aggregates, the feed classes and why no mean volume is ever formed.

The scheme classes precompute the target cell and weights of every ordered pair of classes
(:meth:`PivotAggregation._pair_weights`) for the compiled rates (``_compiled.aggregation_totals``);
the feed classes (``extra``) follow the K pivots in ``beta`` and the (3, K+P) totals."""

from __future__ import annotations

import numpy as np


class PivotAggregation:
    """Shared pair bookkeeping of the pivot schemes: grid ``x`` (ascending, (K,)), the K-1 inner
    cell ``bounds`` (default: x_k 2r/(1+r), pivots at the centres of geometric cells) and the
    volumes ``extra`` (P,) of further classes that receive no births (feed granules, in the unit
    of ``x``; default none). ``M`` = K + P classes."""

    #: name used in the config (``pbm.aggregation.scheme``)
    name = ""
    #: births by the cell-average split (else the map's first K rows are the births)
    _cell_average = False

    def __init__(self, x: np.ndarray, bounds: np.ndarray | None = None, extra=None):
        x = np.asarray(x, float)
        self.x = x
        K = self.K = x.size
        extra = np.asarray([] if extra is None else extra, dtype=float).reshape(-1)
        if extra.size and not (np.all(extra >= x[0] * (1 - 1e-12)) and np.all(extra <= x[-1] * (1 + 1e-12))):
            raise ValueError(f"extra class volumes must lie in [x_0, x_(K-1)], got {extra.tolist()}")
        self.extra = extra
        M = self.M = K + extra.size
        iu, ju = np.triu_indices(M)
        # work in units of the first pivot: every volume of the maps is O(1) .. O(r^K)
        xr = x / x[0]
        #: class volumes in units of x_0: [pivots, extra]
        vc = self.class_volumes = np.concatenate([xr, extra / x[0]])
        s = vc[iu] + vc[ju]
        if bounds is None:
            r = x[1] / x[0]
            bounds = x[:-1] * 2.0 * r / (1.0 + r)
        bounds = np.asarray(bounds, float)
        if bounds.shape != (K - 1,) or np.any(bounds <= x[:-1]) or np.any(bounds >= x[1:]):
            raise ValueError("cell bounds must be K-1 values strictly between neighbouring pivots")
        valid = s <= xr[-1] * (1.0 + 1e-12)
        self.xr = xr
        target = np.searchsorted(bounds / x[0], s, side="right")
        #: (M, M) target cell of each pair's aggregate (-1 = beyond the grid), for inspection
        tm = np.full((M, M), -1, dtype=int)
        tm[iu[valid], ju[valid]] = target[valid]
        tm[ju[valid], iu[valid]] = target[valid]
        self.target_matrix = tm
        # ordered pairs (i, j), flattened row-major (index i M + j): aggregate volume and target
        I, J = np.divmod(np.arange(M * M), M)
        self._S = vc[I] + vc[J]
        self._T = tm.ravel()
        self._ok = self._T >= 0
        self._build()

    def __repr__(self) -> str:
        extra = f", extra={np.round(self.extra / self.x[0], 6).tolist()} x_0" if self.extra.size else ""
        return f"{type(self).__name__}(K={self.K}{extra})"

    def _build(self):
        """The arrays of the compiled evaluation (numba, imported here: building an operator loads
        or compiles it, :mod:`._compiled`): the target cell or lower pivot of every ordered pair
        (-1 beyond the grid), its weights, and the scheme's split factors."""
        from . import _compiled  # noqa: F401  lazy: numba + compiled cache ~3 s (measured), loaded with a model

        target, weight = self._pair_weights()
        self._target = np.ascontiguousarray(target, dtype=np.int64)
        self._weight = np.ascontiguousarray(weight, dtype=float)
        self._factors = np.ascontiguousarray(self._split_factors(), dtype=float)
        self._work = np.empty((10, self.K))

    def _pair_weights(self) -> tuple[np.ndarray, np.ndarray]:
        """(M^2,) target and (2, M^2) weights of the ordered pairs for the compiled evaluation
        (``_compiled.aggregation_totals`` documents them per scheme)."""
        raise NotImplementedError

    def _split_factors(self) -> np.ndarray:
        """(4, K) factors of the cell-average split of the births of every cell (unused by the
        fixed pivot)."""
        return np.zeros((4, self.K))

    def compiled_arrays(self) -> tuple:
        """(K, cell_average, target, weight, factors, work): the grid's arguments of the compiled
        evaluations (``_compiled.aggregation_totals``, ``_compiled.class_rates``)."""
        return self.K, self._cell_average, self._target, self._weight, self._factors, self._work


class CellAverageAggregation(PivotAggregation):
    """Cell-average technique (Kumar et al. 2006).

    Births are collected per cell c (number B_c, first moment about the pivot D_c, liquid, gas).
    Their mean volume x_c (1 + D_c/B_c) is split between x_c and x_(c+1) if D_c > 0, or between
    x_(c-1) and x_c if D_c < 0, so that number and solid volume are exact. Liquid and gas born
    in c go to those pivots in proportion to the solid volume each receives.
    """

    name = "cell_average"
    _cell_average = True

    def _pair_weights(self):
        T, ok, S = self._T, self._ok, self._S
        w = np.zeros((2, T.size))
        w[0, ok] = S[ok] / self.xr[T[ok]] - 1.0  # s/x_c - 1: the first moment about the pivot
        w[0, ~ok] = S[~ok]  # refused: the aggregate's volume
        return np.where(ok, T, -1), w

    def _split_factors(self):
        return cell_average_factors(self.xr)


class FixedPivotAggregation(PivotAggregation):
    """Fixed pivot technique (Kumar & Ramkrishna 1996).

    An aggregate of volume s with x_k <= s <= x_(k+1) adds (x_(k+1) - s)/(x_(k+1) - x_k) particles
    to bin k and (s - x_k)/(x_(k+1) - x_k) to bin k+1, so number and solid volume are exact. The
    aggregate's liquid and gas are split in proportion to the solid volume each pivot receives.
    """

    name = "fixed_pivot"

    def _pair_weights(self):
        K, ok, S, xr = self.K, self._ok, self._S, self.xr
        s = S[ok]
        lo = np.clip(np.searchsorted(xr, s, side="right") - 1, 0, K - 2)
        up_number = (s - xr[lo]) / (xr[lo + 1] - xr[lo])
        target = np.full(S.size, -1)
        target[ok] = lo
        w = np.zeros((2, S.size))
        w[0, ok] = up_number  # the upper pivot's share of the number
        w[1, ok] = up_number * xr[lo + 1] / s  # and of the solid (liquid and gas follow it)
        w[0, ~ok] = S[~ok]  # refused: the aggregate's volume
        return target, w


def cell_average_factors(xr: np.ndarray) -> np.ndarray:
    """(4, K) factors of the cell-average split of the births of every cell of the pivots ``xr``
    (units of x_0), for aggregation and breakage alike (``_compiled._split_cells``)."""
    dx_up = np.append(xr[1:] - xr[:-1], np.inf)
    dx_down = np.insert(xr[1:] - xr[:-1], 0, np.inf)
    return np.stack(
        [
            xr / dx_up,  # n_up = D_c x_c / (x_(c+1) - x_c); 0 for the last cell
            -xr / dx_down,  # n_down = -D_c x_c / (x_c - x_(c-1)); 0 for the first cell
            np.append(xr[1:] / xr[:-1], 0.0),  # x_(c+1) / x_c
            np.insert(xr[:-1] / xr[1:], 0, 0.0),  # x_(c-1) / x_c
        ]
    )


#: the aggregation schemes by config name
SCHEMES: dict[str, type[PivotAggregation]] = {c.name: c for c in (CellAverageAggregation, FixedPivotAggregation)}

#: operators by (scheme, pivots, cell bounds, extra classes): the same for every model of a grid (a
#: process of the design space builds many; an operator is not modified after its build)
_OPERATORS: dict = {}


def operator(scheme: type[PivotAggregation], grid, extra: tuple) -> PivotAggregation:
    """The operator of ``scheme`` on the pivots and cells of ``grid`` with the ``extra`` class volumes (m3)."""
    bounds = grid.edges[1:-1]
    key = (scheme, grid.x.tobytes(), bounds.tobytes(), extra)
    op = _OPERATORS.get(key)
    if op is None:
        if len(_OPERATORS) >= 32:
            _OPERATORS.clear()
        op = _OPERATORS[key] = scheme(grid.x, bounds, extra=extra or None)
    return op
