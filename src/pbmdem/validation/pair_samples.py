"""The surrogate's pair encounter frequency on the PBM-DEM loops' own samples.

Every coupling interval of a PBM-DEM loop runs LIGGGHTS on the PBM's representative sample of that
moment and records the DEM's encounter frequency of every class pair (``intervals.csv``:
``class_diameters``, ``class_counts``, ``class_frequencies``, per pair in the order of
:func:`pbmdem.frequency.upper_pairs`). These samples are the states PBM-ANN passes through, so
the surrogate's error on them is the test of the pair frequency that matters most (issue 34):
:func:`pair_sample_table` gives, per validation speed and over all speeds, the mean error and the
mean absolute error of log10(surrogate / DEM) (decades) over the class pairs with DEM encounters
of the distinct samples (a sample that several intervals or replicates share, typically the feed,
counts once), beside the targets :data:`MEAN_ERROR_TARGET` and :data:`MAE_TARGET`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.frequency import upper_pairs
from pbmdem.tables import INTERVALS

from .results import run_folder

#: |mean error| of log10 c on the loops' samples at most this (decades; issue 34, item 2)
MEAN_ERROR_TARGET = 0.01
#: mean absolute error of log10 c on the loops' samples at most this (decades; issue 34, item 2)
MAE_TARGET = 0.045


@dataclass(frozen=True)
class LoopSample:
    """One representative sample of a PBM-DEM loop: speed (rpm), class diameters (m), particle
    counts, the DEM's encounter frequency per pair of every class pair (1/s, upper pairs)."""

    rpm: float
    diameters: np.ndarray
    counts: np.ndarray
    frequencies: np.ndarray


def loop_samples(validation_dir: str | Path, rpms, replicates: int) -> list[LoopSample]:
    """The distinct samples of the PBM-DEM loops (``replicates`` per speed of ``rpms``, the speeds as
    in the paths) under ``validation_dir``, from their ``intervals.csv`` (contract
    :data:`pbmdem.tables.INTERVALS`)."""
    out, seen = [], set()
    for rpm in rpms:
        for rep in range(int(replicates)):
            path = run_folder(validation_dir, str(rpm), "pbm_dem", rep) / "intervals.csv"
            table = INTERVALS.read(path, "PBM-DEM coupling-interval record")
            for row in table.itertuples():
                d, n, c = row.class_diameters, row.class_counts, row.class_frequencies
                key = (float(rpm), tuple(d), tuple(n))
                if key in seen:
                    continue
                seen.add(key)
                if len(d) != len(n) or len(c) != len(d) * (len(d) + 1) // 2:
                    raise ValueError(
                        f"{path}: interval {row.interval}: {len(d)} diameters, {len(n)} counts and {len(c)} pair "
                        f"frequencies; K classes need K counts and K (K + 1) / 2 frequencies"
                    )
                out.append(LoopSample(float(rpm), d, n, c))
    return out


def sample_errors(model, samples) -> pd.DataFrame:
    """log10(surrogate / DEM) of every class pair with DEM encounters of every sample: columns rpm,
    sample (its index), class_i, class_j, error (decades). ``model``: a fitted surrogate (its
    ``frequency_matrix``, the ensemble mean PBM-ANN uses); its out-of-domain warnings are not
    repeated here (PBM-ANN's own loops count them)."""
    rows = []
    for k, s in enumerate(samples):
        iu, ju = upper_pairs(len(s.diameters))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            c = model.frequency_matrix(s.diameters, s.counts, s.rpm)[iu, ju]
        ok = s.frequencies > 0
        rows.append(
            pd.DataFrame(
                {
                    "rpm": s.rpm,
                    "sample": k,
                    "class_i": iu[ok],
                    "class_j": ju[ok],
                    "error": np.log10(c[ok] / s.frequencies[ok]),
                }
            )
        )
    return (
        pd.concat(rows, ignore_index=True)
        if rows
        else pd.DataFrame(columns=["rpm", "sample", "class_i", "class_j", "error"])
    )


def pair_sample_table(model, samples) -> pd.DataFrame:
    """One row per speed and a last row ``all`` (contract :data:`pbmdem.tables.PAIR_SAMPLES`): the
    speed, distinct samples, class pairs with DEM encounters, mean error and MAE of log10 c
    (decades), the targets and whether both are met."""
    errors = sample_errors(model, samples)
    if errors.empty:
        raise ValueError("no PBM-DEM loop sample with DEM encounters: nothing to compare the surrogate with")
    groups = [(f"{rpm:g}", g) for rpm, g in errors.groupby("rpm", sort=True)] + [("all", errors)]
    rows = []
    for speed, g in groups:
        mean, mae = float(g["error"].mean()), float(g["error"].abs().mean())
        rows.append(
            {
                "rpm": speed,
                "samples": int(g["sample"].nunique()),
                "pairs": len(g),
                "mean_error_log10": mean,
                "mae_log10": mae,
                "mean_error_target": MEAN_ERROR_TARGET,
                "mae_target": MAE_TARGET,
                "met": bool(abs(mean) <= MEAN_ERROR_TARGET and mae <= MAE_TARGET),
            }
        )
    return pd.DataFrame(rows)
