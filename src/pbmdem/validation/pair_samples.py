"""The surrogate's pair encounter frequency on the PBM-DEM loops' own distinct samples against the
DEM's, per validation speed and over all (docs/validation.md, "Pair encounter frequency on the
PBM-DEM loops' own samples"; issue 34).
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
    """One representative sample of a PBM-DEM loop and the DEM's frequency of its class pairs (upper pairs)."""

    rpm: float
    diameters: np.ndarray
    counts: np.ndarray
    frequencies: np.ndarray


def loop_samples(validation_dir: str | Path, rpms, replicates: int) -> list[LoopSample]:
    """The distinct samples of the PBM-DEM loops (``replicates`` per speed of ``rpms``) under ``validation_dir``."""
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
    """log10(surrogate / DEM) (decades) of every class pair with DEM encounters of every sample; the
    surrogate's out-of-domain warnings are not repeated here (PBM-ANN's own loops count them)."""
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
    return pd.concat(rows, ignore_index=True) if rows else pd.DataFrame()


def pair_sample_table(model, samples) -> pd.DataFrame:
    """One row per speed and a last row ``all`` (contract :data:`pbmdem.tables.PAIR_SAMPLES`)."""
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
