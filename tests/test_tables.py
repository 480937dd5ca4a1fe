"""The table contracts (pbmdem.tables): one reader per table, errors naming file, row and column.

Issue 25, item 2: an edited per-replicate table of a finished run (a negative frequency, an
empty cell) was averaged into the grid table, or silently dropped a replicate from its mean.
"""

from __future__ import annotations

import re

import pandas as pd
import pytest

from pbmdem.dem.collisions import aggregate
from pbmdem.readers import InputFileError
from pbmdem.tables import (
    COMPARISON,
    GRID_PAIRS,
    GRID_VELOCITIES,
    GRID_WALLS,
    INTERVALS,
    RUN_PAIRS,
    RUN_VELOCITIES,
    RUN_WALLS,
    RUNS,
)


def pair_rows(replicate: int, frequency: float = 0.1) -> list[dict]:
    """A per-run collision table of two classes (10 and 1 particles: the (1, 1) pair has none)."""
    rows = []
    for i, j in ((0, 0), (0, 1), (1, 1)):
        n_i, n_j = (10, 1)[i], (10, 1)[j]
        pairs = n_i * (n_i - 1) // 2 if i == j else n_i * n_j
        rows.append(
            {
                "point_id": "rpm600_small",
                "rpm": 600.0,
                "distribution": "small",
                "replicate": replicate,
                "class_i": i,
                "class_j": j,
                "d_i": 0.002,
                "d_j": 0.003,
                "n_i": n_i,
                "n_j": n_j,
                "n_total": 11,
                "collisions": 4 if pairs else 0,
                "sampling_time": 0.5,
                "frequency": 8.0 if pairs else 0.0,
                "frequency_per_pair": 8.0 / pairs if pairs else float("nan"),
                "encounters": 2 if pairs else 0,
                "encounter_frequency_per_pair": frequency if pairs else float("nan"),
                "impact_velocity_median": 0.3 if pairs else float("nan"),
            }
        )
    return rows


def write_runs(tmp_path, edit=None) -> list:
    paths = []
    for rep in range(2):
        frame = pd.DataFrame(pair_rows(rep, 0.1 + 0.1 * rep))
        if edit is not None and rep == 0:
            frame = edit(frame)
        path = tmp_path / f"rep{rep}" / "collisions.csv"
        path.parent.mkdir()
        frame.to_csv(path, index=False)
        paths.append(path)
    return paths


def test_finished_tables_pass_and_the_grid_mean_is_their_mean(tmp_path):
    paths = write_runs(tmp_path)
    grid = aggregate(paths, tmp_path / "grid.csv")
    GRID_PAIRS.read(tmp_path / "grid.csv")
    row = grid[(grid.class_i == 0) & (grid.class_j == 0)].iloc[0]
    assert row.encounter_frequency_per_pair == pytest.approx(0.15) and row.n_replicates == 2


def test_a_negative_frequency_in_a_replicate_is_refused_naming_file_row_and_column(tmp_path):
    def negative(frame):
        frame.loc[1, "encounter_frequency_per_pair"] = -0.2395
        return frame

    paths = write_runs(tmp_path, negative)
    with pytest.raises(InputFileError) as err:
        aggregate(paths, tmp_path / "grid.csv")
    assert str(err.value) == (
        f"per-run collision table {paths[0]}: row 2, column 'encounter_frequency_per_pair' = -0.2395: "
        "a finite number >= 0 is required"
    )
    assert not (tmp_path / "grid.csv").exists()


def test_an_empty_cell_does_not_drop_a_replicate_from_the_mean(tmp_path):
    def emptied(frame):
        frame.loc[0, "encounter_frequency_per_pair"] = None
        return frame

    paths = write_runs(tmp_path, emptied)
    with pytest.raises(InputFileError) as err:
        aggregate(paths, tmp_path / "grid.csv")
    text = str(err.value)
    assert f"{paths[0]}: row 1, column 'encounter_frequency_per_pair' = nan" in text
    assert "an empty cell is allowed only where the class pair has no particle pair" in text


def test_an_empty_frequency_of_a_pair_without_particle_pairs_is_part_of_the_contract(tmp_path):
    paths = write_runs(tmp_path)
    frame = RUN_PAIRS.read(paths[0])
    assert frame.encounter_frequency_per_pair.isna().tolist() == [False, False, True]


@pytest.mark.parametrize(
    "column, value, requirement",
    [
        ("replicate", 0.5, "a finite integer >= 0 is required"),
        ("rpm", 0.0, "a finite number > 0 is required"),
        ("collisions", "many", "a finite integer >= 0 is required"),
        ("sampling_time", float("inf"), "a finite number > 0 is required"),
        ("point_id", None, "a text is required (an empty cell is not allowed)"),
        ("impact_velocity_median", None, "only where there was no encounter"),
    ],
)
def test_each_kind_of_violation(tmp_path, column, value, requirement):
    frame = pd.DataFrame(pair_rows(0))
    frame[column] = frame[column].astype(object)
    frame.loc[0, column] = value
    path = tmp_path / "collisions.csv"
    frame.to_csv(path, index=False)
    with pytest.raises(InputFileError, match=rf"row 1, column .{column}. = .*{re.escape(requirement)}"):
        RUN_PAIRS.read(path)


def test_a_missing_column_is_named(tmp_path):
    path = tmp_path / "collisions.csv"
    pd.DataFrame(pair_rows(0)).drop(columns=["n_total"]).to_csv(path, index=False)
    with pytest.raises(InputFileError, match=r"missing column\(s\) \['n_total'\]"):
        RUN_PAIRS.read(path)


def test_wall_velocity_run_interval_and_comparison_tables_are_checked(tmp_path):
    cases = [
        (RUN_WALLS, "frequency_per_particle"),
        (GRID_PAIRS, "encounter_frequency_per_pair_se"),
        (GRID_WALLS, "encounters"),
        (GRID_VELOCITIES, "encounters"),
        (RUN_VELOCITIES, "encounters"),
        (RUNS, "total_encounters"),
        (INTERVALS, "mean_frequency_per_pair"),
        (COMPARISON, "d50_end_ann_mm"),
    ]
    for contract, column in cases:
        row = {c.name: {"str": "x", "list": "[1]"}.get(c.kind, 1) for c in contract.columns}
        row[column] = -1
        path = tmp_path / f"{contract.what.replace(' ', '_')}.csv"
        pd.DataFrame([row]).to_csv(path, index=False)
        with pytest.raises(InputFileError, match=rf"{path}: row 1, column '{column}' = .*-1.* is required"):
            contract.read(path)
        row[column] = 1
        pd.DataFrame([row]).to_csv(path, index=False)
        assert len(contract.read(path)) == 1
