"""Aggregation on a pivot grid: the cell-average technique and the fixed pivot technique.

Two interchangeable discretisations of the Smoluchowski equation on the K pivots x_k (every
particle of bin k has solid volume x_k), selected by ``pbm.aggregation.scheme``:

* ``cell_average`` (default): Kumar, Peglow, Warnecke, Heinrich, Moerl (2006), Chem. Eng. Sci.
  61:3327. Births are first collected per cell, then their average volume is split between two
  neighbouring pivots.
* ``fixed_pivot``: Kumar & Ramkrishna (1996), Chem. Eng. Sci. 51:1311. Every aggregate is split
  between the two pivots that bracket its own volume.

Both preserve number and solid volume exactly and differ only in how births are placed. Every
unordered pair (i <= j) is precomputed once per grid: the aggregate volume s_ij = x_i + x_j and
where it goes. A rate evaluation, with event rates R_ij = beta_ij N_i N_j (i < j) and
R_ii = beta_ii N_i^2 / 2, works like this:

1. deaths: each event removes one particle of each partner, with its own liquid and gas
   (per particle: l, g);
2. births: number, solid volume, and liquid and gas sum R (l_i + l_j), sum R (g_i + g_j) go to
   pivots as the scheme decides. Liquid and gas follow the solid volume sent to each pivot, so
   per-bin totals are conserved.

Pairs whose aggregate exceeds the last pivot x_(K-1) are refused: no birth and no death, so solid
volume is conserved to round-off. The solid-volume rate of refused aggregates is returned, so
the solver can account for it and stop (GridOverflowError) once it exceeds the allowed fraction.
No Python loop runs over pairs; scatter sums use ``np.bincount``.

Accuracy (docs/pbm.md, ``benchmarks/bench_pbm_accuracy.py``): both schemes are exact in the
zeroth and first moments. The fixed pivot places every aggregate on the two pivots around it,
and this adds variance, so it over-predicts the second moment. With a ratio-2 grid and Golovin's
kernel after 10x growth of the mean volume the error is +500 %. The cell average largely cancels
that error and is the default.
"""

from __future__ import annotations

import numpy as np


class PivotAggregation:
    """Shared pair bookkeeping of the pivot schemes: grid ``x`` (ascending, (K,)) and the K-1 inner
    cell ``bounds`` (default: x_k 2r/(1+r), pivots at the centres of geometric cells)."""

    #: name used in the config (``pbm.aggregation.scheme``)
    name = ""

    def __init__(self, x: np.ndarray, bounds: np.ndarray | None = None):
        x = np.asarray(x, float)
        self.x = x
        K = self.K = x.size
        iu, ju = np.triu_indices(K)
        s = x[iu] + x[ju]
        if bounds is None:
            r = x[1] / x[0]
            bounds = x[:-1] * 2.0 * r / (1.0 + r)
        bounds = np.asarray(bounds, float)
        if bounds.shape != (K - 1,) or np.any(bounds <= x[:-1]) or np.any(bounds >= x[1:]):
            raise ValueError("cell bounds must be K-1 values strictly between neighbouring pivots")
        valid = s <= x[-1] * (1.0 + 1e-12)
        pair_weight = np.where(iu == ju, 0.5, 1.0)
        self.i, self.j = iu[valid], ju[valid]
        self.weight = pair_weight[valid]
        self.s = s[valid]
        self.refused_i, self.refused_j = iu[~valid], ju[~valid]
        self.refused_s = s[~valid]
        self.refused_weight = pair_weight[~valid]
        #: (K, K) target cell of each pair's aggregate (-1 = beyond the grid), for inspection
        target = np.searchsorted(bounds, s, side="right")
        tm = np.full((K, K), -1, dtype=int)
        tm[iu[valid], ju[valid]] = target[valid]
        tm[ju[valid], iu[valid]] = target[valid]
        self.target_matrix = tm
        #: target cell of each valid pair's aggregate
        self.target = target[valid]

    def __repr__(self) -> str:
        return f"{type(self).__name__}(K={self.K})"

    def rates(self, beta: np.ndarray, N: np.ndarray, l: np.ndarray, g: np.ndarray):
        """Aggregation rates of change.

        Parameters: kernel ``beta`` (K, K), numbers ``N`` (K,), per-particle liquid ``l`` and gas
        ``g`` (K,). Returns ``(dN, dL, dG, refused_rate)``: per-bin rates of number, liquid and gas
        totals and the solid-volume rate (m3/s) of refused aggregates beyond the last bin.
        """
        K = self.K
        i, j = self.i, self.j
        R = beta[i, j] * N[i] * N[j] * self.weight
        if self.refused_s.size:
            ri, rj = self.refused_i, self.refused_j
            refused = float(np.sum(beta[ri, rj] * N[ri] * N[rj] * self.refused_weight * self.refused_s))
        else:
            refused = 0.0
        loss = np.bincount(i, R, K) + np.bincount(j, R, K)
        bN, bL, bG = self._births(R, l[i] + l[j], g[i] + g[j])
        return bN - loss, bL - loss * l, bG - loss * g, refused

    def _births(self, R, pair_liquid, pair_gas):
        """Per-bin birth rates of number, liquid and gas for event rates ``R`` of the valid pairs."""
        raise NotImplementedError


