"""The DEM's wall impacts as a source for breakage (:class:`WallTable`): per wall (bowl, impeller)
the encounters per granule and second of each size class (results/dem/wall_collisions.csv) and
their impact-speed distribution (wall_impact_velocity.csv), interpolated onto any diameters and
speed the way :class:`~pbmdem.pbm.table.TableFrequency` interpolates the pair table (log f linear
in log d, clamped; zero frequencies floored at ``zero_floor`` x the smallest positive one)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pbmdem.frequency import fractions_with_fallback
from pbmdem.impact import N_VELOCITY_BINS, WALLS, WallRates, velocity_bins_of
from pbmdem.readers import InputFileError, first_index
from pbmdem.tables import GRID_WALL_VELOCITIES, GRID_WALLS

from .errors import PBMInputError
from .table import read_grid_table, speed_weights

#: Column of the wall table the breakage selection is built on (impacts of granules that were apart).
WALL_FREQUENCY_COLUMN = "encounter_frequency_per_particle"


class WallTable:
    """Wall impacts per granule interpolated from the DEM's wall tables.

    ``walls``: the grid wall-collision table (columns rpm, wall, class_i, d_i, point_id and
    ``encounter_frequency_per_particle``); ``velocities``: the wall impact-velocity table (point_id,
    wall, class_i, v_lo, v_hi, encounters). A class with wall encounters but no velocity counts
    is refused (the tables come from different runs)."""

    def __init__(self, walls: pd.DataFrame, velocities: pd.DataFrame, zero_floor: float = 1e-3):
        self.zero_floor = float(zero_floor)
        need = ["point_id", "rpm", "wall", "class_i", "d_i", WALL_FREQUENCY_COLUMN]
        missing = [c for c in need if c not in walls.columns]
        missing += [
            c for c in ("point_id", "wall", "class_i", "v_lo", "v_hi", "encounters") if c not in velocities.columns
        ]
        if missing:
            raise PBMInputError(f"wall tables lack columns {missing}")
        t = walls[walls["wall"].isin(WALLS)].copy()
        if t.empty:
            raise PBMInputError(f"wall-collision table has no rows for the walls {list(WALLS)}")
        f = t[WALL_FREQUENCY_COLUMN].to_numpy(float)
        if not np.all(np.isfinite(f) & (f >= 0)) or not (f > 0).any():
            raise PBMInputError(f"wall-collision table {WALL_FREQUENCY_COLUMN}: allowed finite values >= 0, one > 0")
        floor = self.zero_floor * f[f > 0].min()
        t["log_f"] = np.log(np.maximum(f, floor))
        t = t.join(self._counts(t, velocities))
        self.rpms = np.array(sorted(t["rpm"].astype(float).unique()))
        self._grids = [self._speed_grid(g) for _, g in t.groupby("rpm", sort=True)]

    @staticmethod
    def _counts(t: pd.DataFrame, velocities: pd.DataFrame) -> pd.DataFrame:
        """(rows of t, V) wall encounters per velocity bin, as columns 0..V-1 on t's index."""
        v = velocities[velocities["point_id"].astype(str).isin(set(t["point_id"].astype(str)))]
        try:
            b = velocity_bins_of(v["v_lo"], v["v_hi"], "wall impact-velocity table")
        except InputFileError as exc:
            raise PBMInputError(str(exc)) from None
        keys = ["point_id", "wall", "class_i"]
        wide = (
            v.assign(bin=b, point_id=v["point_id"].astype(str), class_i=v["class_i"].astype(int))
            .pivot_table(index=keys, columns="bin", values="encounters", aggfunc="sum", fill_value=0.0)
            .reindex(columns=range(N_VELOCITY_BINS), fill_value=0.0)
        )
        index = pd.MultiIndex.from_arrays([t["point_id"].astype(str), t["wall"], t["class_i"].astype(int)], names=keys)
        counts = wide.reindex(index).to_numpy(float)
        lacking = (t[WALL_FREQUENCY_COLUMN].to_numpy(float) > 0) & ~(np.nan_to_num(counts).sum(axis=1) > 0)
        if (k := first_index(lacking)) is not None:
            raise PBMInputError(
                f"wall-collision table: {tuple(index[k])} has wall encounters but no row in the wall "
                "impact-velocity table; both tables must come from the same DEM runs"
            )
        return pd.DataFrame(np.nan_to_num(counts), index=t.index)

    @staticmethod
    def _speed_grid(g: pd.DataFrame) -> dict:
        """Per wall: table log d, log f and fractions (n, V) of one speed's rows."""
        out = {}
        for wall in WALLS:
            rows = g[g["wall"] == wall]
            if rows.empty:
                raise PBMInputError(f"wall-collision table at rpm {g['rpm'].iloc[0]:g}: no rows for the {wall}")
            pooled = rows.groupby("d_i", sort=True)
            counts = pooled[list(range(N_VELOCITY_BINS))].sum().to_numpy(float)
            fractions = fractions_with_fallback(counts, counts.sum(axis=0))
            out[wall] = (np.log(pooled.size().index.to_numpy(float)), pooled["log_f"].mean().to_numpy(), fractions)
        return out

    @classmethod
    def from_csv(cls, path, velocity_path, distribution: str | None = None) -> WallTable:
        """The grid's wall tables (results/dem/wall_collisions.csv, wall_impact_velocity.csv), read
        through their contracts; ``distribution`` keeps only that distribution's rows."""
        walls = read_grid_table(path, GRID_WALLS, distribution)
        velocities = read_grid_table(velocity_path, GRID_WALL_VELOCITIES, distribution)
        try:
            return cls(walls, velocities)
        except PBMInputError as err:
            raise PBMInputError(f"{path} / {velocity_path}: {err}") from None

    def __repr__(self) -> str:
        return f"WallTable(rpm=[{','.join(f'{r:g}' for r in self.rpms)}])"

    def rates(self, diameters, rpm) -> WallRates:
        """:class:`pbmdem.impact.WallRates` of classes of these diameters (m) at ``rpm``."""
        ld = np.log(np.atleast_1d(np.asarray(diameters, float)))
        log_f = np.zeros((len(WALLS), ld.size))
        fractions = np.zeros((len(WALLS), ld.size, N_VELOCITY_BINS))
        for k, w in speed_weights(self.rpms, rpm):
            for i, wall in enumerate(WALLS):
                lx, lf, fr = self._grids[k][wall]
                x = np.clip(ld, lx[0], lx[-1])
                log_f[i] += w * np.interp(x, lx, lf)
                fractions[i] += w * np.stack([np.interp(x, lx, fr[:, b]) for b in range(N_VELOCITY_BINS)], axis=1)
        return WallRates(np.exp(log_f), fractions / fractions.sum(axis=2, keepdims=True))
