"""The contracts of the tables pbmdem passes between its stages, and their one reader.

One owner per table: each `Table` below declares its columns (type, sign, where an empty cell is
allowed) and `read(path)` checks a file against it; every stage reads these tables through it.

* `RUN_PAIRS`, `RUN_WALLS`, `RUN_VELOCITIES`, `RUN_WALL_VELOCITIES`: one DEM run's collisions.csv,
  wall_collisions.csv, impact_velocity.csv, wall_impact_velocity.csv (results/dem/<point>/rep<k>/);
  `RUN_PAIRS` is also the stacked results/dem/collisions_replicates.csv.
* `GRID_PAIRS`, `GRID_WALLS`, `GRID_VELOCITIES`, `GRID_WALL_VELOCITIES`: their replicate means with
  `n_replicates` and standard errors (results/dem/collisions.csv, wall_collisions.csv,
  impact_velocity.csv, wall_impact_velocity.csv).
* `RUNS`: results/dem/runs.csv, one row per DEM run.
* `INTERVALS`: a coupled loop's intervals.csv; `COMPARISON`: results/report/comparison.csv.
* `MEASURED`: measured d10/d50/d90 over a batch at one or more speeds (`pbmdem calibrate --data`).

A violation is an `InputFileError` naming the file, the 1-based data row, the column, the value
and what is allowed: a missing column, a cell that is not of the column's type, a non-finite
number, a negative count or frequency, an empty cell where the row must have a value (a
frequency of a class pair that has pairs, a median of a pair that had encounters). An empty cell
is allowed only where the table's own definition makes it empty (no pairs, no encounters, one
replicate), so that no replicate is silently dropped from a mean.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.readers import InputFileError, first_index, read_table

KINDS = {"int": "an integer", "float": "a number", "str": "a text", "list": "a JSON list of numbers"}
SIGNS = {None: "", "nonneg": " >= 0", "positive": " > 0"}


#: the size statistics of every granule-size table (summary.csv, the studies, the measured table):
#: the diameters (m) that 10, 50 and 90 % of the mass is finer than
STATISTICS = ("d10", "d50", "d90")


def as_list(cell) -> np.ndarray | None:
    """A cell of a `list` column as a 1-D float array (an array as it is); None: not a JSON list of numbers."""
    try:
        values = cell if isinstance(cell, np.ndarray) else np.asarray(json.loads(cell), float)
    except (TypeError, ValueError):
        return None
    return values if values.ndim == 1 else None


@dataclass(frozen=True)
class Column:
    """One column: `kind` int, float, str or list (a JSON list of numbers, read as a float array);
    `sign` None, nonneg or positive (numbers); `empty` (a frame -> boolean row mask) where an empty
    cell is allowed, None: never; `required`: the column must be present."""

    name: str
    kind: str = "float"
    sign: str | None = "nonneg"
    empty: Callable[[pd.DataFrame], np.ndarray] | None = None
    required: bool = True

    def problem(self, frame: pd.DataFrame) -> tuple[int, str] | None:
        """(row index, requirement) of the first cell that breaks this column's contract."""
        raw = frame[self.name]
        blank = raw.isna().to_numpy() | (raw.astype(str).str.strip() == "").to_numpy()
        allowed = np.zeros(len(frame), bool) if self.empty is None else np.asarray(self.empty(frame), bool)
        if (row := first_index(blank & ~allowed)) is not None:
            reason = " is allowed only where " + self.empty.__doc__ if self.empty else " is not allowed"
            return row, f"{KINDS[self.kind]}{SIGNS[self.sign]} is required (an empty cell{reason})"
        if self.kind == "str":
            return None
        if self.kind == "list":
            bad = np.array([not b and as_list(cell) is None for cell, b in zip(raw, blank)], bool)
            return None if (row := first_index(bad)) is None else (row, f"{KINDS['list']} is required")
        values = pd.to_numeric(raw.where(~blank), errors="coerce").to_numpy(float)
        checks = [~blank & ~np.isfinite(values)]
        if self.kind == "int":
            checks.append(~blank & np.isfinite(values) & (values != np.round(values)))
        if self.sign == "nonneg":
            checks.append(~blank & (values < 0))
        elif self.sign == "positive":
            checks.append(~blank & ~(values > 0))
        if (row := first_index(np.logical_or.reduce(checks))) is not None:
            return row, f"a finite {KINDS[self.kind].split()[-1]}{SIGNS[self.sign]} is required"
        return None


