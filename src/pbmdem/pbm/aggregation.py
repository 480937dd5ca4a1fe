"""Aggregation by the cell-average technique (Kumar et al. 2006, Chem. Eng. Sci. 61:3327).

For the K pivots x_k every unordered pair (i <= j) is precomputed once per grid: the volume of
its aggregate s_ij = x_i + x_j and the cell it falls into (``bounds``: the K-1 inner cell
boundaries; default for a geometric grid x_k 2r/(1+r), pivots at the cell centres). At each rate evaluation, with event rates R_ij = beta_ij N_i N_j (i < j) and
R_ii = beta_ii N_i^2 / 2:

1. births per cell: number B_c = sum R_ij, solid volume V_c = sum R_ij s_ij, liquid and gas
   sum R_ij (l_i + l_j) and sum R_ij (g_i + g_j) over pairs landing in c (l, g per particle);
2. the average new volume a_c = V_c / B_c is split between the pivots x_c and x_(c+1) (if
   a_c > x_c) or x_(c-1) and x_c (if a_c < x_c) so that number and solid volume are exact;
3. liquid and gas born in c are distributed to those two pivots in proportion to the solid
   volume sent to each, so per-bin totals are conserved;
4. deaths: each event removes one particle of each partner with its per-particle liquid and gas.

Pairs whose aggregate exceeds the last pivot x_(K-1) are refused (neither birth nor death), so
solid volume is conserved to round-off; the solid-volume rate of the refused aggregates is
returned so the solver can account for it and stop (GridOverflowError) once it exceeds the
allowed fraction. No Python loop runs over pairs: scatter sums use ``np.bincount``.
"""

from __future__ import annotations

import numpy as np


class CellAverageAggregation:
    """Precomputed cell-average aggregation operator of a pivot grid ``x`` (ascending, (K,))."""

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
        target = np.searchsorted(bounds, s, side="right")
        valid = s <= x[-1] * (1.0 + 1e-12)
        self.pair_i, self.pair_j = iu, ju
        self.pair_weight = np.where(iu == ju, 0.5, 1.0)
        self.valid = valid
        self.i, self.j = iu[valid], ju[valid]
        self.weight = self.pair_weight[valid]
        self.s = s[valid]
        self.target = target[valid]
        self.refused_i, self.refused_j = iu[~valid], ju[~valid]
        self.refused_s = s[~valid]
        self.refused_weight = self.pair_weight[~valid]
        #: full (K, K) matrices for inspection: aggregate volume and target cell (-1 = beyond grid)
        tm = np.full((K, K), -1, dtype=int)
        tm[iu[valid], ju[valid]] = target[valid]
        tm[ju[valid], iu[valid]] = target[valid]
        self.target_matrix = tm
        self.dx_up = np.append(x[1:] - x[:-1], np.inf)     # x_(c+1) - x_c (inf for the last cell)
        self.dx_down = np.insert(x[1:] - x[:-1], 0, np.inf)  # x_c - x_(c-1) (inf for the first)
        self.x_up = np.append(x[1:], 0.0)
        self.x_down = np.insert(x[:-1], 0, 0.0)

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
        t = self.target
        B = np.bincount(t, R, K)
        V = np.bincount(t, R * self.s, K)
        BL = np.bincount(t, R * (l[i] + l[j]), K)
        BG = np.bincount(t, R * (g[i] + g[j]), K)

        x = self.x
        has = B > 0
        a = np.where(has, V / np.where(has, B, 1.0), x)
        up = a > x
        down = a < x
        n_up = np.where(up, B * (a - x) / self.dx_up, 0.0)
        n_down = np.where(down, B * (x - a) / self.dx_down, 0.0)
        n_stay = B - n_up - n_down
        # share of each cell's born solid volume sent up / down (the rest stays at x_c)
        Vs = np.where(V > 0, V, 1.0)
        f_up = n_up * self.x_up / Vs
        f_down = n_down * self.x_down / Vs
        f_stay = 1.0 - f_up - f_down

        dN = n_stay - loss
        dN[1:] += n_up[:-1]
        dN[:-1] += n_down[1:]
        dL = BL * f_stay - loss * l
        dL[1:] += (BL * f_up)[:-1]
        dL[:-1] += (BL * f_down)[1:]
        dG = BG * f_stay - loss * g
        dG[1:] += (BG * f_up)[:-1]
        dG[:-1] += (BG * f_down)[1:]
        return dN, dL, dG, refused
