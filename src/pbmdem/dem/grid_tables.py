"""The grid's tables: per-run tables of every point and replicate stacked, and their replicate
means with standard errors (docs/architecture.md, "Collision tables")."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.atomic import write_csv
from pbmdem.readers import read_json
from pbmdem.tables import KEYS, RUN_TABLES, SE_COLUMNS


def replicate_mean(frame: pd.DataFrame, keys: list[str]) -> pd.DataFrame:
    """Mean over the replicates of every column but `keys`, with `n_replicates` and the standard
    error `<column>_se` (sample sd / sqrt(n), NaN for one replicate) of the SE_COLUMNS."""
    values = [c for c in frame.columns if c not in keys and c != "replicate"]
    grouped = frame.groupby(keys, sort=True, dropna=False)
    out = grouped[values].mean()
    out["n_replicates"] = grouped["replicate"].nunique()
    for col in SE_COLUMNS:
        if col in values:
            out[f"{col}_se"] = grouped[col].std(ddof=1) / np.sqrt(out["n_replicates"])
    out = out.reset_index()
    first = [c for c in frame.columns if c in out.columns]
    return out[first + [c for c in out.columns if c not in first]]


def read_tables(tables: list[str | Path], kind: str = "pairs") -> pd.DataFrame:
    """The per-run tables of `kind` (pairs, walls or velocities) stacked into one frame (every
    replicate a row of its own), each checked against its contract (pbmdem.tables)."""
    frames = [RUN_TABLES[kind].read(p) for p in tables]
    if not frames:
        raise ValueError("no collision tables to aggregate")
    return _sorted(pd.concat(frames, ignore_index=True))


def _sorted(frame: pd.DataFrame) -> pd.DataFrame:
    sort = [c for c in ("rpm", "distribution", "replicate", "wall", "class_i", "class_j", "v_lo") if c in frame.columns]
    return frame.sort_values(sort, kind="stable").reset_index(drop=True)


def aggregate(tables: list[str | Path], out: str | Path, kind: str = "pairs") -> pd.DataFrame:
    """Replicate means of per-run tables (`kind`: pairs, walls or velocities), one row per point
    and class pair (or wall, or velocity bin), sorted and written atomically."""
    grid = _sorted(replicate_mean(read_tables(tables, kind), list(KEYS[kind])))
    write_csv(out, grid)
    return grid


def run_table(summaries: list[str | Path], out: str | Path):
    """One row per run with its size, cost and convergence figures (atomically written CSV)."""
    rows = [read_json(p, "DEM run summary") for p in summaries]
    frame = pd.DataFrame(rows).drop(columns="particles_per_class", errors="ignore")
    frame = frame.sort_values(["rpm", "distribution"]).reset_index(drop=True)
    write_csv(out, frame)
    return frame
