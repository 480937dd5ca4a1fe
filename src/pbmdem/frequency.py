"""The collision-frequency contract shared by the DEM tables, the surrogate, the coupled loops and
the PBM kernel (docs/architecture.md).

A population of K size classes with n_k particles has pair_counts(n)[i, j] distinct particle
pairs: n_i n_j for i != j and n_i (n_i - 1) / 2 on the diagonal. A collision-frequency matrix
c (K, K) is symmetric, in 1/s per particle pair; tables list it once per unordered class pair
(class_i <= class_j, row-major upper triangle), and `matrix_from_pairs` / `pairs_of` convert
between the two forms. The bed's mean frequency per pair weights every class pair by its number
of particle pairs (`pair_weighted_mean`).
"""

from __future__ import annotations

import functools

import numpy as np

from pbmdem.impact import N_VELOCITY_BINS, WALLS, WallRates, binned_counts, velocity_bin


def upper_pairs(k: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column index (i <= j) of the K (K + 1) / 2 unordered class pairs, row-major (read-only
    arrays, made once per K: every coupling interval and prediction asks for them)."""
    return _upper_pairs(int(k))


@functools.lru_cache(maxsize=64)
def _upper_pairs(k: int) -> tuple[np.ndarray, np.ndarray]:
    iu, ju = np.triu_indices(k)
    iu.flags.writeable = ju.flags.writeable = False
    return iu, ju


def pair_counts(n) -> np.ndarray:
    """(K, K) number of distinct particle pairs: n_i n_j, and n_i (n_i - 1) / 2 on the diagonal."""
    n = np.asarray(n, float)
    pairs = np.outer(n, n)
    np.fill_diagonal(pairs, n * (n - 1) / 2.0)
    return pairs


def pairs_of(matrix) -> np.ndarray:
    """The upper-triangle entries (i <= j, row-major) of a (K, K) matrix (or (K, K, ...) array)."""
    m = np.asarray(matrix)
    return m[upper_pairs(m.shape[0])]


def matrix_from_pairs(values, k: int) -> np.ndarray:
    """The symmetric (K, K) (or (K, K, ...)) array whose upper triangle is `values`."""
    values = np.asarray(values, float)
    iu, ju = upper_pairs(k)
    out = np.empty((k, k, *values.shape[1:]))
    out[iu, ju] = values
    out[ju, iu] = values
    return out


def pair_weighted_mean(matrix, n) -> float:
    """Mean of a symmetric (K, K) per-pair frequency over all distinct particle pairs of a bed
    with n particles per class (the bed's mean frequency per pair)."""
    pairs = pairs_of(pair_counts(n))
    return float((pairs_of(matrix) * pairs).sum() / pairs.sum())


def matrix_from_table(table, k: int, column: str = "encounter_frequency_per_pair") -> np.ndarray:
    """(K, K) symmetric matrix of `column` from a table of rows (class_i, class_j, value)."""
    c = np.zeros((k, k))
    c[table["class_i"].to_numpy(int), table["class_j"].to_numpy(int)] = table[column].to_numpy(float)
    return np.triu(c) + np.triu(c, 1).T


def fractions_with_fallback(counts: np.ndarray, pooled: np.ndarray) -> np.ndarray:
    """Fractions per velocity bin from (..., V) encounter counts; a pair without encounters gets
    the `pooled` (V,) counts of all unordered pairs, normalised (uniform if they are all zero)."""
    counts = np.asarray(counts, float)
    pooled = np.asarray(pooled, float)
    fallback = pooled / pooled.sum() if pooled.sum() > 0 else np.full(counts.shape[-1], 1.0 / counts.shape[-1])
    total = counts.sum(axis=-1, keepdims=True)
    return np.where(total > 0, counts / np.where(total > 0, total, 1.0), fallback)


def velocity_fractions_from_table(velocities, k: int) -> np.ndarray:
    """(K, K, V) fraction of each class pair's encounters per impact-velocity bin, from one DEM
    run's impact_velocity.csv (rows class_i <= class_j, v_lo, v_hi, encounters; read by
    `pbmdem.impact.binned_counts`)."""
    pairs, counts = binned_counts(velocities, keys=("class_i", "class_j"))
    upper = np.zeros((k, k, N_VELOCITY_BINS))
    upper[pairs["class_i"].to_numpy(), pairs["class_j"].to_numpy()] = counts
    strictly_upper = np.triu(np.ones((k, k)), 1)[:, :, None] * upper
    return fractions_with_fallback(upper + np.transpose(strictly_upper, (1, 0, 2)), upper.sum(axis=(0, 1)))


def wall_rates_from_tables(walls, velocities, k: int):
    """:class:`pbmdem.impact.WallRates` of K classes from one DEM run's wall_collisions.csv (rows
    wall, class_i, encounter_frequency_per_particle) and wall_impact_velocity.csv (rows wall,
    class_i, v_lo, encounters); a class without wall encounters gets the wall's pooled speeds."""
    frequency = np.zeros((len(WALLS), k))
    counts = np.zeros((len(WALLS), k, N_VELOCITY_BINS))
    w = np.array([WALLS.index(x) for x in walls["wall"]], int)
    frequency[w, walls["class_i"].to_numpy(int)] = np.nan_to_num(
        walls["encounter_frequency_per_particle"].to_numpy(float)
    )
    wv = np.array([WALLS.index(x) for x in velocities["wall"]], int)
    b = velocity_bin(velocities["v_lo"].to_numpy(float))
    np.add.at(counts, (wv, velocities["class_i"].to_numpy(int), b), velocities["encounters"].to_numpy(float))
    fractions = np.stack([fractions_with_fallback(counts[i], counts[i].sum(axis=0)) for i in range(len(WALLS))])
    return WallRates(frequency, fractions)
