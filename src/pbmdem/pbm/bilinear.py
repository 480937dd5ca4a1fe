"""Linear interpolation of a (n, n) table on the square grid (g, g), extrapolated linearly beyond
it: what ``scipy.interpolate.RegularGridInterpolator((g, g), values, method="linear",
bounds_error=False, fill_value=None)`` gives, with the arithmetic of its 2-D path (the cell by
``searchsorted``, the normalised distances y, the four corner terms summed in its order), without
its construction and per-call checks (about 1 ms per coupling interval of the PBM-ANN batch); at
every pair of a set of points (``outer``, the bins' frequency matrix) compiled.
``TableFrequency`` uses it for its log frequencies; tests/test_pbm_compiled.py holds it equal to
the interpolator to the bit on random tables and points, inside and outside the grid.
"""

from __future__ import annotations

import numpy as np


class Bilinear:
    """``Bilinear(grid (n,), values (n, n))(points (m, 2)) -> (m,)``, n >= 2, grid strictly ascending."""

    def __init__(self, grid: np.ndarray, values: np.ndarray):
        self.grid = np.asarray(grid, float)
        self.values = np.asarray(values, float)

    def _cell(self, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The cell of every value of ``a`` (the lower node, the last cell beyond the grid) and the
        normalised distance from its lower node."""
        g = self.grid
        i = np.clip(np.searchsorted(g, a, side="right") - 1, 0, g.size - 2)
        return i, (a - g[i]) / (g[i + 1] - g[i])

    def _corners(self, i, j, y0, y1) -> np.ndarray:
        """The four corner terms of the cells (i, j), summed in the interpolator's order."""
        v = self.values
        out = 0.0 + v[i, j] * (1 - y0) * (1 - y1)
        out = out + v[i, j + 1] * (1 - y0) * y1
        out = out + v[i + 1, j] * y0 * (1 - y1)
        return out + v[i + 1, j + 1] * y0 * y1

    def __call__(self, points: np.ndarray) -> np.ndarray:
        (i, y0), (j, y1) = self._cell(points[:, 0]), self._cell(points[:, 1])
        return self._corners(i, j, y0, y1)

    def outer(self, a: np.ndarray) -> np.ndarray:
        """(n, n): ``self(points)`` at every pair (a[p], a[q]) of ``a`` (n,), reshaped, compiled
        (``_compiled.bilinear_outer``: the cells and distances of the n values once, the corner
        terms over the pairs); elementwise the same operations, so the same numbers to the bit
        (tests/test_pbm_compiled.py)."""
        from ._compiled import bilinear_outer  # numba: loaded with the model's compiled rates

        a = np.ascontiguousarray(a, dtype=float)
        out = np.empty((a.size, a.size))
        bilinear_outer(np.ascontiguousarray(self.grid), np.ascontiguousarray(self.values), a, out)
        return out
