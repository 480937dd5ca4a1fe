"""The verification harness: the PBM against the closed-form solutions of `pbm_analytical`.

Discretised initial distributions, the verification grids of the tests and benchmarks, a pure
aggregation run and a breakage run (with or without aggregation) from an exponential start, and
the errors of a result against the analytical solution (`pbm_analytical`) integrated over the
cells.
"""

from __future__ import annotations

import numpy as np
import pbm_analytical as analytical

from pbmdem.config import Solver
from pbmdem.pbm.breakage import Breakage
from pbmdem.pbm.grid import Grid
from pbmdem.pbm.kernels import Kernel, KernelFactors, KernelInput
from pbmdem.pbm.model import GranulationPBM
from pbmdem.pbm.state import State


def discretise_exponential(grid, N0, m):
    """Numbers per bin of ``grid`` for the exponential density: number and volume of each cell
    (first cell from 0, last to infinity) are put on the pivots with the lever rule. Number and
    volume are exact except for mass below x_0 or above x_(K-1) (choose the grid so that it is
    negligible)."""
    edges = np.concatenate([[0.0], grid.edges[1:-1], [np.inf]])
    num, vol = analytical.exponential_cells(edges, N0, m)
    mean = np.clip(vol / np.where(num > 0, num, 1.0), grid.x[0], grid.x[-1])
    N, _ = grid.map_particles(mean, num, what="exponential initial distribution")
    return N


def geometric_grid(q: int = 1, x0: float = 1e-3, x_max: float = 1.6e7):
    """Grid of ratio 2^(1/q) from the first pivot ``x0`` to at least ``x_max`` (in units of the
    initial mean volume): the verification grids of tests and benchmarks."""
    r = 2.0 ** (1.0 / q)
    return Grid(int(np.ceil(np.log(x_max / x0) / np.log(r))) + 1, r, v0=x0)


def simulate_exponential(
    kernel,
    t_end,
    grid,
    scheme: str = "cell_average",
    N0: float = 1.0,
    m: float = 1.0,
    rtol: float = 1e-3,
    atol: float = 1e-9,
    max_overflow_fraction: float = 1e-6,
):
    """Pure aggregation with ``kernel`` from the discretised exponential n(v, 0) = N0/m e^(-v/m) to
    ``t_end``. Returns ``(result, errors)``: the Result and the relative errors of the moments
    M0, M1, M2 at ``t_end`` against ``pbm_analytical.moments`` (M_k = sum N x^k)."""
    N = discretise_exponential(grid, N0, m)
    K = grid.bins
    solver = Solver().replace(rtol=rtol, atol=atol, max_overflow_fraction=max_overflow_fraction)
    model = GranulationPBM(grid, kernel, scheme=scheme, solver=solver)
    res = model.run(0.0, t_end, State(0.0, N, np.zeros(K), np.zeros(K)))
    return res, res.moments()[-1] / np.array(analytical.moments(kernel, t_end, N0, m)) - 1.0


def cell_errors(kernel, grid, number, t, N0: float = 1.0, m: float = 1.0):
    """Errors of the numbers per bin ``number`` at time ``t`` against the kernel's analytical
    solution integrated over the cells (first cell from 0, last to infinity): the L1 error of the
    cell numbers relative to the total number, and the largest error of the cumulative mass
    (solid-volume) fraction over the bins."""
    return density_errors(lambda v: analytical.solution(kernel, v, t, N0, m), grid, number)


class NoAggregation(Kernel):
    """beta = 0: the kernel of the pure-breakage cases."""

    def __repr__(self) -> str:
        return "NoAggregation()"

    def __call__(self, inp: KernelInput) -> np.ndarray:
        M = inp.volumes.size
        return np.zeros((M, M))

    def factors(self, inp: KernelInput) -> KernelFactors:
        return KernelFactors(self(inp))


def simulate_breakage(
    breakage: Breakage,
    t_end: float,
    grid,
    kernel=None,
    N0: float = 1.0,
    m: float = 1.0,
    rtol: float = 1e-6,
    atol: float = 1e-12,
    output_times=None,
):
    """Breakage (with aggregation by ``kernel``; default none) from the discretised exponential
    n(v, 0) = N0/m e^(-v/m) to ``t_end``, liquid and gas 0.3 and 0.1 of the solid of every bin:
    the Result."""
    N = discretise_exponential(grid, N0, m)
    solver = Solver().replace(rtol=rtol, atol=atol, max_step=np.inf)
    model = GranulationPBM(grid, NoAggregation() if kernel is None else kernel, solver=solver, breakage=breakage)
    S = N * grid.x
    return model.run(0.0, t_end, State(0.0, N, 0.3 * S, 0.1 * S), output_times=output_times)


def density_errors(density, grid, number):
    """Errors of the numbers per bin ``number`` against the number density ``density(v)``
    integrated over the cells (first cell from 0, last to infinity): the L1 error of the cell
    numbers relative to the total number, and the largest error of the cumulative mass fraction."""
    edges = np.concatenate([[0.0], grid.edges[1:-1], [np.inf]])
    num, vol = analytical.cell_integrals(density, edges)
    number = np.asarray(number, float)
    l1 = np.abs(number - num).sum() / num.sum()
    Q = np.cumsum(number * grid.x) / np.sum(number * grid.x)
    return float(l1), float(np.abs(Q - np.cumsum(vol) / vol.sum()).max())
