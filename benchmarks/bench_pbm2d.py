"""Two-dimensional PBM speed and accuracy benchmark (prints figures, no assertions).

* the default batch: ``run_batch`` of config/config.yaml's pbm settings with ``pbm.dimensions: 2``
  (PBM-constant: constant c_ij, 600 rpm, 'fine' feed, breakage on), wall and CPU time of the whole
  call (settings, grid, run), min / median / max over the repeats after one warm-up, its steps and
  what limited them, d10 / d50 / d90; the same for ``dimensions: 1`` beside it;
* the one-off cost of the first 2-D model build in a fresh process (numba loading ``_compiled2d``
  from its cache);
* one rate evaluation (``_compiled2d.class_rates2d``) at the batch's end state, with the number of
  occupied classes;
* ``--accuracy``: the verification of tests/test_pbm2d.py on the grids q = 1..4 (size ratio and
  liquid-class ratio 2^(1/q)): errors of the size marginal, of the mean and the spread of the liquid
  per size and of the liquid's second moment against the closed form (``analytical2d``), observed
  orders between successive grids, conservation of solid, liquid and gas (about 2 min).

Run on one core: numba's loops are serial; the benchmark pins the process to one CPU where the
platform allows. ``--quick``: three repeats, no fresh-process build cost, no accuracy table (well
under a minute).

    .venv/bin/python benchmarks/bench_pbm2d.py [--quick] [--repeat N] [--accuracy]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the verification harness lives with the tests
RPM = 600.0

_BUILD_PROBE = r"""
import sys, time
from pbmdem.config import load_config
from pbmdem.pbm.setup import build_model
cfg = load_config(sys.argv[1])
batch = cfg.pbm_batch("fine")
t0 = time.perf_counter()
build_model(batch.pbm.replace(dimensions=2), None, 600.0)
print(time.perf_counter() - t0)
"""


def _stats(values) -> str:
    return f"min {min(values):.3f}  median {statistics.median(values):.3f}  max {max(values):.3f}"


def batch_times(dimensions: int, repeat: int):
    from pbmdem.config import load_config
    from pbmdem.pbm.setup import run_batch

    batch = load_config(ROOT / "config" / "config.yaml").pbm_batch("fine")
    batch = batch.replace(pbm=batch.pbm.replace(dimensions=dimensions))
    run_batch(batch, None, RPM)  # warm: numba's cache loaded, the grid's operators built
    walls, cpus = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        res = run_batch(batch, None, RPM)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    s = res.summary().iloc[-1]
    print(f"default batch, dimensions {dimensions} ({repeat} runs, warm):")
    print(f"  wall s: {_stats(walls)}")
    print(f"  CPU s:  {_stats(cpus)}")
    print(f"  steps {res.info['steps']}, limits {res.info['step_limits']}")
    print(f"  final d10 / d50 / d90 = {s.d10 * 1e3:.4f} / {s.d50 * 1e3:.4f} / {s.d90 * 1e3:.4f} mm")
    return res


def evaluation_time(res) -> None:
    """One rate evaluation at the batch's end state (the model of the last run)."""
    from pbmdem.config import load_config
    from pbmdem.pbm.setup import build_model

    batch = load_config(ROOT / "config" / "config.yaml").pbm_batch("fine")
    model = build_model(batch.pbm.replace(dimensions=2), None, RPM)
    state = res.state
    model.run(state.t, state.t + 1e-3, state)  # sets up the classes, the kernel's factors, the selection
    u = model._class_state(state)
    occupied = int(np.count_nonzero(u[: model._M2]))
    n = 200
    t0 = time.perf_counter()
    for _ in range(n):
        model._rates(state.t, u, False, 0)
    dt = (time.perf_counter() - t0) / n
    print(f"one rate evaluation at the end state: {dt * 1e3:.3f} ms ({occupied} of {model._M2} classes occupied)")


def build_cost() -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    out = subprocess.run(
        [sys.executable, "-c", _BUILD_PROBE, str(ROOT / "config" / "config.yaml")],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    print(f"first 2-D model build in a fresh process (numba cache load): {float(out.stdout):.2f} s")


def accuracy(qs=(1, 2, 3, 4)) -> None:
    import pbm_verification2d as v2

    from pbmdem.pbm.grid import Grid

    N0, mx, my, beta, t_end = 1000.0, 1e-9, 0.3e-9, 1e-3, 18.0  # SI; tenfold growth (tests/test_pbm2d.py)
    print("\nconstant kernel, bivariate exponential start, tenfold growth (SI units, rtol 1e-5):")
    print("q | K x J | steps | CPU s | size L1 | liquid mean | liquid spread | M02 | conservation (solid, liquid, gas)")
    prev = None
    keys = ("size_l1", "liquid_mean", "liquid_spread")
    for q in qs:
        r = 2.0 ** (1.0 / q)
        grid = Grid(int(np.ceil(np.log(400 / 1e-2) / np.log(r))) + 1, r, v0=1e-2 * mx)
        lg = v2.geometric_liquid_grid(my / mx / 16, my / mx * 16, r)
        c0 = time.process_time()
        res = v2.simulate_bivariate(grid, lg, beta, t_end, N0, mx, my, rtol=1e-5, atol=1e-10)
        cpu = time.process_time() - c0
        e = v2.bivariate_errors(res, beta, N0, mx, my)
        tot = [
            np.array([(c[0] * grid.x[:, None]).sum(), c[1].sum(), c[2].sum()])
            for c in (res.classes[0], res.classes[-1])
        ]
        cons = np.abs(tot[1] / tot[0] - 1)
        print(
            f"{q} | {grid.bins} x {lg.classes} | {res.info['steps']} | {cpu:.1f} | "
            + " | ".join(f"{e[k]:.3g}" for k in keys)
            + f" | {e['M02']:+.3g} | "
            + " ".join(f"{c:.1e}" for c in cons)
        )
        if prev is not None:
            pq, pe = prev
            orders = [np.log(pe[k] / e[k]) / np.log(q / pq) for k in keys]
            print(f"  observed order q {pq} -> {q}: " + ", ".join(f"{k} {o:.2f}" for k, o in zip(keys, orders)))
        prev = (q, e)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="three repeats, no fresh-process build, no accuracy")
    ap.add_argument("--repeat", type=int, default=None, help="timed runs of each batch (default 9, quick 3)")
    ap.add_argument("--accuracy", action="store_true", help="the verification table (about 2 min)")
    args = ap.parse_args(argv)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
        print(f"pinned to CPU {sorted(os.sched_getaffinity(0))[0]}; load average {os.getloadavg()}")
    repeat = args.repeat or (3 if args.quick else 9)
    if not args.quick:
        build_cost()
    res = batch_times(2, repeat)
    batch_times(1, repeat)
    evaluation_time(res)
    if args.accuracy and not args.quick:
        accuracy()


if __name__ == "__main__":
    main()
