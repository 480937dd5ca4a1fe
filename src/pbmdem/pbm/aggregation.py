"""Aggregation on a pivot grid: the cell-average technique and the fixed pivot technique.

Two interchangeable discretisations of the Smoluchowski equation on the K pivots x_k (every
particle of bin k has solid volume x_k), selected by ``pbm.aggregation.scheme``:

* ``cell_average`` (default): Kumar, Peglow, Warnecke, Heinrich, Moerl (2006), Chem. Eng. Sci.
  61:3327. Births are first collected per cell, then their average volume is split between two
  neighbouring pivots.
* ``fixed_pivot``: Kumar & Ramkrishna (1996), Chem. Eng. Sci. 51:1311. Every aggregate is split
  between the two pivots that bracket its own volume.

Both preserve number and solid volume exactly and differ only in how births are placed. Every
ordered pair (i, j) is mapped once per grid: the aggregate volume s_ij = x_i + x_j and where it
goes. A rate evaluation works on bin *totals* (numbers N, liquid L and gas G per bin) and never
divides by a number or a volume of the state:

* ordered-pair rates R_ij = beta_ij N_i N_j, RL_ij = beta_ij L_i N_j, RG_ij = beta_ij G_i N_j
  (the event rate of the unordered pair i < j is R_ij, of i = i it is R_ii / 2; the liquid an
  event of (i, j) brings is l_i + l_j, so sum RL over both orders is the liquid born);
* every per-bin total the scheme needs is a sum of these 3 K^2 rates with weights fixed by the
  grid: deaths (N_i sum_j beta_ij N_j and the same for L and G: each event removes one particle
  of each partner with its own liquid and gas), births and the refused solid rate. One compiled
  loop over the ordered pairs (numba, ``_compiled.aggregation_totals``) forms them, with the
  target cell of every pair precomputed once per grid. The same sums as one precomputed sparse
  map (scipy.sparse, block-diagonal over R, RL, RG) are kept as the numpy reference
  (``totals_numpy``): the same products added in the same order, so the two agree to the bit.

Cell average, volumes in units of the cell's pivot: with B_c = sum R (number born in cell c) and
D_c = sum R (s/x_c - 1) (first moment of the births about the pivot, in units of x_c), the mean
a_c = x_c (1 + D_c/B_c) goes up if D_c > 0: n_up = D_c x_c/(x_(c+1) - x_c), or down if D_c < 0:
n_down = -D_c x_c/(x_c - x_(c-1)); the rest stays. |D_c| <= B_c (r - 1)/(r + 1) by construction,
so every share is non-negative whatever the unit of volume and however small the rates; no
mean volume a_c = V_c/B_c is ever formed (that ratio of two underflowing sums is where a run in
m3 could produce negative births). Liquid and gas born in a cell follow the solid volume each
pivot receives.

Feed classes (``extra``): besides the K pivot classes, a map can hold P further classes of any
volume in [x_0, x_(K-1)] that never receive births: the feed granules that have not aggregated
yet, at their own sizes and apart from the aggregates, so that the two do not share liquid and
gas (docs/pbm.md, "Feed granules"). They die like any class; an aggregate of volume s (of any
two classes) is born on the pivots like every other. The classes are ordered [pivots 0..K-1,
extra 0..P-1] in ``beta`` (K+P, K+P) and in the (3, K+P) totals.

Pairs whose aggregate exceeds the last pivot x_(K-1) are refused: no birth and no death, so solid
volume is conserved to round-off. The solid-volume rate of refused aggregates is returned, so
the solver can account for it and stop (GridOverflowError) once it exceeds the allowed fraction.

Accuracy (docs/pbm.md, ``benchmarks/bench_pbm_accuracy.py``): both schemes are exact in the
zeroth and first moments. The fixed pivot places every aggregate on the two pivots around it,
and this adds variance, so it over-predicts the second moment. With a ratio-2 grid and Golovin's
kernel after 10x growth of the mean volume the error is +500 %. The cell average largely cancels
that error and is the default.
"""

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
        # ordered pairs (i, j), flattened row-major: column i * K + j of the maps
        I, J = np.divmod(np.arange(M * M), M)
        S = vc[I] + vc[J]
        ok = tm.ravel() >= 0
        self._I, self._J, self._S, self._ok = I, J, S, ok
        self._T = tm.ravel()
        self._build()

    def __repr__(self) -> str:
        extra = f", extra={np.round(self.extra / self.x[0], 6).tolist()} x_0" if self.extra.size else ""
        return f"{type(self).__name__}(K={self.K}{extra})"

    # ----------------------------------------------------------------- sparse maps
    def _number_rows(self):
        """(rows, cols, values) of the scheme's map applied to R (rows 0 .. 2K-1)."""
        raise NotImplementedError

    def _liquid_rows(self):
        """(rows, cols, values) of the scheme's map applied to RL and RG (rows 0 .. 2K-1)."""
        raise NotImplementedError

    def _build(self):
        """The arrays of the compiled evaluation (numba, imported here: building an operator loads
        or compiles it, :mod:`._compiled`): the target cell or lower pivot of every ordered pair
        (-1 beyond the grid) and its weights."""
        from . import _compiled

        self._totals = _compiled.aggregation_totals
        target, weight = self._pair_weights()
        self._target = np.ascontiguousarray(target, dtype=np.int64)
        self._weight = np.ascontiguousarray(weight, dtype=float)
        self._factors = np.zeros((4, self.K))
        self._work = np.empty((10, self.K))
        self._no_p = np.ones(self.M)
        self._map = None

    def _build_map(self):
        """The sparse map of :meth:`totals_numpy` (built on first use)."""
        from scipy import sparse

        K, M, I, ok = self.K, self.M, self._I, self._ok
        cols = np.arange(M * M)
        # every block (R, RL, RG) has 2K + M + 1 rows: [0, K) the scheme's first K rows (births),
        # [K, 2K) its second K rows (cell average: D_c, R block only), [2K, 2K + M) the deaths of
        # the M classes (row i collects beta_ij N_j x (N_i, L_i or G_i) over valid j; the pair
        # (i, i) removes two particles at the event rate R_ii / 2), 2K + M the refused solid (R
        # block only, x_0 units)
        R = self.R = 2 * K + M + 1
        dr, dc = 2 * K + I[ok], cols[ok]
        refused = ~ok
        blocks = []
        for rows, cc, vals in (self._number_rows(), self._liquid_rows(), self._liquid_rows()):
            if len(blocks) == 0:
                extra_r = np.concatenate([dr, np.full(int(refused.sum()), 2 * K + M)])
                extra_c = np.concatenate([dc, cols[refused]])
                extra_v = np.concatenate([np.ones(dr.size), 0.5 * self._S[refused]])
            else:
                extra_r, extra_c, extra_v = dr, dc, np.ones(dr.size)
            blocks.append(
                sparse.csr_matrix(
                    (np.concatenate([vals, extra_v]), (np.concatenate([rows, extra_r]), np.concatenate([cc, extra_c]))),
                    shape=(R, M * M),
                )
            )
        m = sparse.block_diag(blocks, format="csr")
        m.sum_duplicates()
        m.sort_indices()
        self._map = m
        self._y = np.zeros(3 * R)
        self._U = np.empty((3, M, M))
        try:  # the bare CSR kernel skips scipy's dispatch (~5 us)
            from scipy.sparse import _sparsetools

            self._matvec = _sparsetools.csr_matvec
        except ImportError:  # pragma: no cover - other scipy layouts
            self._matvec = None

    def _pair_weights(self) -> tuple[np.ndarray, np.ndarray]:
        """(M^2,) target and (2, M^2) weights of the ordered pairs for the compiled evaluation."""
        raise NotImplementedError

    # ----------------------------------------------------------------- evaluation
    def totals(self, beta: np.ndarray, N: np.ndarray, L: np.ndarray, G: np.ndarray):
        """Aggregation rates from class totals: ``beta`` (M, M) symmetric, numbers ``N``, liquid
        ``L`` and gas ``G`` totals per class (M,) in any unit of volume (M = K without extra
        classes). Returns ``(d, refused)``: ``d`` (3, M) the rates of N, L and G (in the units of
        L and G) and the refused solid-volume rate in units of the first pivot x_0 (multiply by
        x_0)."""
        return self.totals_stacked(beta, np.stack((N, L, G)))

    def totals_stacked(self, beta: np.ndarray, nlg: np.ndarray):
        """:meth:`totals` with N, L, G given as one (3, M) array: one compiled loop over the ordered
        pairs, equal to the bit to :meth:`totals_numpy` (the sparse map)."""
        M = self.M
        if np.shape(beta) != (M, M) or np.shape(nlg) != (3, M):
            raise ValueError(
                f"aggregation totals: beta {np.shape(beta)} and N, L, G {np.shape(nlg)}; expected "
                f"({M}, {M}) and (3, {M}) for the {M} classes"
            )
        d = np.empty((3, M))
        refused = self._totals(
            np.ascontiguousarray(beta, dtype=float),
            self._no_p,
            False,
            np.ascontiguousarray(nlg, dtype=float),
            self.K,
            self._cell_average,
            self._target,
            self._weight,
            self._factors,
            self._work,
            d,
        )
        return d, refused

    def compiled_arrays(self) -> tuple:
        """(K, cell_average, target, weight, factors, work): the grid's arguments of the compiled
        evaluations (``_compiled.aggregation_totals``, ``_compiled.class_rates``)."""
        return self.K, self._cell_average, self._target, self._weight, self._factors, self._work

    def totals_numpy(self, beta: np.ndarray, nlg: np.ndarray):
        """:meth:`totals_stacked` in numpy: the ordered-pair rates mapped by one sparse product (the
        reference of the compiled evaluation; about 25 numpy calls instead of one)."""
        if self._map is None:
            self._build_map()
        U = np.multiply(nlg[:, :, None], beta * nlg[0], out=self._U)  # R, RL, RG
        m, y = self._map, self._y
        if self._matvec is not None:
            y.fill(0.0)
            self._matvec(m.shape[0], m.shape[1], m.indptr, m.indices, m.data, U.reshape(-1), y)
        else:
            y = m @ U.reshape(-1)
        Y = y.reshape(3, self.R)
        K, M = self.K, self.M
        d = -Y[:, 2 * K : 2 * K + M]
        d[:, :K] += self._births(Y)
        return d, float(Y[0, 2 * K + M])

    def rates(self, beta: np.ndarray, N: np.ndarray, l: np.ndarray, g: np.ndarray):
        """Aggregation rates of change from per-particle liquid ``l`` and gas ``g`` (K,).

        Returns ``(dN, dL, dG, refused_rate)``: per-bin rates of number, liquid and gas totals and
        the solid-volume rate (in the unit of ``x``) of refused aggregates beyond the last bin.
        """
        N = np.asarray(N, float)
        d, refused = self.totals(np.asarray(beta, float), N, N * l, N * g)
        return d[0], d[1], d[2], refused * self.x[0]

    def _births(self, Y: np.ndarray) -> np.ndarray:
        """(3, K) birth rates of number, liquid and gas from the mapped sums ``Y`` (3, 2K + M + 1)."""
        raise NotImplementedError


