"""Size of a saved surrogate and the time to load it (``pbmdem.surrogate.load_surrogate``: sidecar,
hash, version and type checks, then ``skops.io.load``).

Prints the sizes of ``model.skops`` and its sidecar ``model.json`` and min/median/max of the wall
time of ``REPEATS`` loads in one process (the first, which imports nothing new either, included).
Usage:

    .venv/bin/python benchmarks/bench_surrogate_persistence.py [results/surrogate/model.skops ...] [--quick]

``--quick`` (the suite's smoke test): the MLP surrogate with wall models of benchmarks/quick.py,
trained on its synthetic tables in a temporary folder.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from quick import timed_surrogate

from pbmdem.surrogate import load_surrogate
from pbmdem.surrogate.persistence import metadata_path_for

REPEATS = 11


def measure(path: Path) -> None:
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        model = load_surrogate(path)
        times.append(time.perf_counter() - t0)
    walls = ", ".join(sorted(getattr(model, "wall_models_", None) or {})) or "none"
    print(
        f"{path}: model.skops {path.stat().st_size / 1e3:.1f} kB, model.json "
        f"{metadata_path_for(path).stat().st_size / 1e3:.1f} kB; family "
        f"{type(model.frequency_model_).__name__}, wall models {walls}"
    )
    print(
        f"load ms ({REPEATS} loads in one process): min {1e3 * min(times):.1f}, "
        f"median {1e3 * statistics.median(times):.1f}, max {1e3 * max(times):.1f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="*", type=Path, help="model.skops files (their model.json beside them)")
    parser.add_argument("--quick", action="store_true", help="a small surrogate trained on synthetic tables")
    args = parser.parse_args()
    if not args.models and not args.quick:
        parser.error("give model files or --quick")
    for path in args.models:
        measure(path)
    if args.quick:
        with tempfile.TemporaryDirectory() as folder:
            measure(timed_surrogate(folder)[0])


if __name__ == "__main__":
    main()