class CellAverageAggregation(PivotAggregation):
    """Cell-average technique (Kumar et al. 2006).

    Births are collected per cell c (number B_c, solid V_c, liquid, gas). Their mean volume
    a_c = V_c / B_c is split between x_c and x_(c+1) if a_c > x_c, or between x_(c-1) and x_c if
    a_c < x_c, so that number and solid volume are exact. Liquid and gas born in c go to those
    pivots in proportion to the solid volume each receives.
    """

    name = "cell_average"

    def __init__(self, x: np.ndarray, bounds: np.ndarray | None = None):
        super().__init__(x, bounds)
        x = self.x
        self.dx_up = np.append(x[1:] - x[:-1], np.inf)     # x_(c+1) - x_c (inf for the last cell)
        self.dx_down = np.insert(x[1:] - x[:-1], 0, np.inf)  # x_c - x_(c-1) (inf for the first)
        self.x_up = np.append(x[1:], 0.0)
        self.x_down = np.insert(x[:-1], 0, 0.0)

    def _births(self, R, pair_liquid, pair_gas):
        K, x, t = self.K, self.x, self.target
        B = np.bincount(t, R, K)
        V = np.bincount(t, R * self.s, K)
        BL = np.bincount(t, R * pair_liquid, K)
        BG = np.bincount(t, R * pair_gas, K)
        has = B > 0
        a = np.where(has, V / np.where(has, B, 1.0), x)
        n_up = np.where(a > x, B * (a - x) / self.dx_up, 0.0)
        n_down = np.where(a < x, B * (x - a) / self.dx_down, 0.0)
        n_stay = B - n_up - n_down
        # share of each cell's born solid volume sent up / down (the rest stays at x_c)
        Vs = np.where(V > 0, V, 1.0)
        f_up = n_up * self.x_up / Vs
        f_down = n_down * self.x_down / Vs
        f_stay = 1.0 - f_up - f_down
        out = []
        for stay, up, down in ((n_stay, n_up, n_down), (BL * f_stay, BL * f_up, BL * f_down),
                               (BG * f_stay, BG * f_up, BG * f_down)):
            b = stay.copy()
            b[1:] += up[:-1]
            b[:-1] += down[1:]
            out.append(b)
        return tuple(out)


class FixedPivotAggregation(PivotAggregation):
    """Fixed pivot technique (Kumar & Ramkrishna 1996).

    An aggregate of volume s with x_k <= s <= x_(k+1) adds (x_(k+1) - s)/(x_(k+1) - x_k) particles
    to bin k and (s - x_k)/(x_(k+1) - x_k) to bin k+1, so number and solid volume are exact. The
    aggregate's liquid and gas are split in proportion to the solid volume each pivot receives.
    """

    name = "fixed_pivot"

    def __init__(self, x: np.ndarray, bounds: np.ndarray | None = None):
        super().__init__(x, bounds)
        x, s = self.x, self.s
        lo = np.clip(np.searchsorted(x, s, side="right") - 1, 0, self.K - 2)
        self.lower = lo
        self.up_number = (s - x[lo]) / (x[lo + 1] - x[lo])    # number fraction to lo + 1
        self.up_solid = self.up_number * x[lo + 1] / s        # solid-volume fraction to lo + 1

    def _births(self, R, pair_liquid, pair_gas):
        K, lo, hi = self.K, self.lower, self.lower + 1
        out = []
        for amount, up in ((R, self.up_number), (R * pair_liquid, self.up_solid), (R * pair_gas, self.up_solid)):
            out.append(np.bincount(lo, amount * (1.0 - up), K) + np.bincount(hi, amount * up, K))
        return tuple(out)


#: the aggregation schemes by config name
SCHEMES: dict[str, type[PivotAggregation]] = {c.name: c for c in (CellAverageAggregation, FixedPivotAggregation)}
