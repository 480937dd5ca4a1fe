"""Synthetic collision tables with a known law, for tests and benchmarks of the surrogate."""

from __future__ import annotations

import numpy as np
import pandas as pd

from .features import TABLE_COLUMNS


def power_law(d_i, d_j, rpm, n_total, c0: float = 1e-3):
    """Smooth reference law (1/s per pair): c0 ((d_i + d_j)/6 mm)^2 (rpm/600) (2000/n_total)."""
    d_i, d_j = np.asarray(d_i, float), np.asarray(d_j, float)
    return c0 * ((d_i + d_j) / 0.006) ** 2 * (np.asarray(rpm, float) / 600.0) * (2000.0 / np.asarray(n_total, float))


def make_synthetic_table(
    rpms=(300, 450, 600, 750, 900),
    distributions: dict | None = None,
    diameters=(0.002, 0.003, 0.004),
    n_total_range=(1200, 3500),
    noise_log10: float = 0.03,
    run_noise_log10: float = 0.0,
    sampling_time: float = 0.2,
    law=power_law,
    seed: int = 0,
) -> pd.DataFrame:
    """A collision table (contract columns) for every rpm x distribution.

    ``distributions`` maps names to number fractions over ``diameters``; by default a handful of
    random ones. ``n_total`` of a distribution decreases with its mean size (fixed bed volume).
    frequency_per_pair = law x 10**N(0, noise_log10) per row x 10**N(0, run_noise_log10) per run.
    """
    rng = np.random.default_rng(seed)
    d = np.asarray(diameters, dtype=float)
    if distributions is None:
        distributions = {f"dist{k}": rng.dirichlet(np.full(d.size, 2.0)) for k in range(4)}
    lo, hi = n_total_range
    d3 = {name: float(np.dot(np.asarray(f, float), d ** 3)) for name, f in distributions.items()}
    d3_lo, d3_hi = min(d3.values()), max(d3.values())
    rows = []
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
                    fpp = float(law(d[i], d[j], rpm, n_total)) * run_factor * 10.0 ** rng.normal(0.0, noise_log10)
                    collisions = fpp * pairs * sampling_time
                    rows.append({
                        "point_id": pid, "rpm": rpm, "distribution": name, "class_i": i, "class_j": j,
                        "d_i": d[i], "d_j": d[j], "n_i": int(n[i]), "n_j": int(n[j]), "n_total": n_total,
                        "collisions": collisions, "sampling_time": sampling_time,
                        "frequency": collisions / sampling_time,
                        "frequency_per_pair": collisions / (pairs * sampling_time) if pairs > 0 else np.nan,
                    })
    return pd.DataFrame(rows, columns=list(TABLE_COLUMNS))
