"""PBM speed benchmark (prints figures, no assertions).

* ``import pbmdem.pbm`` (fresh interpreter, in-process import time);
* the default batch: ``run_batch`` of config/config.yaml (all processes, whole process time,
  constant c_ij, 600 rpm, 'fine'), wall time of the whole call (settings, grid, run), with the
  number of steps and what limited them;
* the same on a 4x finer grid, with the fixed pivot scheme, with the feed granules sharing their
  bins' liquid (``separate_feed: false``, the model before) and with Heun's method;
* the time of one aggregation-rate evaluation of both schemes.

``--before REF`` (default ``bdf2171``, the solver before the speed-up) also measures the import
and the default batch of that git revision, in the same way and right after, so before/after
see the same machine load (this machine is shared: compare the two columns, not runs on
different days). Every timing is repeated; min and median are printed.

Run: .venv/bin/python benchmarks/bench_pbm.py [--before REF | --no-before] [--repeat N]
(accuracy against analytical solutions: benchmarks/bench_pbm_accuracy.py)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

# measured in a fresh interpreter (PYTHONPATH selects the source tree): import time, then the
# default batch `repeat` times
_PROBE = r"""
import json, sys, time
t0 = time.perf_counter()
import pbmdem.pbm
t_import = time.perf_counter() - t0
from pbmdem.config import load_config
cfg = load_config(sys.argv[1])
try:                                       # this tree: typed settings
    from pbmdem.pbm.setup import run_batch
    batch = cfg.pbm_batch("fine")
    run = lambda: run_batch(batch, None, 600)
except ImportError:                        # trees before the settings layer
    from pbmdem.pbm import run_pbm
    run = lambda: run_pbm(cfg, None, 600, "fine")
walls = []
for _ in range(int(sys.argv[2])):
    t0 = time.perf_counter()
    res = run()
    walls.append(time.perf_counter() - t0)
s = res.summary()
print(json.dumps({"import_s": t_import, "walls": walls, "steps": int(res.info["steps"]),
                  "d50": [float(s.d50.iloc[0]), float(s.d50.iloc[-1])], "bins": int(res.grid.bins),
                  "step_limits": res.info.get("step_limits")}))
