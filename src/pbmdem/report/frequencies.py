"""The collision frequencies the three models used, interval by interval (their intervals.csv and
PBM-constant's calibrated value), and the surrogate's c_ij against the DEM's on PBM-DEM's own
samples, its out-of-domain warnings recorded (docs/validation.md, "Report": Figures of a speed).
"""

from __future__ import annotations

import pandas as pd

from pbmdem.frequency import upper_pairs
from pbmdem.readers import InputFileError
from pbmdem.surrogate.domain import out_of_domain_recorded
from pbmdem.tables import INTERVALS

#: the interval columns these tables read
INTERVAL_COLUMNS = (
    "interval",
    "t_start",
    "t_end",
    "class_diameters",
    "class_counts",
    "class_frequencies",
    "mean_frequency_per_pair",
)


def _intervals(run, what: str) -> pd.DataFrame:
    frame = run.intervals
    if frame is None:
        raise InputFileError(f"{what}: no intervals.csv (a coupled loop writes one)")
    return INTERVALS.check(frame, f"({what}) intervals.csv", need=INTERVAL_COLUMNS)


def interval_frequencies(speed) -> pd.DataFrame:
    """Long table of the mean frequency per pair (1/s per pair) of every interval of every loop;
    PBM-constant is one row over the whole batch (`interval` -1)."""
    loops = [("PBM-DEM", f"replicate {k}", rep, f"PBM-DEM replicate {k} result") for k, rep in enumerate(speed.dem)]
    loops.append(("PBM-ANN", "ensemble mean", speed.ann, "PBM-ANN result"))
    rows = []
    for model, run, result, what in loops:
        frame = _intervals(result, what)
        rows += [
            {
                "model": model,
                "run": run,
                "interval": int(r.interval),
                "t_start": r.t_start,
                "t_end": r.t_end,
                "mean_frequency_per_pair": r.mean_frequency_per_pair,
            }
            for r in frame.itertuples()
        ]
    if "frequency" not in speed.constant.timing:
        raise InputFileError(
            f"PBM-constant timing {speed.constant.folder / 'timing.json'}: missing field(s) ['frequency']"
        )
    rows.append(
        {
            "model": "PBM-constant",
            "run": "calibrated",
            "interval": -1,
            # over PBM-ANN's batch (the last loop's intervals)
            "t_start": float(frame.t_start.min()),
            "t_end": float(frame.t_end.max()),
            "mean_frequency_per_pair": float(speed.constant.timing["frequency"]),
        }
    )
    return pd.DataFrame(rows)


def surrogate_on_dem_samples(speed, surrogate) -> pd.DataFrame:
    """One row per class pair of every PBM-DEM interval sample: the DEM's and the surrogate's c_ij
    (1/s per pair) and whether (and what) the surrogate warned on this sample."""
    rows = []
    for k, rep in enumerate(speed.dem):
        for r in _intervals(rep, f"PBM-DEM replicate {k} result").itertuples():
            d, n, dem = r.class_diameters, r.class_counts, r.class_frequencies
            with out_of_domain_recorded(
                f"report, {speed.rpm} rpm, PBM-DEM replicate {k} interval {r.interval}", log_each=False
            ) as found:
                c = surrogate.frequency_matrix(d, n, float(speed.rpm))
            iu, ju = upper_pairs(len(d))
            if dem.shape != iu.shape:
                raise InputFileError(
                    f"PBM-DEM replicate {k} intervals.csv, interval {r.interval}: "
                    f"{dem.size} class-pair frequencies for {len(d)} classes "
                    f"({iu.size} pairs expected)"
                )
            rows += [
                {
                    "replicate": k,
                    "interval": int(r.interval),
                    "class_i": int(i),
                    "class_j": int(j),
                    "d_i": d[i],
                    "d_j": d[j],
                    "dem": float(dem[p]),
                    "surrogate": float(c[i, j]),
                    "out_of_domain": bool(found),
                    "warnings": "; ".join(found),
                }
                for p, (i, j) in enumerate(zip(iu, ju))
            ]
    return pd.DataFrame(
        rows,
        columns=[
            "replicate",
            "interval",
            "class_i",
            "class_j",
            "d_i",
            "d_j",
            "dem",
            "surrogate",
            "out_of_domain",
            "warnings",
        ],
    )