@dataclass(frozen=True)
class Table:
    """A table's contract: what it is (for messages) and its columns (others may follow)."""

    what: str
    columns: tuple[Column, ...]

    def check(self, frame: pd.DataFrame, source, need=None) -> pd.DataFrame:
        """`frame` if it fulfils the contract, else InputFileError naming `source`, row and column.
        `need`: the columns that must be present (default: every required column of the
        contract); every column of the contract that is present is checked. `source` (a path, or
        empty for a frame in memory) follows the table's name in messages."""
        label = f"{self.what} {source}".strip()
        needed = [c.name for c in self.columns if c.required] if need is None else list(need)
        missing = [name for name in needed if name not in frame.columns]
        if missing:
            raise InputFileError(f"{label}: missing column(s) {missing}; present: {list(frame.columns)}")
        for column in self.columns:
            if column.name not in frame.columns:
                continue
            found = column.problem(frame)
            if found is not None:
                row, requirement = found
                value = frame[column.name].iloc[row]
                value = value.item() if hasattr(value, "item") else value  # a numpy scalar as plain Python
                raise InputFileError(f"{label}: row {row + 1}, column {column.name!r} = {value!r}: {requirement}")
        lists = [c.name for c in self.columns if c.kind == "list" and c.name in frame.columns]  # decoded once, here
        return frame.assign(**{name: [as_list(cell) for cell in frame[name]] for name in lists}) if lists else frame

    def read(self, path: str | Path, what: str | None = None, need=None) -> pd.DataFrame:
        """The table at `path` (a CSV), checked (`what` replaces the table's name in messages;
        `need`: the columns a reader uses, when it does not need the whole table)."""
        table = self if what is None else replace(self, what=what)
        return table.check(read_table(path, table.what), path, need)


# --- where an empty cell is part of a table's definition (never, if the table lacks the columns
# the condition reads)
def _numbers(frame: pd.DataFrame, name: str) -> np.ndarray:
    if name not in frame.columns:
        return np.full(len(frame), np.nan)
    return pd.to_numeric(frame[name], errors="coerce").to_numpy(float)


def no_pairs(frame: pd.DataFrame) -> np.ndarray:
    """the class pair has no particle pair (n_i n_j, or n_i (n_i - 1) / 2 on the diagonal, is 0)"""
    n_i, n_j = _numbers(frame, "n_i"), _numbers(frame, "n_j")
    same = _numbers(frame, "class_i") == _numbers(frame, "class_j")
    return np.where(same, n_i * (n_i - 1) / 2, n_i * n_j) == 0


def no_particles(frame: pd.DataFrame) -> np.ndarray:
    """the class holds no particle (n_i = 0)"""
    return _numbers(frame, "n_i") == 0


def no_encounters(frame: pd.DataFrame) -> np.ndarray:
    """there was no encounter (encounters = 0)"""
    return _numbers(frame, "encounters") == 0


def one_replicate_or_no_particles(frame: pd.DataFrame) -> np.ndarray:
    """the mean is of one replicate (n_replicates = 1) or the class holds no particle"""
    return (_numbers(frame, "n_replicates") == 1) | no_particles(frame)


def one_replicate_or_no_pairs(frame: pd.DataFrame) -> np.ndarray:
    """the mean is of one replicate (n_replicates = 1) or the class pair has no particle pair"""
    return (_numbers(frame, "n_replicates") == 1) | no_pairs(frame)


def _text(name: str) -> Column:
    return Column(name, "str", None)


