"""The comparison table: PBM-ANN and PBM-constant against the replicated PBM-DEM reference, one row
per validation speed (`results/report/comparison.csv`, contract `pbmdem.tables.COMPARISON`; its
columns: docs/validation.md, "Comparison").
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .bands import band_table, finished_members, largest_outside
from .results import SpeedResults, load_speed


def relative_error(reference: pd.DataFrame, other: pd.DataFrame, column: str = "d50") -> tuple[float, float]:
    """(max over time, at the end) of |other - reference| / reference on the reference's times."""
    values = np.interp(reference.time, other.time, other[column])
    err = np.abs(values - reference[column].to_numpy()) / reference[column].to_numpy()
    return float(err.max()), float(err[-1])


def replicate_spread(dem: list[pd.DataFrame], column: str = "d50") -> float:
    """The reference's own yardstick: the largest relative error over time of one replicate's d50
    against the mean of the others (NaN for fewer than two replicates)."""
    if len(dem) < 2:
        return float("nan")
    times = dem[0].time.to_numpy(float)
    values = np.array([np.interp(times, r.time, r[column]) for r in dem])
    worst = 0.0
    for k in range(len(dem)):
        others = np.delete(values, k, axis=0).mean(axis=0)
        worst = max(worst, float(np.max(np.abs(values[k] - others) / others)))
    return worst


def bands_of(speed: SpeedResults) -> pd.DataFrame:
    return band_table([r.summary for r in speed.dem], speed.ann.summary, speed.members, speed.constant.summary)


def domain_counts(speed: SpeedResults) -> dict:
    """PBM-ANN's intervals with out-of-domain warnings and the constant kernel's calibration warnings."""
    ann = speed.ann.intervals
    counts = ann["out_of_domain_count"].fillna(0) if ann is not None and "out_of_domain_count" in ann else None
    return {
        "ann_out_of_domain_intervals": int((counts > 0).sum()) if counts is not None else float("nan"),
        "ann_intervals": int(len(ann)) if ann is not None else 0,
        "ann_out_of_domain_warnings": int(counts.sum()) if counts is not None else float("nan"),
        "constant_calibration_out_of_domain_warnings": speed.constant.timing.get("out_of_domain_count", float("nan")),
    }


def merged_fraction(timing: dict) -> float:
    """The share of a run's final number of granules merged at the grid floor; NaN when not recorded."""
    return float(timing.get("grid_floor", {}).get("merged_fraction", float("nan")))


def floor_columns(speed: SpeedResults) -> dict:
    """The grid floor of every model at this speed (of PBM-DEM, the largest over the replicates)."""
    dem = [merged_fraction(r.timing) for r in speed.dem]
    return {
        "dem_merged_fraction_max": max(dem) if dem and not np.isnan(dem).any() else float("nan"),
        "ann_merged_fraction": merged_fraction(speed.ann.timing),
        "constant_merged_fraction": merged_fraction(speed.constant.timing),
    }


