"""Measured granule sizes over a batch (the `MEASURED` table of `pbmdem.tables`, docs/calibration.md
"The measured table"): checked for what a calibration needs beyond the columns' contract, and built
from a model's output for the check on known parameters.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.readers import InputFileError, first_index
from pbmdem.tables import MEASURED, STATISTICS


def check_measured(frame: pd.DataFrame, source, end_time: float) -> pd.DataFrame:
    """`frame` (already read against `MEASURED`) if its rows make one time series per speed within
    the batch (0 <= time <= `end_time`, times strictly ascending per speed) with d10 <= d50 <= d90;
    InputFileError naming `source`, row and column otherwise."""
    if frame.empty:
        raise InputFileError(f"measured size table {source}: no data rows; at least one (rpm, time) is required")
    times = frame.time.to_numpy(float)
    if (row := first_index(times > end_time * (1 + 1e-12))) is not None:
        raise InputFileError(
            f"measured size table {source}: row {row + 1}, column 'time' = {times[row]:g}: allowed 0 .. "
            f"{end_time:g} s (the batch of pbm.process)"
        )
    last: dict[float, float] = {}
    for row, (rpm, t) in enumerate(zip(frame.rpm.to_numpy(float), times, strict=True)):
        if rpm in last and not t > last[rpm]:
            raise InputFileError(
                f"measured size table {source}: row {row + 1}, column 'time' = {t:g}: the times of rpm {rpm:g} "
                f"must be strictly ascending (previous: {last[rpm]:g})"
            )
        last[rpm] = t
    for small, large in (("d10", "d50"), ("d50", "d90")):
        if (row := first_index(frame[small].to_numpy(float) > frame[large].to_numpy(float))) is not None:
            raise InputFileError(
                f"measured size table {source}: row {row + 1}, column {large!r} = {frame[large].iloc[row]:g}: "
                f"must be at least {small} = {frame[small].iloc[row]:g} (sizes of a cumulative distribution)"
            )
    return frame


def read_measured(path: str | Path, end_time: float) -> pd.DataFrame:
    """The measured size table at `path`, checked (`check_measured`)."""
    return check_measured(MEASURED.read(path), path, end_time)


def measured_from_series(series: dict[float, list[pd.DataFrame]], times) -> pd.DataFrame:
    """A measured table from model output: per speed the summaries of its replicates (time, d10,
    d50, d90), read at `times`; the value is the replicates' mean and the sd its standard error
    (sd over replicates / sqrt(n)); one replicate: sd 0 (the caller adds its own error)."""
    rows = []
    for rpm, summaries in sorted(series.items()):
        at = np.stack([np.column_stack([np.interp(times, s.time, s[k]) for k in STATISTICS]) for s in summaries])
        mean = at.mean(axis=0)
        n = at.shape[0]
        se = at.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros_like(mean)
        for j, t in enumerate(times):
            row = {"rpm": float(rpm), "time": float(t)}
            row.update({k: float(mean[j, i]) for i, k in enumerate(STATISTICS)})
            row.update({f"{k}_sd": float(se[j, i]) for i, k in enumerate(STATISTICS)})
            rows.append(row)
    return pd.DataFrame(rows)


def with_noise(table: pd.DataFrame, relative_sd: float, seed: int) -> pd.DataFrame:
    """`table` with Gaussian noise of sd `relative_sd` x value added to d10/d50/d90 (seeded), the
    sd columns set to that sd, and each row's sizes sorted so that d10 <= d50 <= d90 still holds."""
    rng = np.random.default_rng(seed)
    out = table.copy()
    values = out[list(STATISTICS)].to_numpy(float)
    noisy = values * (1.0 + relative_sd * rng.standard_normal(values.shape))
    out[list(STATISTICS)] = np.sort(noisy, axis=1)
    for i, k in enumerate(STATISTICS):
        out[f"{k}_sd"] = relative_sd * values[:, i]
    return out