POINT = (_text("point_id"), Column("rpm", sign="positive"), _text("distribution"))
REPLICATE = Column("replicate", "int")
RUN_PAIRS = Table(
    "per-run collision table",
    (
        *POINT,
        REPLICATE,
        Column("class_i", "int"),
        Column("class_j", "int"),
        Column("d_i", sign="positive"),
        Column("d_j", sign="positive"),
        Column("n_i", "int"),
        Column("n_j", "int"),
        Column("n_total", "int", "positive"),
        Column("collisions", "int"),
        Column("sampling_time", sign="positive"),
        Column("frequency"),
        Column("frequency_per_pair", empty=no_pairs),
        Column("encounters", "int"),
        Column("encounter_frequency_per_pair", empty=no_pairs),
        Column("impact_velocity_median", empty=no_encounters),
    ),
)
RUN_WALLS = Table(
    "per-run wall-collision table",
    (
        *POINT,
        REPLICATE,
        Column("class_i", "int"),
        Column("d_i", sign="positive"),
        Column("n_i", "int"),
        Column("n_total", "int", "positive"),
        _text("wall"),
        Column("collisions", "int"),
        Column("sampling_time", sign="positive"),
        Column("frequency"),
        Column("frequency_per_particle", empty=no_particles),
        Column("encounters", "int"),
        Column("encounter_frequency_per_particle", empty=no_particles),
        Column("impact_velocity_median", empty=no_encounters),
    ),
)
RUN_VELOCITIES = Table(
    "per-run impact-velocity table",
    (
        *POINT,
        REPLICATE,
        Column("class_i", "int"),
        Column("class_j", "int"),
        Column("v_lo"),
        Column("v_hi", sign="positive"),
        Column("encounters", "int"),
    ),
)
RUN_WALL_VELOCITIES = Table(
    "per-run wall impact-velocity table",
    (
        *POINT,
        REPLICATE,
        _text("wall"),
        Column("class_i", "int"),
        Column("v_lo"),
        Column("v_hi", sign="positive"),
        Column("encounters", "int"),
    ),
)
#: per table kind: the columns that are keys of the replicate mean (not averaged)
KEYS = {
    "pairs": ("point_id", "rpm", "distribution", "class_i", "class_j", "d_i", "d_j"),
    "walls": ("point_id", "rpm", "distribution", "wall", "class_i", "d_i"),
    "velocities": ("point_id", "rpm", "distribution", "class_i", "class_j", "v_lo", "v_hi"),
    "wall_velocities": ("point_id", "rpm", "distribution", "wall", "class_i", "v_lo", "v_hi"),
}
#: columns of which the grid tables also carry a standard error `<column>_se`
SE_COLUMNS = ("encounter_frequency_per_pair", "frequency_per_pair", "encounter_frequency_per_particle")


def _grid(table: Table, what: str, keys) -> Table:
    """The replicate-mean table of a per-run table: averaged columns become numbers, `replicate`
    gives way to `n_replicates`, the frequencies of SE_COLUMNS get `<column>_se`."""
    columns = [c if c.name in keys or c.kind == "str" else replace(c, kind="float") for c in table.columns]
    columns = [c for c in columns if c.name != "replicate"] + [Column("n_replicates", "int", "positive")]
    pairs = any(c.name == "n_j" for c in table.columns)
    for c in table.columns:
        if c.name in SE_COLUMNS:
            empty = one_replicate_or_no_pairs if pairs else one_replicate_or_no_particles
            columns.append(Column(f"{c.name}_se", empty=empty))
    return Table(what, tuple(columns))


GRID_PAIRS = _grid(RUN_PAIRS, "collision table", KEYS["pairs"])
GRID_WALLS = _grid(RUN_WALLS, "wall-collision table", KEYS["walls"])
GRID_VELOCITIES = _grid(RUN_VELOCITIES, "impact-velocity table", KEYS["velocities"])
GRID_WALL_VELOCITIES = _grid(RUN_WALL_VELOCITIES, "wall impact-velocity table", KEYS["wall_velocities"])
RUN_TABLES = dict(zip(KEYS, (RUN_PAIRS, RUN_WALLS, RUN_VELOCITIES, RUN_WALL_VELOCITIES)))  # by kind, as KEYS

RUNS = Table(
    "DEM run table",
    (
        *POINT,
        REPLICATE,
        Column("n_particles", "int", "positive"),
        Column("steps", "int", "positive"),
        Column("timestep", sign="positive"),
        Column("total_collisions", "int"),
        Column("total_encounters", "int"),
        Column("sampling_time", sign="positive"),
    ),
)

INTERVALS = Table(
    "coupling-interval record",
    (
        Column("interval", "int"),
        Column("t_start"),
        Column("t_end", sign="positive"),
        Column("rpm", sign="positive"),
        _text("method"),
        Column("classes", "int", "positive"),
        Column("class_diameters", "list", None),
        Column("class_counts", "list", None),
        Column("sample_particles", "int", "positive"),
        Column("class_frequencies", "list", None),
        Column("mean_frequency_per_pair"),
        Column("provider_wall_time_s"),
        Column("pbm_wall_time_s"),
        Column("out_of_domain_count", "int", required=False),
    ),
)


def _no_dem_spread(frame: pd.DataFrame) -> np.ndarray:
    """there is one PBM-DEM replicate (n_dem_replicates = 1)"""
    return _numbers(frame, "n_dem_replicates") == 1


