"""Does a refit of every surrogate family give the same model on another BLAS kernel or thread count?

For each OpenBLAS kernel in KERNELS (OPENBLAS_CORETYPE, set for a child process only) and thread
count, the child fits every family (``pbmdem.surrogate.settings.FAMILIES``, settings of the given
config) on the same collision and impact-velocity tables and prints its predictions on the
training rows; the parent prints, per family, the largest relative difference of the encounter
frequency and of the median impact speed against the first setting (target <= 1e-6), and
every family's held-out pooled R2 under every setting. Usage:

    .venv/bin/python benchmarks/bench_surrogate_reproducibility.py [collisions.csv impact_velocity.csv] [--quick]

Without tables, the synthetic tables of tests/synthetic_tables.py are used. ``--quick`` (the
suite's smoke test, about 20 s): config/test.yaml with 2 grouped folds and Kriging without
restarts, the synthetic tables of benchmarks/quick.py, and two settings (QUICK_SETTINGS).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the synthetic tables live with the tests
KERNELS = ("default", "Haswell", "Prescott")
THREADS = (1, 2)
#: the settings of ``--quick`` (kernel, threads): one against another kernel and thread count
QUICK_SETTINGS = (("default", 1), ("Prescott", 2))
CHILD = r"""
import json, sys, warnings
import numpy as np, pandas as pd
from threadpoolctl import threadpool_info
from pbmdem.config import load_config
from pbmdem.surrogate import cross_validate_models, summarise
from pbmdem.surrogate.features import training_data
from pbmdem.surrogate.settings import FAMILIES, build_families
cfg = load_config(sys.argv[1])
radius = cfg.granulator.impeller.tip_radius
table, velocity = pd.read_csv(sys.argv[2]), pd.read_csv(sys.argv[3])
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    data = training_data(
        table, radius, cfg.surrogate.zero_collisions, velocity_table=velocity, speed_law=cfg.surrogate.speed_law
    )
    out = {"blas": [i.get("architecture") for i in threadpool_info()]}
    families = build_families(cfg.surrogate.to_dict(), radius)
    metrics, _ = cross_validate_models(data, families, cfg.surrogate.cv.strategy, cfg.surrogate.cv.n_splits)
    out["r2"] = {k: v["pooled_r2_log10"] for k, v in summarise(metrics).items()}
    for name, model in families.items():
        model.fit(data.X, data.y, groups=data.groups, velocity=data.velocity)
        out[name] = {
            "log10_c": model.predict(data.X, check_domain=False).tolist(),
            "mu": model.predict_velocity(data.X, check_domain=False)[0].tolist(),
        }
print(json.dumps(out))
"""


def quick_inputs(tmp: Path) -> tuple[Path, list[Path]]:
    """(config, [collisions, impact velocities]) of ``--quick``: config/test.yaml with 2 grouped folds
    and Kriging without optimizer restarts (its CV takes minutes with the tiny config's 5 restarts
    and leave-one-run-out), the synthetic grid tables of benchmarks/quick.py."""
    import quick
    import yaml

    data = yaml.safe_load(quick.TEST_CONFIG.read_text())
    data["surrogate"].update(cv={"strategy": "group_kfold", "n_splits": 2}, kriging={"n_restarts_optimizer": 0})
    config = tmp / "quick.yaml"
    config.write_text(yaml.safe_dump(data))
    dem = quick.dem_tables(tmp / "dem", quick.config(config))
    return config, [dem / quick.TABLE_FILES["pairs"], dem / quick.TABLE_FILES["velocities"]]


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tables", nargs="*", type=Path, help="collisions.csv impact_velocity.csv (default: synthetic)")
    parser.add_argument("--quick", action="store_true", help="tiny config, 2 settings (smoke test)")
    args = parser.parse_args(argv)
    if len(args.tables) not in (0, 2):
        parser.error("give both tables (collisions.csv impact_velocity.csv) or none")
    root = Path(__file__).resolve().parents[1]
    config = root / "config" / "config.yaml"
    settings = [(kernel, threads) for kernel in KERNELS for threads in THREADS]
    with tempfile.TemporaryDirectory() as tmp:
        if args.quick:
            config, tables = quick_inputs(Path(tmp))
            settings = QUICK_SETTINGS
        elif args.tables:
            tables = args.tables
        else:
            from synthetic_tables import make_synthetic_tables

            t, v = make_synthetic_tables(0.0265, rpms=(300, 600, 1200), sample_velocities=True)
            tables = [Path(tmp) / "c.csv", Path(tmp) / "v.csv"]
            t.to_csv(tables[0], index=False)
            v.to_csv(tables[1], index=False)
        runs = {}
        for kernel, threads in settings:
            env = dict(os.environ, OMP_NUM_THREADS=str(threads), OPENBLAS_NUM_THREADS=str(threads))
            env.pop("OPENBLAS_CORETYPE", None)
            if kernel != "default":
                env["OPENBLAS_CORETYPE"] = kernel
            proc = subprocess.run(
                [sys.executable, "-c", CHILD, str(config), *map(str, tables)],
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            runs[(kernel, threads)] = json.loads(proc.stdout.strip().splitlines()[-1])
            print(f"fitted with kernel {kernel} ({runs[(kernel, threads)]['blas']}), {threads} thread(s)", flush=True)
    ref_key = next(iter(runs))
    ref = runs[ref_key]
    families = [k for k in ref if k not in ("blas", "r2")]
    print(f"\nlargest relative difference against {ref_key} (encounter frequency c; median impact speed)")
    print("| setting | " + " | ".join(families) + " |")
    print("| --- |" + " --- |" * len(families))
    for key, run in runs.items():
        cells = []
        for name in families:
            dc = np.max(np.abs(10 ** (np.array(run[name]["log10_c"]) - np.array(ref[name]["log10_c"])) - 1))
            dv = np.max(np.abs(10 ** (np.array(run[name]["mu"]) - np.array(ref[name]["mu"])) - 1))
            cells.append(f"{dc:.1e}; {dv:.1e}")
        print(f"| {key[0]}, {key[1]} thread(s) | " + " | ".join(cells) + " |")
    print("\nheld-out pooled R2 of log10 c (grouped CV of the config)")
    print("| setting | " + " | ".join(families) + " |")
    print("| --- |" + " --- |" * len(families))
    for key, run in runs.items():
        print(f"| {key[0]}, {key[1]} thread(s) | " + " | ".join(f"{run['r2'][n]:.4f}" for n in families) + " |")


if __name__ == "__main__":
    main(sys.argv[1:])
