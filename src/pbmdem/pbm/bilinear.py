"""Linear interpolation of a (n, n) table on the square grid (g, g), extrapolated linearly beyond
it: what ``scipy.interpolate.RegularGridInterpolator((g, g), values, method="linear",
bounds_error=False, fill_value=None)`` gives, with the arithmetic of its 2-D path (the cell by
``searchsorted``, the normalised distances y, the four corner terms summed in its order), without
its construction and per-call checks (about 1 ms per coupling interval of the PBM-ANN batch).
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

    def __call__(self, points: np.ndarray) -> np.ndarray:
        g, v = self.grid, self.values
        a, b = points[:, 0], points[:, 1]
        i = np.clip(np.searchsorted(g, a, side="right") - 1, 0, g.size - 2)
        j = np.clip(np.searchsorted(g, b, side="right") - 1, 0, g.size - 2)
        y0 = (a - g[i]) / (g[i + 1] - g[i])
        y1 = (b - g[j]) / (g[j + 1] - g[j])
        out = 0.0 + v[i, j] * (1 - y0) * (1 - y1)
        out = out + v[i, j + 1] * (1 - y0) * y1
        out = out + v[i + 1, j] * y0 * (1 - y1)
        return out + v[i + 1, j + 1] * y0 * y1

    def outer(self, a: np.ndarray) -> np.ndarray:
        """(n, n): ``self(points)`` at every pair (a[p], a[q]) of ``a`` (n,), reshaped: the cells
        and distances of the n values once, broadcast over the pairs; elementwise the same
        operations, so the same numbers to the bit (tests/test_pbm_compiled.py)."""
        g, v = self.grid, self.values
        i = np.clip(np.searchsorted(g, a, side="right") - 1, 0, g.size - 2)
        y = (a - g[i]) / (g[i + 1] - g[i])
        i0, j0 = i[:, None], i[None, :]
        y0, y1 = y[:, None], y[None, :]
        out = 0.0 + v[i0, j0] * (1 - y0) * (1 - y1)
        out = out + v[i0, j0 + 1] * (1 - y0) * y1
        out = out + v[i0 + 1, j0] * y0 * (1 - y1)
        return out + v[i0 + 1, j0 + 1] * y0 * y1