def comparison_row(speed: SpeedResults, in_grid: bool) -> dict:
    band = bands_of(speed)
    mean = band.pivot(index="time", columns="statistic", values="dem_mean").reset_index()
    ann, con = speed.ann.summary, speed.constant.summary
    ann_max, ann_end = relative_error(mean, ann)
    con_max, con_end = relative_error(mean, con)
    ends = np.array([r.summary.d50.iloc[-1] for r in speed.dem])
    tails = {}  # the tails: breakage moves d10 first, aggregation d90
    for q in ("d10", "d90"):
        values = np.array([r.summary[q].iloc[-1] for r in speed.dem])
        tails |= {
            f"{q}_end_dem_mm": 1e3 * values.mean(),
            f"{q}_end_dem_min_mm": 1e3 * values.min(),
            f"{q}_end_dem_max_mm": 1e3 * values.max(),
            f"{q}_end_ann_mm": 1e3 * ann[q].iloc[-1],
            f"ann_{q}_outside_band_max": largest_outside(band, "ann", q),
        }
    dem_wall = np.array([r.timing["total_wall_time_s"] for r in speed.dem])
    dem_liggghts = np.array([r.timing["provider_wall_time_s"] for r in speed.dem])
    nan = float("nan")
    dem_cpu = np.array([r.timing.get("dem_cpu_time_s", nan) + r.timing.get("pbm_cpu_time_s", nan) for r in speed.dem])
    timing = speed.ann.timing
    t_first = float(timing["total_wall_time_s"])
    t_ann = float(timing.get("warm_wall_time_s_median", nan))
    cpu_ann = float(timing.get("warm_cpu_time_s_median", nan))
    row = {
        "rpm": float(speed.rpm),
        "in_training_grid": bool(in_grid),
        "n_dem_replicates": len(speed.dem),
        "d50_start_mm": 1e3 * mean.d50.iloc[0],
        "d50_end_dem_mm": 1e3 * ends.mean(),
        "d50_end_dem_sd_mm": 1e3 * ends.std(ddof=1) if len(ends) > 1 else float("nan"),
        "d50_end_dem_min_mm": 1e3 * ends.min(),
        "d50_end_dem_max_mm": 1e3 * ends.max(),
        "d50_end_ann_mm": 1e3 * ann.d50.iloc[-1],
        "d50_end_constant_mm": 1e3 * con.d50.iloc[-1],
        **tails,
        "ann_d50_rel_error_max": ann_max,
        "ann_d50_rel_error_end": ann_end,
        "ann_d50_outside_band_max": largest_outside(band, "ann", "d50"),
        "dem_replicate_d50_rel_error_max": replicate_spread([r.summary for r in speed.dem]),
        "constant_d50_rel_error_max": con_max,
        "constant_d50_rel_error_end": con_end,
        "constant_d50_outside_band_max": largest_outside(band, "constant", "d50"),
        "dem_calls": int(len(speed.dem[0].intervals)) if speed.dem[0].intervals is not None else 0,
        "pbm_dem_wall_s": float(dem_wall.mean()),
        "pbm_dem_cpu_s": float(dem_cpu.mean()),
        "pbm_dem_liggghts_wall_s": float(dem_liggghts.mean()),
        "pbm_ann_wall_s": t_ann,
        "pbm_ann_cpu_s": cpu_ann,
        "pbm_ann_first_batch_wall_s": t_first,
        "pbm_ann_surrogate_wall_s": float(timing["provider_wall_time_s"]),
        "pbm_ann_pbm_wall_s": float(timing["pbm_wall_time_s"]),
        "pbm_constant_wall_s": float(speed.constant.timing["total_wall_time_s"]),
        "wall_time_ratio_dem_over_ann": float(dem_wall.mean()) / t_ann if t_ann > 0 else nan,
        "cpu_time_ratio_dem_over_ann": float(dem_cpu.mean()) / cpu_ann if cpu_ann > 0 else nan,
        **domain_counts(speed),
        **floor_columns(speed),
    }
    if speed.members is not None and len(speed.members):
        ok = finished_members(speed.members)
        row["ann_members"] = int(speed.members.member.nunique())
        row["ann_members_failed"] = row["ann_members"] - int(ok.member.nunique())
        if len(ok):
            last = ok[ok.time == ok.time.max()]
            row["ann_member_d50_end_min_mm"] = 1e3 * last.d50.min()
            row["ann_member_d50_end_max_mm"] = 1e3 * last.d50.max()
    return row


def compare(validation_dir: str | Path, rpms, grid_rpm, replicates: int) -> pd.DataFrame:
    """The comparison table of every validation speed (`rpms` as in the result folders)."""
    grid = {float(r) for r in grid_rpm}
    return pd.DataFrame(
        [comparison_row(load_speed(validation_dir, rpm, replicates), float(rpm) in grid) for rpm in rpms]
    )
