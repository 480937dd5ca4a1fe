"""Class frequencies of one coupling interval, interpolated onto the PBM bins
(`ClassFrequencySource`; docs/validation.md, "DEM -> PBM"): a power law in size, clamped beyond
the classes; impact-velocity fractions of the nearest class in log d; wall impacts per granule
linear in log d between the classes (a class may have none, which log f could not hold)."""

from __future__ import annotations

import numpy as np

from pbmdem.impact import EncounterRates, ImpactRates, WallRates
from pbmdem.pbm.kernels import TableFrequency


class ClassFrequencySource:
    """Hold class frequencies for an interval and interpolate them onto any PBM bins.

    `rates` is the (K, K) encounter frequency per class pair, or an EncounterRates whose velocity
    fractions then make the source velocity-resolved (:meth:`encounters`), or an ImpactRates whose
    wall impacts also make it a source for breakage (:meth:`impacts`)."""

    #: the frequencies on given bins depend on their diameters alone (not on numbers, rpm or time):
    #: a kernel need not ask again for the same bins (``CollisionKernel.prepare``)
    fixed_for_diameters = True

    def __init__(self, diameters, rates, label: str):

        self.diameters = list(map(float, diameters))
        self.fractions = None
        self.walls = None
        if isinstance(rates, ImpactRates):
            self.walls = rates.walls
            rates = rates.pairs
        if isinstance(rates, EncounterRates):
            self.fractions = np.asarray(rates.velocity_fractions, float)
            rates = rates.frequency
        self.matrix = np.asarray(rates, float)
        self.label = label
        self._cache_key = None
        if len(self.diameters) == 1:
            self._value = float(self.matrix[0, 0])
            self._table = None
        else:
            # the TableFrequency of the upper-triangular class pairs, built without DataFrames
            self._table = TableFrequency.from_matrix(
                self.diameters, self.matrix, extrapolation="clamp", column="frequency_per_pair"
            )

    def __repr__(self) -> str:
        return f"ClassFrequencySource({self.label}, classes={len(self.diameters)})"

    def _nearest(self, diameters) -> np.ndarray:
        d = np.log(np.atleast_1d(np.asarray(diameters, float)))
        return np.abs(d[:, None] - np.log(np.asarray(self.diameters))[None, :]).argmin(axis=1)

    def encounters(self, diameters, numbers, rpm) -> EncounterRates:
        if self.fractions is None:
            raise ValueError(f"{self.label}: no impact-velocity distribution for a velocity-dependent success model")
        nearest = self._nearest(diameters)
        # fractions[np.ix_(nearest, nearest)], taken one axis at a time (the same entries, faster)
        return EncounterRates(self(diameters, numbers, rpm), self.fractions[nearest][:, nearest])

    def impacts(self, diameters, numbers, rpm) -> ImpactRates:
        """Pair encounters (:meth:`encounters`) and wall impacts of the bins (needs ImpactRates)."""
        if self.walls is None:
            raise ValueError(f"{self.label}: no wall impacts for breakage from impacts")
        ld = np.log(np.atleast_1d(np.asarray(diameters, float)))
        lx = np.log(np.asarray(self.diameters))
        frequency = np.stack([np.interp(ld, lx, row) for row in self.walls.frequency])
        fractions = self.walls.velocity_fractions[:, self._nearest(diameters)]
        return ImpactRates(self.encounters(diameters, numbers, rpm), WallRates(frequency, fractions, self.walls.walls))

    def __call__(self, diameters, numbers, rpm) -> np.ndarray:
        # within an interval the class frequencies are fixed and the PBM bins do not move, so the
        # interpolated matrix is computed once per set of bin diameters
        key = np.asarray(diameters, float).tobytes()
        if self._cache_key == key:
            return self._cache
        if self._table is None:
            k = np.atleast_1d(diameters).size
            out = np.full((k, k), self._value)
        else:
            out = self._table(diameters, numbers, rpm)
        self._cache_key, self._cache = key, out
        return out
