"""Hand-made grid tables of the DEM stage for tests: pair, wall and impact-velocity tables with the
columns the DEM writes (pbmdem.tables), for points named `rpm<rpm>_<distribution>`."""

from __future__ import annotations

import pandas as pd

from pbmdem.impact import N_VELOCITY_BINS, VELOCITY_EDGES

WALLS = ("bowl", "impeller")


def point(rpm: float, distribution: str) -> dict:
    """The columns that name a grid point."""
    return {"point_id": f"rpm{rpm:g}_{distribution}", "rpm": rpm, "distribution": distribution}


def pair_table(d, frequency, rpms, distribution="fine", **columns) -> pd.DataFrame:
    """One row per speed and class pair a <= b of the classes of diameters `d`, with
    `encounter_frequency_per_pair` = frequency(rpm, a, b) and the constant `columns`."""
    n = len(d)
    return pd.DataFrame(
        {
            **point(rpm, distribution),
            "class_i": a,
            "class_j": b,
            "d_i": d[a],
            "d_j": d[b],
            **columns,
            "encounter_frequency_per_pair": frequency(rpm, a, b),
        }
        for rpm in rpms
        for a in range(n)
        for b in range(a, n)
    )


def wall_table(d, frequency, rpms, distribution="fine") -> pd.DataFrame:
    """One row per speed, wall and class, with `encounter_frequency_per_particle` =
    frequency(rpm, wall, class)."""
    return pd.DataFrame(
        {**point(rpm, distribution), "wall": wall, "class_i": c, "d_i": d[c]}
        | {"encounter_frequency_per_particle": frequency(rpm, wall, c)}
        for rpm in rpms
        for wall in WALLS
        for c in range(len(d))
    )


def binned(counts, every_bin=True) -> pd.DataFrame:
    """An impact-velocity table: for each (columns, {bin: encounters}) of `counts` one row per
    velocity bin (every bin, the uncounted ones with 0 encounters, or only the counted ones)."""
    return pd.DataFrame(
        {**keys, "v_lo": VELOCITY_EDGES[b], "v_hi": VELOCITY_EDGES[b + 1], "encounters": per_bin.get(b, 0.0)}
        for keys, per_bin in counts
        for b in (range(N_VELOCITY_BINS) if every_bin else per_bin)
    )


def pair_velocity_table(counts, distribution="fine", every_bin=True) -> pd.DataFrame:
    """The pair impact-velocity table of `counts`: {(rpm, a, b): {bin: encounters}}."""
    keys = [
        ({**point(rpm, distribution), "class_i": a, "class_j": b}, per_bin) for (rpm, a, b), per_bin in counts.items()
    ]
    return binned(keys, every_bin)


def wall_velocity_table(counts, distribution="fine", every_bin=True) -> pd.DataFrame:
    """The wall impact-velocity table of `counts`: {(rpm, wall, class): {bin: encounters}}."""
    keys = [
        ({**point(rpm, distribution), "wall": wall, "class_i": c}, per_bin)
        for (rpm, wall, c), per_bin in counts.items()
    ]
    return binned(keys, every_bin)