def _no_ann_time(frame: pd.DataFrame) -> np.ndarray:
    """PBM-ANN's warm batches were not timed or took no measurable time (pbm_ann_wall_s empty or 0:
    the ratio is undefined)"""
    t = _numbers(frame, "pbm_ann_wall_s")
    return ~(t > 0)


def _no_cpu_time(frame: pd.DataFrame) -> np.ndarray:
    """a CPU time was not recorded (loops of an older record) or PBM-ANN took no measurable CPU time"""
    return ~(_numbers(frame, "pbm_ann_cpu_s") > 0) | ~np.isfinite(_numbers(frame, "pbm_dem_cpu_s"))


def _not_recorded(frame: pd.DataFrame) -> np.ndarray:
    """the run did not record it (a surrogate-free run, or an older record: before the out-of-domain
    count or the tally of fragments merged at the grid floor)"""
    return np.ones(len(frame), bool)


COMPARISON = Table(
    "comparison table",
    (
        Column("rpm", sign="positive"),
        _text("in_training_grid"),
        Column("n_dem_replicates", "int", "positive"),
        Column("d50_start_mm", sign="positive"),
        Column("d50_end_dem_mm", sign="positive"),
        Column("d50_end_dem_sd_mm", empty=_no_dem_spread),
        Column("d50_end_dem_min_mm", sign="positive"),
        Column("d50_end_dem_max_mm", sign="positive"),
        Column("d50_end_ann_mm", sign="positive"),
        Column("d50_end_constant_mm", sign="positive"),
        *(
            Column(name, sign=sign)
            for q in ("d10", "d90")
            for name, sign in (
                (f"{q}_end_dem_mm", "positive"),
                (f"{q}_end_dem_min_mm", "positive"),
                (f"{q}_end_dem_max_mm", "positive"),
                (f"{q}_end_ann_mm", "positive"),
                (f"ann_{q}_outside_band_max", None),
            )
        ),
        Column("ann_d50_rel_error_max", sign=None),
        Column("ann_d50_rel_error_end", None),
        Column("ann_d50_outside_band_max", sign=None),
        Column("dem_replicate_d50_rel_error_max", sign=None, empty=_no_dem_spread),
        Column("constant_d50_rel_error_max", sign=None),
        Column("constant_d50_rel_error_end", None),
        Column("constant_d50_outside_band_max", sign=None),
        Column("dem_calls", "int"),
        Column("pbm_dem_wall_s"),
        Column("pbm_dem_cpu_s", empty=_no_cpu_time),
        Column("pbm_dem_liggghts_wall_s"),
        Column("pbm_ann_wall_s", empty=_no_ann_time),
        Column("pbm_ann_cpu_s", empty=_no_cpu_time),
        Column("pbm_ann_first_batch_wall_s"),
        Column("pbm_ann_surrogate_wall_s"),
        Column("pbm_constant_wall_s"),
        Column("wall_time_ratio_dem_over_ann", empty=_no_ann_time),
        Column("cpu_time_ratio_dem_over_ann", empty=_no_cpu_time),
        Column("ann_out_of_domain_intervals", "int", empty=_not_recorded),
        Column("ann_intervals", "int"),
        Column("ann_out_of_domain_warnings", "int", empty=_not_recorded),
        Column("constant_calibration_out_of_domain_warnings", "int", empty=_not_recorded),
        # breakage fragments merged at the grid floor, share of the final number (pbm.results.grid_floor)
        Column("dem_merged_fraction_max", empty=_not_recorded),
        Column("ann_merged_fraction", empty=_not_recorded),
        Column("constant_merged_fraction", empty=_not_recorded),
    ),
)

#: the surrogate's pair encounter frequency on the PBM-DEM loops' own samples
#: (pbmdem.validation.pair_samples): one row per validation speed, then the row ``all``
PAIR_SAMPLES = Table(
    "pair-sample table",
    (
        _text("rpm"),
        Column("samples", "int", "positive"),
        Column("pairs", "int", "positive"),
        Column("mean_error_log10", sign=None),
        Column("mae_log10"),
        Column("mean_error_target", sign="positive"),
        Column("mae_target", sign="positive"),
        _text("met"),
    ),
)

#: measured granule sizes over a batch (docs/calibration.md): one row per (impeller speed, time)
#: with d10/d50/d90 and their measurement sd (m); what a calibration fits
MEASURED = Table(
    "measured size table",
    (
        Column("rpm", sign="positive"),
        Column("time"),
        *(Column(s, sign="positive") for s in STATISTICS),
        *(Column(f"{s}_sd") for s in STATISTICS),
    ),
)
