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

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
from scipy.special import ndtr

from pbmdem.readers import InputFileError, first_index
from pbmdem.tables import GRID_VELOCITIES

BINS_PER_DECADE = 4
V_MIN = 1.0e-3  # m/s, lower edge of the first log-spaced bin
V_MAX = 10.0  # m/s, upper edge of the last bin
VELOCITY_EDGES = np.concatenate(
    [[0.0], np.logspace(np.log10(V_MIN), np.log10(V_MAX), int(round(BINS_PER_DECADE * np.log10(V_MAX / V_MIN))) + 1)]
)
N_VELOCITY_BINS = len(VELOCITY_EDGES) - 1


def velocity_edge_bin(speed: float | None, key: str) -> int:
    """The bin whose lower edge is ``speed`` (m/s, an inner edge of :data:`VELOCITY_EDGES` to 3
    digits; None: 0, every bin); ValueError naming ``key``, the value and the allowed edges otherwise."""
    if speed is None:
        return 0
    inner = VELOCITY_EDGES[1:-1]
    match = np.flatnonzero(np.isclose(inner, float(speed), rtol=5e-3, atol=0.0))
    if match.size != 1:
        raise ValueError(
            f"{key} = {speed!r} m/s; allowed: null or an inner edge of the velocity bins (3 digits suffice), "
            f"{[float(f'{e:.4g}') for e in inner]}"
        )
    return int(match[0]) + 1


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


#: The walls a granule can hit, in the order of the DEM deck's meshes (pbmdem.dem.collisions).
WALLS = ("bowl", "impeller")