class CellAverageAggregation(PivotAggregation):
    """Cell-average technique (Kumar et al. 2006).

    Births are collected per cell c (number B_c, first moment about the pivot D_c, liquid, gas).
    Their mean volume x_c (1 + D_c/B_c) is split between x_c and x_(c+1) if D_c > 0, or between
    x_(c-1) and x_c if D_c < 0, so that number and solid volume are exact. Liquid and gas born
    in c go to those pivots in proportion to the solid volume each receives.
    """

    name = "cell_average"
    _cell_average = True

    def _number_rows(self):
        K, T, ok, S, xr = self.K, self._T, self._ok, self._S, self.xr
        cols = np.arange(self.M**2)[ok]
        t = T[ok]
        # rows 0..K-1: B_c (weight 1/2 per ordered pair); rows K..2K-1: D_c = sum R (s/x_c - 1)
        rows = np.concatenate([t, K + t])
        vals = np.concatenate([np.full(t.size, 0.5), 0.5 * (S[ok] / xr[t] - 1.0)])
        return rows, np.concatenate([cols, cols]), vals

    def _liquid_rows(self):
        ok = self._ok
        cols = np.arange(self.M**2)[ok]
        return self._T[ok], cols, np.ones(cols.size)

    def _pair_weights(self):
        T, ok, S = self._T, self._ok, self._S
        w = np.zeros((2, T.size))
        w[0, ok] = S[ok] / self.xr[T[ok]] - 1.0  # s/x_c - 1: the first moment about the pivot
        w[0, ~ok] = S[~ok]  # refused: the aggregate's volume
        return np.where(ok, T, -1), w

    def _build(self):
        super()._build()
        xr = self.xr
        dx_up = np.append(xr[1:] - xr[:-1], np.inf)
        dx_down = np.insert(xr[1:] - xr[:-1], 0, np.inf)
        self._cu = xr / dx_up  # n_up = D_c x_c / (x_(c+1) - x_c); 0 for the last cell
        self._ncd = -xr / dx_down  # n_down = -D_c x_c / (x_c - x_(c-1)); 0 for the first cell
        self._ru = np.append(xr[1:] / xr[:-1], 0.0)  # x_(c+1) / x_c
        self._rd = np.insert(xr[:-1] / xr[1:], 0, 0.0)  # x_(c-1) / x_c
        self._factors = np.ascontiguousarray(np.stack([self._cu, self._ncd, self._ru, self._rd]))

    def _births(self, Y):
        K = self.K
        A = Y[:, :K]  # number, liquid, gas born per cell
        B, D = A[0], Y[0, K : 2 * K]
        up = np.maximum(D, 0.0) * self._cu
        down = np.minimum(D, 0.0) * self._ncd
        V = B + D  # solid born, units of x_c (>= B 2/(1+r))
        inv = np.divide(1.0, V, out=np.zeros(K), where=V > 0)
        mu = np.empty((3, K))
        md = np.empty((3, K))
        mu[0] = up
        md[0] = down
        np.multiply(A[1:], up * self._ru * inv, out=mu[1:])  # liquid and gas follow the solid
        np.multiply(A[1:], down * self._rd * inv, out=md[1:])
        out = A - mu - md
        out[:, 1:] += mu[:, :-1]
        out[:, :-1] += md[:, 1:]
        return out


