"""The verification harness of the two-dimensional PBM: the bivariate exponential start on (size
classes) x (liquid classes), a pure-aggregation run with the constant kernel, and its errors
against the closed form of ``analytical2d`` (docs/pbm.md, "Two-dimensional PBM: verification").
"""

from __future__ import annotations

import numpy as np
import pbm_analytical2d as analytical2d

from pbmdem.config import Solver
from pbmdem.pbm.grid import Grid
from pbmdem.pbm.kernels import ConstantKernel
from pbmdem.pbm.liquid_grid import LiquidGrid
from pbmdem.pbm.model2d import GranulationPBM2D

#: Gauss-Legendre nodes per size cell of the start's integrals (exact to round-off for the
#: exponentials over a cell of ratio <= 2)
_NODES = 32


def geometric_liquid_grid(first: float, last: float, ratio: float) -> LiquidGrid:
    """Liquid classes [0, first), [first, first r), ..., [>= last, inf): bounds first r^k up to the
    first at or above ``last`` (the verification's exponential start spans decades of ratio)."""
    n = int(np.ceil(np.log(last / first) / np.log(ratio) - 1e-9)) + 1
    return LiquidGrid(first * ratio ** np.arange(n, dtype=float))


def discretise_bivariate(grid: Grid, lg: LiquidGrid, N0: float, mx: float, my: float, gas_per_solid: float = 0.0):
    """Class totals (3, K, J) (number, liquid, gas) of the bivariate exponential start: the number,
    solid and liquid of every size cell (first from 0) and liquid class are integrated (liquid
    classes: ratio bands y / x), and each (cell, class) is put on the pivots by the lever rule with
    its liquid following the solid (number, solid and liquid exact but for the solid below the
    first pivot's cell and above the last's); gas = ``gas_per_solid`` x solid."""
    edges = np.concatenate([[0.0], grid.edges[1:]])
    z, w = np.polynomial.legendre.leggauss(_NODES)
    a, b = edges[:-1, None], edges[1:, None]
    x = 0.5 * (b - a) * z + 0.5 * (b + a)  # (K, nodes)
    wx = 0.5 * (b - a) * w * np.exp(-x / mx) / mx * N0
    lo = np.concatenate([[0.0], lg.bounds])
    hi = np.concatenate([lg.bounds, [np.inf]])
    K, J = grid.bins, lg.classes
    out = np.zeros((3, K, J))
    for e in range(J):
        ca = np.exp(-lo[e] * x / my)
        cb = np.exp(-hi[e] * x / my) if np.isfinite(hi[e]) else np.zeros_like(x)
        num = (wx * (ca - cb)).sum(1)
        sol = (wx * x * (ca - cb)).sum(1)
        liq_b = (hi[e] * x + my) * cb if np.isfinite(hi[e]) else np.zeros_like(x)
        liq = (wx * ((lo[e] * x + my) * ca - liq_b)).sum(1)
        keep = num > 0
        mean = np.clip(sol[keep] / num[keep], grid.x[0], grid.x[-1])
        N, frac = grid.map_particles(mean, num[keep], what="bivariate exponential start")
        out[0, :, e] = N
        out[1, :, e] = liq[keep] @ frac
        out[2, :, e] = gas_per_solid * (sol[keep] @ frac)
    return out


def simulate_bivariate(grid, lg, beta, t_end, N0, mx, my, rtol=1e-6, atol=1e-12, gas_per_solid=0.1):
    """Pure aggregation with the constant kernel ``beta`` from the discretised bivariate
    exponential to ``t_end``: the Result (``result.classes`` the class totals)."""
    solver = Solver().replace(rtol=rtol, atol=atol, max_step=np.inf)
    model = GranulationPBM2D(grid, ConstantKernel(beta), solver=solver, separate_feed=False, liquid_grid=lg)
    state = model.make_state(0.0, discretise_bivariate(grid, lg, N0, mx, my, gas_per_solid))
    return model.run(0.0, t_end, state)


def bivariate_errors(result, beta, N0, mx, my) -> dict:
    """Errors at the end of ``result`` against the closed form, per size cell (the cells' integrals
    of the density, first cell from 0, last to infinity, by Gauss-Legendre):

    * ``size_l1``: L1 error of the numbers of the size cells relative to the total number;
    * ``liquid_mean``, ``liquid_spread``: relative errors of the mean and of the standard deviation
      of the liquid volume of the granules of each size, weighted by the cells' solid volume;
    * ``M02``: relative error of the second moment of the liquid, sum N l^2 (the spread the
      liquid classes keep: a class's granules count with its mean liquid l)."""
    grid = result.grid
    t = float(result.times[-1])
    C = result.classes[-1]
    K = grid.bins
    N, L = C[0, :K], C[1, :K]
    Nk = N.sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        l = np.where(N > 0, L / np.where(N > 0, N, 1.0), 0.0)
        mean = L.sum(1) / Nk
        second = (N * l * l).sum(1) / Nk
    edges = np.concatenate([[0.0], grid.edges[1:-1], [grid.edges[-1] * 4.0]])
    z, w = np.polynomial.legendre.leggauss(_NODES)
    a, b = edges[:-1, None], edges[1:, None]
    x = 0.5 * (b - a) * z + 0.5 * (b + a)
    wn = 0.5 * (b - a) * w * analytical2d.size_marginal(x, t, beta, N0, mx)
    m_y, v_y = analytical2d.liquid_given_size(x, t, beta, N0, mx, my)
    n_ref = wn.sum(1)
    mean_ref = (wn * m_y).sum(1) / n_ref
    spread_ref = np.sqrt((wn * (v_y + m_y**2)).sum(1) / n_ref - mean_ref**2)
    spread = np.sqrt(np.maximum(second - mean**2, 0.0))
    S = (wn * x).sum(1)
    ok = (S > 1e-12 * S.sum()) & (Nk > 0)
    _, M02, _ = analytical2d.liquid_moments(t, beta, N0, mx, my)
    return {
        "size_l1": float(np.abs(Nk - n_ref).sum() / n_ref.sum()),
        "liquid_mean": float((S * np.abs(mean / mean_ref - 1))[ok].sum() / S[ok].sum()),
        "liquid_spread": float((S * np.abs(spread / spread_ref - 1))[ok].sum() / S[ok].sum()),
        "M02": float((N * l * l).sum() / M02 - 1.0),
    }
