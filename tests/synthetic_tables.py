"""Synthetic collision and impact-velocity tables with known laws, for tests and benchmarks.

Both tables follow the contract of docs/architecture.md ("Collision tables"): every run
(rpm x distribution) is replicated ``n_replicates`` times; the encounter frequency per pair of a
replicate is the known law times log-normal replicate noise, the table holds the mean over
replicates and its standard error; the impact speeds of a pair follow a known log-normal law
(:func:`velocity_law`), binned on :data:`pbmdem.impact.VELOCITY_EDGES` (expected counts, or
multinomial samples of each replicate's encounters with ``sample_velocities``).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from pbmdem.impact import VELOCITY_EDGES
from pbmdem.surrogate.features import tip_speed
from pbmdem.surrogate.velocity import speed_fractions
from pbmdem.tables import GRID_PAIRS

#: Columns of the synthetic collision tables: the contract's (pbmdem.tables.GRID_PAIRS) but frequency_per_pair_se.
TABLE_COLUMNS = tuple(c.name for c in GRID_PAIRS.columns if c.name != "frequency_per_pair_se")

#: Raw new contacts per encounter in the synthetic tables (re-contacts of a pair that bounces).
CONTACTS_PER_ENCOUNTER = 1.6


def power_law(d_i, d_j, rpm, n_total, c0: float = 1e-3):
    """Smooth reference law (1/s per pair): c0 ((d_i + d_j)/6 mm)^2 (rpm/600) (2000/n_total)."""
    d_i, d_j = np.asarray(d_i, float), np.asarray(d_j, float)
    return c0 * ((d_i + d_j) / 0.006) ** 2 * (np.asarray(rpm, float) / 600.0) * (2000.0 / np.asarray(n_total, float))


def velocity_law(d_i, d_j, rpm, impeller_radius: float):
    """Reference impact-speed law: ``(mu, sigma)`` of log10 v (m/s, decades).

    median = 0.12 v_tip (d_small / d_large)^0.5 (unequal pairs meet more gently in this toy law),
    sigma = 0.30 (600 / rpm)^0.25 decades (a slower impeller gives a broader spread); v_tip is the
    tip speed of an impeller of radius ``impeller_radius`` (m).
    """
    d_i, d_j = np.asarray(d_i, float), np.asarray(d_j, float)
    rpm = np.asarray(rpm, float)
    v_tip = tip_speed(rpm, impeller_radius)
    ratio = np.minimum(d_i, d_j) / np.maximum(d_i, d_j)
    mu = np.log10(0.12 * v_tip * ratio**0.5)
    sigma = 0.30 * (600.0 / rpm) ** 0.25
    return mu, sigma


def make_synthetic_tables(
    impeller_radius: float,
    rpms=(300, 450, 600, 750, 900),
    distributions: dict | None = None,
    diameters=(0.002, 0.003, 0.004),
    n_total_range=(1200, 3500),
    noise_log10: float = 0.03,
    run_noise_log10: float = 0.0,
    sampling_time: float = 0.2,
    law=power_law,
    n_replicates: int = 3,
    vlaw=velocity_law,
    sample_velocities: bool = False,
    seed: int = 0,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """``(collisions, impact_velocity)`` tables for every rpm x distribution.

    ``impeller_radius`` (m) sets the tip speed of the velocity law (``vlaw(d_i, d_j, rpm,
    impeller_radius)``); train on the tables with the same radius.

    ``distributions`` maps names to number fractions over ``diameters``; by default a handful of
    random ones. ``n_total`` of a distribution decreases with its mean size (fixed bed volume).
    Replicate r of a row has encounter_frequency_per_pair = law x 10**N(0, noise_log10) x (run
    factor 10**N(0, run_noise_log10), shared by the replicates of a run); the table holds the mean
    over replicates and its standard error (NaN for one replicate). ``collisions`` (raw new
    contacts) are :data:`CONTACTS_PER_ENCOUNTER` times the encounters.

    Longer than 80 lines: the two tables are written row by row in one pass over runs, pairs and
    replicates, so that a row of the collision table and its velocity bins share their random
    draws in a fixed order (same seed, same tables).
    """
    rng = np.random.default_rng(seed)
    if int(n_replicates) < 1:
        raise ValueError(f"n_replicates must be >= 1, got {n_replicates!r}")
    R = int(n_replicates)
    d = np.asarray(diameters, dtype=float)
    if distributions is None:
        distributions = {f"dist{k}": rng.dirichlet(np.full(d.size, 2.0)) for k in range(4)}
    lo, hi = n_total_range
    d3 = {name: float(np.dot(np.asarray(f, float), d**3)) for name, f in distributions.items()}
    d3_lo, d3_hi = min(d3.values()), max(d3.values())
    rows, vrows = [], []
    v_lo, v_hi = VELOCITY_EDGES[:-1], VELOCITY_EDGES[1:]
    for rpm in rpms:
        for name, fractions in distributions.items():
            f = np.asarray(fractions, float) / np.sum(fractions)
            # fixed bed volume: more particles for a finer distribution
            t = 0.5 if d3_hi == d3_lo else (d3[name] - d3_lo) / (d3_hi - d3_lo)
            n_total = int(round(hi - t * (hi - lo)))
            n = np.floor(f * n_total).astype(int)
            n[0] += n_total - n.sum()
            run_factor = 10.0 ** rng.normal(0.0, run_noise_log10) if run_noise_log10 else 1.0
            pid = f"rpm{rpm:g}_{name}"
            for i in range(d.size):
                for j in range(i, d.size):
                    pairs = n[i] * (n[i] - 1) / 2 if i == j else n[i] * n[j]
                    reps = float(law(d[i], d[j], rpm, n_total)) * run_factor * 10.0 ** rng.normal(0.0, noise_log10, R)
                    efpp = float(reps.mean()) if pairs > 0 else np.nan
                    se = float(reps.std(ddof=1) / math.sqrt(R)) if (R > 1 and pairs > 0) else np.nan
                    encounters = efpp * pairs * sampling_time if pairs > 0 else 0.0
                    mu, sigma = vlaw(d[i], d[j], rpm, impeller_radius)
                    frac = speed_fractions(mu, sigma, "lognormal")[0]
                    if sample_velocities and pairs > 0:
                        counts = np.mean(
                            [rng.multinomial(int(round(r * pairs * sampling_time)), frac) for r in reps], axis=0
                        )
                    else:
                        counts = encounters * frac
                    if counts.sum() > 0:
                        cdf = np.cumsum(counts) / counts.sum()
                        b = int(np.searchsorted(cdf, 0.5))
                        median = float(np.sqrt(max(v_lo[b], VELOCITY_EDGES[1]) * v_hi[b]))
                    else:
                        median = np.nan
                    collisions = CONTACTS_PER_ENCOUNTER * encounters
                    rows.append(
                        {
                            "point_id": pid,
                            "rpm": rpm,
                            "distribution": name,
                            "class_i": i,
                            "class_j": j,
                            "d_i": d[i],
                            "d_j": d[j],
                            "n_i": int(n[i]),
                            "n_j": int(n[j]),
                            "n_total": n_total,
                            "collisions": collisions,
                            "sampling_time": sampling_time,
                            "frequency": collisions / sampling_time,
                            "frequency_per_pair": collisions / (pairs * sampling_time) if pairs > 0 else np.nan,
                            "n_replicates": R,
                            "encounters": encounters,
                            "encounter_frequency_per_pair": efpp,
                            "encounter_frequency_per_pair_se": se,
                            "impact_velocity_median": median,
                        }
                    )
                    for b in range(len(counts)):
                        vrows.append(
                            {
                                "point_id": pid,
                                "rpm": rpm,
                                "distribution": name,
                                "class_i": i,
                                "class_j": j,
                                "v_lo": v_lo[b],
                                "v_hi": v_hi[b],
                                "encounters": counts[b],
                            }
                        )
    return (pd.DataFrame(rows, columns=list(TABLE_COLUMNS)), pd.DataFrame(vrows))


def make_synthetic_table(impeller_radius: float, *args, **kwargs) -> pd.DataFrame:
    """The collision table of :func:`make_synthetic_tables` (same arguments)."""
    return make_synthetic_tables(impeller_radius, *args, **kwargs)[0]


#: Reference wall laws of the synthetic wall tables: wall -> (impacts per granule and second at
#: d = 3 mm and 600 rpm, median impact speed / tip speed); rate ~ d^2 rpm, spread 0.3 decades.
WALL_LAWS = {"bowl": (5.0, 0.15), "impeller": (2.0, 0.5)}


def wall_law(wall: str, d, rpm, impeller_radius: float):
    """``(rate, mu, sigma)`` of the synthetic wall table: impacts per granule (1/s), log10 of the
    median impact speed (m/s) and the spread of log10 v (decades)."""
    rate0, speed = WALL_LAWS[wall]
    d, rpm = np.asarray(d, float), np.asarray(rpm, float)
    return rate0 * (d / 0.003) ** 2 * rpm / 600.0, np.log10(speed * tip_speed(rpm, impeller_radius)), 0.3


def make_synthetic_wall_tables(collisions: pd.DataFrame, impeller_radius: float, seed: int = 0):
    """``(wall_collisions, wall_impact_velocity)`` grid tables of the runs and classes of a synthetic
    collision table (:func:`make_synthetic_tables`), following :func:`wall_law` with 3 % log noise."""
    rng = np.random.default_rng(seed)
    classes = collisions[collisions["class_i"] == collisions["class_j"]]
    rows, vrows = [], []
    for wall in WALL_LAWS:
        for r in classes.itertuples():
            rate, mu, sigma = wall_law(wall, r.d_i, r.rpm, impeller_radius)
            rate = float(rate) * 10.0 ** rng.normal(0.0, 0.03)
            encounters = rate * r.n_i * r.sampling_time
            key = {"point_id": r.point_id, "rpm": r.rpm, "distribution": r.distribution, "class_i": r.class_i}
            rows.append(
                key
                | {
                    "d_i": r.d_i,
                    "n_i": r.n_i,
                    "n_total": r.n_total,
                    "wall": wall,
                    "collisions": CONTACTS_PER_ENCOUNTER * encounters,
                    "sampling_time": r.sampling_time,
                    "frequency": CONTACTS_PER_ENCOUNTER * encounters / r.sampling_time,
                    "frequency_per_particle": CONTACTS_PER_ENCOUNTER * rate,
                    "encounters": encounters,
                    "encounter_frequency_per_particle": rate,
                    "impact_velocity_median": 10.0**mu,
                    "n_replicates": r.n_replicates,
                    "encounter_frequency_per_particle_se": 0.03 * rate,
                }
            )
            counts = encounters * speed_fractions(mu, sigma, "lognormal")[0]
            for b, n in enumerate(counts):
                vrows.append(
                    key | {"wall": wall, "v_lo": VELOCITY_EDGES[b], "v_hi": VELOCITY_EDGES[b + 1], "encounters": n}
                )
    return pd.DataFrame(rows), pd.DataFrame(vrows)
