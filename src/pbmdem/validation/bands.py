"""The PBM-DEM reference band (the replicates' envelope at every time) and a model's distance
outside it (docs/validation.md, "The reference is a band").
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pbmdem.tables import STATISTICS


def _on_times(summary: pd.DataFrame, column: str, times: np.ndarray) -> np.ndarray:
    return np.interp(times, summary["time"].to_numpy(float), summary[column].to_numpy(float))


def band_table(
    dem: list[pd.DataFrame],
    ann: pd.DataFrame,
    members: pd.DataFrame | None = None,
    constant: pd.DataFrame | None = None,
) -> pd.DataFrame:
    """The bands.csv of a speed (docs/architecture.md, "Validation results"): one row per statistic
    and recorded time of the first PBM-DEM replicate. Sizes in m."""
    if not dem:
        raise ValueError("no PBM-DEM replicate to form a band")
    times = dem[0]["time"].to_numpy(float)
    for k, s in enumerate(dem[1:], 1):
        t = s["time"].to_numpy(float)
        if t.shape != times.shape or not np.allclose(t, times, rtol=0, atol=1e-9 * max(1.0, times.max())):
            raise ValueError(
                f"PBM-DEM replicate {k} records other times than replicate 0; the loops of one "
                "speed must share their output times"
            )
    rows = []
    for stat in STATISTICS:
        values = np.stack([s[stat].to_numpy(float) for s in dem])
        n = values.shape[0]
        frame = pd.DataFrame(
            {
                "statistic": stat,
                "time": times,
                "n_dem_replicates": n,
                "dem_mean": values.mean(axis=0),
                "dem_sd": values.std(axis=0, ddof=1) if n > 1 else np.full(times.size, np.nan),
                "dem_min": values.min(axis=0),
                "dem_max": values.max(axis=0),
                "ann": _on_times(ann, stat, times),
            }
        )
        ok = finished_members(members)
        if ok is not None and len(ok):
            per = np.stack([_on_times(g, stat, times) for _, g in ok.groupby("member")])
            frame["ann_member_min"], frame["ann_member_max"] = per.min(axis=0), per.max(axis=0)
        if constant is not None:
            frame["constant"] = _on_times(constant, stat, times)
        frame["ann_outside"] = outside(frame, "ann")
        rows.append(frame)
    return pd.concat(rows, ignore_index=True)


def finished_members(members: pd.DataFrame | None) -> pd.DataFrame | None:
    """The rows of the ensemble members whose PBM finished (members.csv: `failed` empty)."""
    if members is None or "failed" not in members:
        return members
    failed = members["failed"].fillna("").astype(str) != ""
    return members[~failed & members["time"].notna()]


def outside(band: pd.DataFrame, column: str) -> np.ndarray:
    """Distance of `band[column]` outside [dem_min, dem_max], as a fraction of dem_mean (0 inside)."""
    value = band[column].to_numpy(float)
    lo, hi, mean = (band[c].to_numpy(float) for c in ("dem_min", "dem_max", "dem_mean"))
    return np.maximum(0.0, np.maximum(lo - value, value - hi)) / mean


def largest_outside(band: pd.DataFrame, column: str = "ann", statistic: str = "d50") -> float:
    """The largest distance of `column`'s `statistic` outside the band over the batch (fraction)."""
    rows = band[band["statistic"] == statistic]
    return float(outside(rows, column).max()) if len(rows) else float("nan")