"""


def _probe(src: Path, config: Path, repeat: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    out = subprocess.run([sys.executable, "-c", _PROBE, str(config), str(repeat)], env=env, cwd=src.parent,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _imports(src: Path, repeat: int) -> tuple[list[float], list[float]]:
    """(in-process import times, wall times of `python -c "import pbmdem.pbm"`)."""
    inner, whole = [], []
    for _ in range(repeat):
        a, b = _probe_import(src)
        inner.append(a)
        whole.append(b)
    return inner, whole


def _probe_import(src: Path) -> tuple[float, float]:
    env = dict(os.environ, PYTHONPATH=str(src))
    code = "import time; t = time.perf_counter(); import pbmdem.pbm; print(time.perf_counter() - t)"
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip()), time.perf_counter() - t0


def _fmt(values, scale=1e3, unit="ms") -> str:
    v = np.asarray(values) * scale
    return f"min {v.min():7.1f} {unit}, median {np.median(v):7.1f} {unit}"


def _checkout(ref: str, dest: Path) -> Path:
    """Source tree (src/, config/, workflow/) of git revision ``ref`` under ``dest``."""
    archive = dest / "src.tar"
    with open(archive, "wb") as fh:
        subprocess.run(["git", "archive", ref, "src", "config", "workflow"], cwd=ROOT, stdout=fh, check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(dest, filter="data")
    return dest / "src"


def batch_with(cfg, section: dict, distribution: str = "fine"):
    """The config's batch with its pbm settings replaced by a (partial) pbm section over the
    schema's defaults (the first pivot stays the config's)."""
    from pbmdem.config import Pbm

    pbm = Pbm.from_section(section)
    if section.get("grid", {}).get("min_diameter") is None:
        pbm = pbm.replace(grid=pbm.grid.replace(min_diameter=cfg.pbm.grid.min_diameter))
    return cfg.pbm_batch(distribution).replace(pbm=pbm)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--before", default="bdf2171", help="git revision to compare with (default bdf2171)")
    ap.add_argument("--no-before", action="store_true", help="skip the comparison with --before")
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    print(f"load average (1, 5, 15 min): {', '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} cores")

    rows = [("this tree", ROOT / "src", ROOT / "config" / "config.yaml")]
    tmp = None
    if not args.no_before:
        tmp = tempfile.TemporaryDirectory()
        src = _checkout(args.before, Path(tmp.name))
        rows.append((f"before ({args.before})", src, Path(tmp.name) / "config" / "config.yaml"))
    print(f"\n`import pbmdem.pbm` (fresh interpreter, {args.repeat} times) and the default batch "
          f"(480 s of process, {args.repeat} times):")
    for name, src, cfg in rows:
        imp, whole = _imports(src, args.repeat)
        r = _probe(src, cfg, args.repeat)
        walls = r["walls"][1:] if len(r["walls"]) > 1 else r["walls"]    # the first call warms caches
        print(f"  {name:22s} import {_fmt(imp)} (python -c 'import pbmdem.pbm': {_fmt(whole)})")
        print(f"  {'':22s} batch  {_fmt(walls)} | {r['steps']} steps, "
              f"{r['bins']} bins, d50 {r['d50'][0] * 1e3:.2f} -> {r['d50'][1] * 1e3:.2f} mm")
        if r.get("step_limits"):
            print(f"  {'':22s} step limits: {r['step_limits']}")
    if tmp is not None:
        tmp.cleanup()

    from pbmdem.config import load_config
    from pbmdem.pbm import SCHEMES, Grid
    from pbmdem.pbm.setup import run_batch

    cfg = load_config(ROOT / "config" / "config.yaml")
    print("\nvariants of the default batch (this tree):")
    ratio = cfg.pbm.grid.ratio
    for label, pbm in (("fixed pivot", {"aggregation": {"scheme": "fixed_pivot"}}),
                       ("4x finer grid", {"grid": {"ratio": ratio ** 0.25}}),
                       ("feed shares bins", {"grid": {"separate_feed": False}}),
                       ("heun (SSP-RK2)", {"solver": {"method": "heun"}})):
        batch = batch_with(cfg, pbm)
        run_batch(batch, None, 600)
        walls = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            res = run_batch(batch, None, 600)
            walls.append(time.perf_counter() - t0)
        s = res.summary()
        print(f"  {label:16s} {_fmt(walls)} | {res.info['steps']} steps, {res.grid.bins} bins, "
              f"d50 {s.d50.iloc[0] * 1e3:.2f} -> {s.d50.iloc[-1] * 1e3:.2f} mm")

    print("aggregation-rate evaluation (full (K,K) kernel, totals):")
    rng = np.random.default_rng(0)
    for scheme, K in ((s, K) for s in SCHEMES for K in (35, 100, 200)):
        grid = Grid(K, 2.0 ** (34 / (K - 1)), v0=1.0)
        t0 = time.perf_counter()
        op = SCHEMES[scheme](grid.x, grid.edges[1:-1])
        setup = time.perf_counter() - t0
        beta = rng.random((K, K))
        beta = beta + beta.T
        nlg = rng.random((3, K))
        n = 2000 if K < 150 else 300
        per = []
        for _ in range(3):
            t0 = time.perf_counter()
            for _ in range(n):
                op.totals_stacked(beta, nlg)
            per.append((time.perf_counter() - t0) / n)
        print(f"  {scheme:12s} K = {K:3d}: {min(per) * 1e6:7.1f} us per evaluation (min of 3); "
              f"map setup {setup * 1e3:.2f} ms")


if __name__ == "__main__":
    main()