class FixedPivotAggregation(PivotAggregation):
    """Fixed pivot technique (Kumar & Ramkrishna 1996).

    An aggregate of volume s with x_k <= s <= x_(k+1) adds (x_(k+1) - s)/(x_(k+1) - x_k) particles
    to bin k and (s - x_k)/(x_(k+1) - x_k) to bin k+1, so number and solid volume are exact. The
    aggregate's liquid and gas are split in proportion to the solid volume each pivot receives.
    """

    name = "fixed_pivot"

    def _split(self):
        K, ok, S, xr = self.K, self._ok, self._S, self.xr
        s = S[ok]
        lo = np.clip(np.searchsorted(xr, s, side="right") - 1, 0, K - 2)
        up_number = (s - xr[lo]) / (xr[lo + 1] - xr[lo])
        up_solid = up_number * xr[lo + 1] / s
        return np.arange(self.M**2)[ok], lo, up_number, up_solid

    def _number_rows(self):
        cols, lo, up, _ = self._split()
        rows = np.concatenate([lo, lo + 1])
        return rows, np.concatenate([cols, cols]), 0.5 * np.concatenate([1.0 - up, up])

    def _liquid_rows(self):
        cols, lo, _, up = self._split()
        rows = np.concatenate([lo, lo + 1])
        return rows, np.concatenate([cols, cols]), np.concatenate([1.0 - up, up])

    def _births(self, Y):
        return Y[:, : self.K]

    def _pair_weights(self):
        ok, S = self._ok, self._S
        _, lo, up_number, up_solid = self._split()
        target = np.full(S.size, -1)
        target[ok] = lo
        w = np.zeros((2, S.size))
        w[0, ok], w[1, ok] = up_number, up_solid
        w[0, ~ok] = S[~ok]
        return target, w


#: the aggregation schemes by config name
SCHEMES: dict[str, type[PivotAggregation]] = {c.name: c for c in (CellAverageAggregation, FixedPivotAggregation)}
