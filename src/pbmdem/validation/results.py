"""Reading the validation's results of one speed, PBM-DEM replicates, PBM-ANN (and its ensemble
members) and PBM-constant, with errors that name the file (layout: docs/architecture.md,
"Validation results").
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from pbmdem import layout
from pbmdem.readers import read_json, read_table
from pbmdem.tables import INTERVALS


def run_folder(validation_dir: str | Path, rpm: str, method: str, replicate: int | None = None) -> Path:
    """One run's folder (`pbmdem.layout.validation_run`) under the validation folder `validation_dir`."""
    return Path(layout.validation_run(method, rpm, replicate, validation_dir))


@dataclass
class Run:
    """One run of a validation model (the files it reads: docs/architecture.md, "Validation results")."""

    folder: Path
    summary: pd.DataFrame
    final_bins: pd.DataFrame
    timing: dict
    intervals: pd.DataFrame | None


def load_run(folder: Path, what: str) -> Run:
    summary = read_table(
        folder / "summary.csv", what, columns=("time", "d10", "d50", "d90"), finite=("time", "d10", "d50", "d90")
    )
    intervals = (
        INTERVALS.read(folder / "intervals.csv", f"{what}: coupling-interval record", need=())
        if (folder / "intervals.csv").exists()
        else None
    )
    return Run(
        folder,
        summary,
        read_table(folder / "final_bins.csv", what),
        read_json(folder / "timing.json", what, keys=("total_wall_time_s",)),
        intervals,
    )


@dataclass
class SpeedResults:
    """Everything the validation computed at one speed."""

    rpm: str
    dem: list[Run]
    ann: Run
    constant: Run
    members: pd.DataFrame | None


def load_speed(validation_dir: str | Path, rpm: str, replicates: int) -> SpeedResults:
    dem = [
        load_run(run_folder(validation_dir, rpm, "pbm_dem", k), f"PBM-DEM replicate {k} result")
        for k in range(replicates)
    ]
    ann_dir = run_folder(validation_dir, rpm, "pbm_ann")
    members = None
    if (ann_dir / "members.csv").exists():
        members = read_table(
            ann_dir / "members.csv", "PBM-ANN ensemble-member table", columns=("member", "time", "d50")
        )
    return SpeedResults(
        rpm,
        dem,
        load_run(ann_dir, "PBM-ANN result"),
        load_run(run_folder(validation_dir, rpm, "pbm_constant"), "PBM-constant result"),
        members,
    )
