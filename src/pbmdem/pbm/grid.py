"""Geometric grid of solid volume: pivots v_k = v_0 r^k, k = 0 .. K-1.

Every particle of bin k has the pivot's solid volume x_k; liquid and gas are carried as lumped
per-bin totals. Cells are geometric too, [x_k 2/(1+r), x_k 2r/(1+r)], with the pivot at the
arithmetic centre of its cell (the layout of Kumar et al. 2006). The last cell accepts new particles up to
its pivot x_{K-1} only: anything larger is beyond the grid (see ``aggregation``).

Sizes are solid-volume-equivalent diameters d_k = (6 x_k / pi)^(1/3): the PBM models the DEM bed
with the DEM particle volume taken as the granule's solid volume (pbm.md, "Size coordinate").
"""

from __future__ import annotations

import numpy as np

from .errors import GridRangeError, PBMInputError, positive


def volume_of(d):
    return np.pi / 6.0 * np.asarray(d, float) ** 3


def diameter_of(v):
    return np.cbrt(6.0 / np.pi * np.asarray(v, float))


class Grid:
    """Pivots ``x`` (m3) of a geometric solid-volume grid with ``bins`` bins and ratio ``ratio``.

    Give the first pivot either as a volume ``v0`` or as a diameter ``min_diameter``.
    """

    def __init__(self, bins: int, ratio: float = 2.0, v0: float | None = None, min_diameter: float | None = None):
        if isinstance(bins, bool) or int(bins) != bins or bins < 3:
            raise PBMInputError(f"grid bins = {bins!r}; allowed: an integer >= 3")
        ratio = positive("grid ratio", ratio)
        if ratio <= 1.0:
            raise PBMInputError(f"grid ratio = {ratio!r}; allowed: a number > 1 (v_(k+1) = ratio * v_k)")
        if (v0 is None) == (min_diameter is None):
            raise PBMInputError("grid: give exactly one of v0 (first pivot volume, m3) and min_diameter (m)")
        v0 = (
            positive("grid v0", v0) if v0 is not None else float(volume_of(positive("grid min_diameter", min_diameter)))
        )
        self.bins = int(bins)
        self.ratio = ratio
        self.v0 = v0
        self.x = v0 * ratio ** np.arange(self.bins, dtype=float)
        # diameters relative to the first pivot's (min_diameter exactly, when given): d_k = d_0
        # (x_k / x_0)^(1/3), so that a pivot at a round diameter (32 mm = 16 x 2 mm) is that diameter
        # to the last digit rather than one rounding below it
        d0 = float(min_diameter) if min_diameter is not None else float(diameter_of(v0))
        self.d = d0 * np.cbrt(self.x / self.x[0])
        #: cell edges in volume (K + 1): cell k is [x_k 2/(1+r), x_k 2r/(1+r)], pivot at its centre
        self.edges = np.concatenate([[self.x[0] * 2.0 / (1.0 + ratio)], self.x * 2.0 * ratio / (1.0 + ratio)])
        #: diameter edges (K + 1), geometric midpoints of neighbouring pivot diameters (for PSDs)
        q = ratio ** (1.0 / 6.0)
        self.d_edges = np.concatenate([[self.d[0] / q], np.sqrt(self.d[:-1] * self.d[1:]), [self.d[-1] * q]])

    @classmethod
    def spanning(cls, min_diameter: float, max_diameter: float, ratio: float) -> Grid:
        """Grid of ``ratio`` from the first pivot of diameter ``min_diameter`` to the first pivot at
        or above ``max_diameter`` (m): bins = ceil(ln(x_max / x_0) / ln(ratio)) + 1."""
        dmin = positive("grid min_diameter", min_diameter)
        dmax = positive("grid max_diameter", max_diameter)
        ratio = positive("grid ratio", ratio)
        if ratio <= 1.0:
            raise PBMInputError(f"grid ratio = {ratio!r}; allowed: a number > 1 (v_(k+1) = ratio * v_k)")
        if not dmax > dmin:
            raise PBMInputError(f"grid max_diameter = {dmax!r} m must be larger than min_diameter = {dmin!r} m")
        steps = 3.0 * np.log(dmax / dmin) / np.log(ratio)
        bins = int(np.ceil(steps - 1e-9)) + 1
        return cls(max(bins, 3), ratio, min_diameter=dmin)

    def __repr__(self) -> str:
        return f"Grid(bins={self.bins}, ratio={self.ratio:g}, v0={self.v0:.4g})"

    def map_particles(self, volumes, numbers, what: str = "particles") -> tuple[np.ndarray, np.ndarray]:
        """Put particles of solid ``volumes`` on the grid, conserving number and solid volume.

        A class of volume u with x_i <= u <= x_(i+1) is split between the two pivots by the lever
        rule (a class within 1e-12 of a pivot goes to that pivot alone). Returns ``(N, fraction)``
        where ``N`` is the number per bin and ``fraction`` a (n_classes, K) matrix: the share of
        each class's solid volume sent to each bin (use it to carry liquid and gas with the solid).
        Raises GridRangeError outside [x_0, x_(K-1)].
        """
        u = np.atleast_1d(np.asarray(volumes, float))
        n = np.atleast_1d(np.asarray(numbers, float))
        if u.shape != n.shape:
            raise PBMInputError(f"{what}: {u.size} volumes but {n.size} numbers")
        if np.any(~np.isfinite(n)) or np.any(n < 0):
            raise PBMInputError(f"{what}: numbers {n.tolist()} must be finite and >= 0")
        lo, hi = self.x[0] * (1 - 1e-12), self.x[-1] * (1 + 1e-12)
        bad = (u < lo) | (u > hi) | ~np.isfinite(u)
        if np.any(bad):
            d_bad = diameter_of(u[bad])
            raise GridRangeError(
                f"{what}: diameters {[float(f'{d:.4g}') for d in d_bad]} m (solid volumes "
                f"{[float(f'{v:.4g}') for v in u[bad]]} m3) lie outside the grid; allowed: "
                f"{self.d[0]:.4g} .. {self.d[-1]:.4g} m (pivots x_0 = {self.x[0]:.4g} .. "
                f"x_{self.bins - 1} = {self.x[-1]:.4g} m3); change pbm.grid.min_diameter, bins or ratio"
            )
        i, w_hi, f_hi = self._lever(u)
        rows = np.arange(u.size)
        n_hi = w_hi * n
        n_lo = n - n_hi
        N = np.zeros(self.bins)
        np.add.at(N, i, n_lo)
        np.add.at(N, i + 1, n_hi)
        frac = np.zeros((u.size, self.bins))
        frac[rows, i + 1] = f_hi
        frac[rows, i] = 1.0 - f_hi
        return N, frac

    def _lever(self, volumes):
        """(lower pivot i, number fraction to i+1, solid fraction to i+1) of each volume; a volume
        within 1e-12 (relative) of a pivot goes to that pivot alone (no round-off fragment)."""
        u = np.clip(np.atleast_1d(np.asarray(volumes, float)), self.x[0], self.x[-1])
        i = np.clip(np.searchsorted(self.x, u, side="right") - 1, 0, self.bins - 2)
        w_hi = (u - self.x[i]) / (self.x[i + 1] - self.x[i])  # number fraction to i+1
        f_hi = w_hi * self.x[i + 1] / u  # solid-volume fraction to i+1
        lo, hi = np.abs(u / self.x[i] - 1.0) <= 1e-12, np.abs(u / self.x[i + 1] - 1.0) <= 1e-12
        w_hi[lo], f_hi[lo] = 0.0, 0.0
        w_hi[hi], f_hi[hi] = 1.0, 1.0
        return i, w_hi, f_hi

    def lever_weights(self, volumes) -> tuple[np.ndarray, np.ndarray]:
        """Lever rule of particles of solid ``volumes`` (n,) in [x_0, x_(K-1)]: (n, K) matrices of
        the number fraction and of the solid-volume fraction each pivot receives (rows sum to 1;
        at most two pivots per row), as :meth:`map_particles` splits them. Kept per set of volumes
        (the feed classes of a batch are asked about at every coupling interval); copies returned."""
        key = np.asarray(volumes, float).tobytes()
        cache = self.__dict__.setdefault("_lever_cache", {})
        if key not in cache:
            if len(cache) >= 64:
                cache.clear()
            cache[key] = self._lever_weights(volumes)
        number, frac = cache[key]
        return number.copy(), frac.copy()

    def _lever_weights(self, volumes) -> tuple[np.ndarray, np.ndarray]:
        i, w_hi, f_hi = self._lever(volumes)
        rows = np.arange(i.size)
        number = np.zeros((i.size, self.bins))
        number[rows, i + 1] = w_hi
        number[rows, i] = 1.0 - w_hi
        frac = np.zeros((i.size, self.bins))
        frac[rows, i + 1] = f_hi
        frac[rows, i] = 1.0 - f_hi
        return number, frac
