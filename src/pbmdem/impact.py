"""Impact-velocity bins and velocity-resolved encounter rates: the contract shared by the DEM
collision tables, the surrogate and the PBM aggregation kernel.

An *encounter* is an impact of two granules that were apart (docs/dem.md); its impact velocity is
the relative normal approach speed just before contact (m/s). Encounter counts are binned on one
fixed set of velocity bins so that tables of different runs, the surrogate's predictions and the
PBM's success probability all speak about the same bins:

* bin 0 holds [0, 1 mm/s): gentle re-contacts, far below any speed at which a binder layer
  could fail to hold two granules together;
* bins 1..16 are log-spaced, four per decade, from 1 mm/s to 10 m/s (a high-shear granulator's
  impeller tip speed is 1-15 m/s; impacts are a fraction of it);
* speeds at or above 10 m/s are counted in the last bin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BINS_PER_DECADE = 4
V_MIN = 1.0e-3  # m/s, lower edge of the first log-spaced bin
V_MAX = 10.0  # m/s, upper edge of the last bin
VELOCITY_EDGES = np.concatenate(
    [[0.0], np.logspace(np.log10(V_MIN), np.log10(V_MAX), int(round(BINS_PER_DECADE * np.log10(V_MAX / V_MIN))) + 1)]
)
N_VELOCITY_BINS = len(VELOCITY_EDGES) - 1


def velocity_bin(v) -> np.ndarray:
    """Bin index (0 .. N_VELOCITY_BINS-1) of each impact speed `v` (m/s, >= 0; larger than
    V_MAX goes to the last bin). Raises ValueError on negative or non-finite speeds."""
    v = np.asarray(v, float)
    if not np.all(np.isfinite(v)) or (v < 0).any():
        bad = v[~np.isfinite(v) | (v < 0)][0]
        raise ValueError(f"impact speed {bad!r} m/s: allowed are finite speeds >= 0")
    return np.clip(np.searchsorted(VELOCITY_EDGES, v, side="right") - 1, 0, N_VELOCITY_BINS - 1)


def representative_velocities() -> np.ndarray:
    """One speed per bin (m/s): the geometric mean of a log bin's edges, V_MIN / 2 for bin 0."""
    lo, hi = VELOCITY_EDGES[:-1], VELOCITY_EDGES[1:]
    return np.where(lo > 0, np.sqrt(np.maximum(lo, V_MIN) * hi), 0.5 * V_MIN)


@dataclass(frozen=True)
class EncounterRates:
    """Velocity-resolved encounter rates of a population of K size classes.

    frequency: (K, K) symmetric encounter frequency per pair (1/s per pair);
    velocity_fractions: (K, K, N_VELOCITY_BINS) fraction of each pair's encounters in each
    velocity bin (sums to 1 over the last axis, or to 0 where a pair has no data).
    The encounter frequency of pair (i, j) in bin b is frequency[i, j] * velocity_fractions[i, j, b].
    """

    frequency: np.ndarray
    velocity_fractions: np.ndarray

    def __post_init__(self):
        K = self.frequency.shape[0]
        if self.frequency.shape != (K, K):
            raise ValueError(f"encounter frequency must be (K, K), got {self.frequency.shape}")
        if self.velocity_fractions.shape != (K, K, N_VELOCITY_BINS):
            raise ValueError(
                f"velocity fractions must be ({K}, {K}, {N_VELOCITY_BINS}), got {self.velocity_fractions.shape}"
            )

    def resolved(self) -> np.ndarray:
        """(K, K, N_VELOCITY_BINS) encounter frequency per pair in each velocity bin (1/s)."""
        return self.frequency[:, :, None] * self.velocity_fractions
