"""The pair encounter frequency of each surrogate family on the PBM-DEM loops' own samples.

Fits every family (``pbmdem.surrogate.settings.FAMILIES``, frequency only) on a finished run's grid
table (results/dem/collisions.csv) and prints, per family, the grouped held-out MAE of log10 c (the
workflow's folds) and the error log10(surrogate / DEM) on every distinct representative sample of
the stored PBM-DEM loops (results/validation/rpm*/pbm_dem/rep*/intervals.csv): mean and MAE,
pooled and per speed. Measured numbers: docs/validation.md ("Pair encounter frequency on the
PBM-DEM loops' own samples").

Run: .venv/bin/python benchmarks/bench_pair_samples.py --results results [--config config/config.yaml]
About 1 min per family on the default grid.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.base import clone

from pbmdem.config import load_config
from pbmdem.frequency import upper_pairs
from pbmdem.surrogate.ensemble import grouped_splits
from pbmdem.surrogate.settings import FAMILIES, build_surrogate
from pbmdem.surrogate.train import _training_data


def loop_samples(results: Path) -> list[tuple[float, np.ndarray, np.ndarray, np.ndarray]]:
    """(rpm, diameters, counts, DEM class-pair frequencies) of every distinct PBM-DEM loop sample."""
    out, seen = [], set()
    for path in sorted((results / "validation").glob("rpm*/pbm_dem/rep*/intervals.csv")):
        rpm = float(path.parts[-4][3:])
        for r in pd.read_csv(path).itertuples():
            key = (rpm, r.class_diameters, r.class_counts)
            if key not in seen:
                seen.add(key)
                out.append((rpm, *(np.asarray(json.loads(v), float) for v in key[1:]),
                            np.asarray(json.loads(r.class_frequencies), float)))  # fmt: skip
    if not out:
        raise SystemExit(f"{results}/validation: no rpm*/pbm_dem/rep*/intervals.csv (a finished run's results?)")
    return out


def sample_errors(model, samples) -> pd.DataFrame:
    """log10(surrogate / DEM) of every class pair with DEM encounters, with its speed."""
    rows = []
    for rpm, d, n, dem in samples:
        iu, ju = upper_pairs(len(d))
        c = model.frequency_matrix(d, n, rpm)[iu, ju]
        ok = dem > 0
        rows.append(pd.DataFrame({"rpm": rpm, "error": np.log10(c[ok] / dem[ok])}))
    return pd.concat(rows, ignore_index=True)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--results", type=Path, required=True, help="a finished run's results folder")
    parser.add_argument("--config", type=Path, default=Path("config/config.yaml"))
    args = parser.parse_args(argv)
    cfg = load_config(args.config)
    settings, radius = cfg.surrogate.to_dict(), cfg.granulator.impeller.tip_radius
    warnings.simplefilter("ignore")  # out-of-domain and convergence warnings: not what is measured here
    data, _, _ = _training_data(args.results / "dem" / "collisions.csv", None, radius, settings)
    samples = loop_samples(args.results)
    splits = grouped_splits(data.groups, settings["cv"]["strategy"], settings["cv"]["n_splits"])
    print(f"{len(samples)} distinct PBM-DEM loop samples; grid table {len(data.y)} rows")
    for family in FAMILIES:
        t0 = time.perf_counter()
        model = build_surrogate(settings, radius, family=family)
        held_out = np.full(len(data.y), np.nan)
        for train, test in splits:
            fitted = clone(model).fit(data.X.iloc[train], data.y[train], groups=data.groups[train])
            held_out[test] = fitted.predict(data.X.iloc[test])
        err = sample_errors(clone(model).fit(data.X, data.y, groups=data.groups), samples)
        per = " ".join(f"{rpm:g}: {e:+.3f}" for rpm, e in err.groupby("rpm").error.mean().items())
        print(
            f"{family:8s} held-out MAE {np.mean(np.abs(held_out - data.y)):.4f}; loop samples: mean error "
            f"{err.error.mean():+.4f}, MAE {err.error.abs().mean():.4f} (mean per rpm {per}); "
            f"{time.perf_counter() - t0:.0f} s"
        )


if __name__ == "__main__":
    main()