def fraction_above(speed: float) -> np.ndarray:
    """(N_VELOCITY_BINS,) fraction of each bin's impacts faster than ``speed`` (m/s).

    A bin wholly above ``speed`` counts 1, wholly below 0. In a bin that straddles it, impacts are
    taken as spread evenly in log v (the bins are log-spaced, and the measured speed distributions
    are close to log-normal, pbmdem.surrogate.velocity), so the fraction above is
    log(v_hi / speed) / log(v_hi / v_lo); in bin 0, [0, 1 mm/s), evenly in v. The last bin, which
    also holds impacts above 10 m/s, is treated as ending at 10 m/s.
    """
    s = float(speed)
    if not (np.isfinite(s) and s >= 0):
        raise ValueError(f"critical impact speed {speed!r} m/s: allowed are finite speeds >= 0")
    lo, hi = VELOCITY_EDGES[:-1], VELOCITY_EDGES[1:]
    inside = (lo < s) & (s < hi)
    out = np.where(s <= lo, 1.0, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_part = np.log(hi / s) / np.log(hi / np.where(lo > 0, lo, 1.0))
    linear_part = (hi - s) / hi
    return np.where(inside, np.where(lo > 0, log_part, linear_part), out)


def breaking_probability(speed, spread: float = 0.0) -> np.ndarray:
    """(N_VELOCITY_BINS,) mean probability that an impact of each bin breaks its granule; with an
    array of critical speeds (one per size class) one row per speed, (K, N_VELOCITY_BINS).

    The granules' dynamic yield strength Y is log-normal across granules, with median Y50 and
    standard deviation ``spread`` of ln Y; an impact at speed v breaks a granule whose St_def =
    rho v^2 / (2 Y) exceeds St_def*, i.e. whose Y is below rho v^2 / (2 St_def*), so with v* the
    critical speed of the median granule (``speed``, m/s)

        P(v) = Phi(2 ln(v / v*) / spread).

    ``spread`` = 0 is the sharp criterion, P = 1 above v* and 0 below: :func:`fraction_above`. As
    there, impacts are spread evenly in log v inside a log bin (the mean of P over the bin is then
    exact: the integral of Phi is z Phi(z) + phi(z)), evenly in v in bin 0 (64-point midpoint
    rule), and the last bin ends at 10 m/s.
    """
    s = float(spread)
    if not (np.isfinite(s) and s >= 0):
        raise ValueError(f"spread of ln Y {spread!r}: allowed are finite values >= 0")
    if s == 0.0:
        if np.ndim(speed) > 0:
            return np.stack([fraction_above(float(v)) for v in np.asarray(speed, float)])
        return fraction_above(speed)
    v_star = np.asarray(speed, float)
    if not np.all(np.isfinite(v_star) & (v_star > 0)):
        raise ValueError(f"critical impact speed {speed!r} m/s: allowed are finite speeds > 0 with a spread")
    a = 2.0 / s
    column = v_star[..., None]  # one row per critical speed, one column per bin
    lo, hi = VELOCITY_EDGES[1:-1], VELOCITY_EDGES[2:]
    z_lo, z_hi = a * np.log(lo / column), a * np.log(hi / column)

    def integral(z):  # antiderivative of Phi
        return z * ndtr(z) + np.exp(-0.5 * z * z) / np.sqrt(2.0 * np.pi)

    log_bins = (integral(z_hi) - integral(z_lo)) / (z_hi - z_lo)
    v0 = (np.arange(64) + 0.5) / 64 * VELOCITY_EDGES[1]
    first = np.mean(ndtr(a * np.log(v0 / column)), axis=-1, keepdims=True)
    return np.clip(np.concatenate([first, log_bins], axis=-1), 0.0, 1.0)


@dataclass(frozen=True)
class WallRates:
    """Velocity-resolved wall impacts of K size classes.

    frequency: (W, K) impacts per granule of each class on each wall of ``walls`` (1/s);
    velocity_fractions: (W, K, N_VELOCITY_BINS) fraction of them in each velocity bin (rows sum to
    1, or to 0 where a class has no data). Speeds are normal approach speeds relative to the wall.
    """

    frequency: np.ndarray
    velocity_fractions: np.ndarray
    walls: tuple[str, ...] = WALLS

    def __post_init__(self):
        W = len(self.walls)
        if self.frequency.ndim != 2 or self.frequency.shape[0] != W:
            raise ValueError(
                f"wall impact frequency must be ({W}, K) for walls {self.walls}, got {self.frequency.shape}"
            )
        K = self.frequency.shape[1]
        if self.velocity_fractions.shape != (W, K, N_VELOCITY_BINS):
            raise ValueError(
                f"wall velocity fractions must be ({W}, {K}, {N_VELOCITY_BINS}), got {self.velocity_fractions.shape}"
            )

    def of(self, wall: str) -> tuple[np.ndarray, np.ndarray]:
        """(K,) frequency and (K, V) fractions of one wall (KeyError naming the walls present)."""
        if wall not in self.walls:
            raise KeyError(f"wall {wall!r}: the impacts hold {list(self.walls)}")
        w = self.walls.index(wall)
        return self.frequency[w], self.velocity_fractions[w]


@dataclass(frozen=True)
class ImpactRates:
    """Every impact a granule of each class suffers: encounters with other granules (per pair)
    and impacts on the walls (per granule), each with its impact-velocity fractions. What a
    breakage selection function needs (pbmdem.pbm.impact_breakage)."""

    pairs: EncounterRates
    walls: WallRates

    def __post_init__(self):
        K = self.pairs.frequency.shape[0]
        if self.walls.frequency.shape[1] != K:
            raise ValueError(f"wall impacts of {self.walls.frequency.shape[1]} classes beside pair encounters of {K}")


#: the columns of an impact-velocity table (results/dem/impact_velocity.csv) that name one bin of one class pair
VELOCITY_KEYS = ("point_id", "class_i", "class_j")


def velocity_bins_of(v_lo, v_hi, source: str = "impact-velocity table") -> np.ndarray:
    """The bin index of every row's [v_lo, v_hi) (m/s); InputFileError naming `source`, the 1-based
    row and the bin if a row's bin is not one of VELOCITY_EDGES (edges equal to rtol 1e-6)."""
    lo, hi = np.asarray(v_lo, float), np.asarray(v_hi, float)
    b = np.clip(np.searchsorted(VELOCITY_EDGES[:-1], lo), 0, N_VELOCITY_BINS - 1)
    ok = np.isclose(VELOCITY_EDGES[b], lo, rtol=1e-6, atol=0.0) & np.isclose(
        VELOCITY_EDGES[b + 1], hi, rtol=1e-6, atol=0.0
    )
    if (k := first_index(~ok)) is not None:
        raise InputFileError(
            f"{source}: row {k + 1}, velocity bin [v_lo, v_hi) = [{lo[k]!r}, {hi[k]!r}) m/s is not one of the "
            f"project's velocity bins; allowed: consecutive edges of pbmdem.impact.VELOCITY_EDGES "
            f"{np.round(VELOCITY_EDGES, 6).tolist()}"
        )
    return b


def binned_counts(velocity: pd.DataFrame, source: str = "impact-velocity table", keys=VELOCITY_KEYS):
    """The one reading of an impact-velocity table (long: one row per class pair and bin).

    Returns ``(pairs, counts)``: a frame of the distinct `keys` of its class pairs (sorted) and their
    (pairs, N_VELOCITY_BINS) encounter counts (bins a pair does not list count 0). The columns are
    checked against the contract `pbmdem.tables.GRID_VELOCITIES` (numbers finite, encounters
    >= 0), every bin against VELOCITY_EDGES, and a bin listed twice for a pair is refused; every
    violation is an InputFileError naming `source`.
    """
    replace(GRID_VELOCITIES, what=source).check(velocity, "", need=(*keys, "v_lo", "v_hi", "encounters"))
    b = velocity_bins_of(velocity["v_lo"], velocity["v_hi"], source)
    frame = velocity.loc[:, list(keys)].astype({k: (str if k == "point_id" else int) for k in keys})
    frame = frame.assign(bin=b).reset_index(drop=True)
    if (k := first_index(frame.duplicated())) is not None:
        raise InputFileError(f"{source}: row {k + 1}, bin listed twice for {frame.iloc[k][list(keys)].to_dict()}")
    pair_index = frame.groupby(list(keys), sort=True).ngroup().to_numpy()
    counts = np.zeros((int(pair_index.max(initial=-1)) + 1, N_VELOCITY_BINS))
    counts[pair_index, b] = pd.to_numeric(velocity["encounters"]).to_numpy(float)
    pairs = frame.loc[:, list(keys)].drop_duplicates().sort_values(list(keys)).reset_index(drop=True)
    return pairs, counts
