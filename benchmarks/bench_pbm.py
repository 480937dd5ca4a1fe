"""PBM and PBM-ANN speed benchmark (prints figures, no assertions).

* ``import pbmdem.pbm`` (fresh interpreter, in-process import time);
* the default batch: ``run_batch`` of config/config.yaml (all processes, whole process time,
  constant c_ij, 600 rpm, 'fine'), wall time of the whole call (settings, grid, run), with the
  number of steps and what limited them, and its d10 / d50 / d90;
* PBM-ANN: the coupled loop of the config (``validation.coupling_intervals`` = 6 intervals) with
  a small surrogate trained here on ``make_synthetic_tables`` of tests/synthetic_tables.py (the
  config's ``surrogate:`` settings with one hyperparameter candidate: 5 + 5 MLP members), split
  into the surrogate's time (``provider_wall_time_s``: one ``encounters`` call per interval with
  its out-of-domain check), the PBM's time (``pbm_wall_time_s``) and the rest of ``run_loop``
  (representative sample, class-frequency source, writing the interval folders and tables);
* the one-off cost of the first model build in a process (numba's import and the load of its
  compiled functions from the on-disk cache), and of a build with an empty cache (compiling);
* variants of the default batch (4x finer grid, fixed pivot, lumped feed, Heun's method);
* the time of one aggregation-rate evaluation: the compiled loop (the library's one
  implementation) and the sparse-map numpy oracle of the tests (``tests/pbm_oracle.py``).

``--before REF`` (default ``1b77f4f``, the tree before the compiled PBM and the surrogate's array
path) also measures the import, the default batch and the PBM-ANN loop of that git revision, in
the same way and right after (the same surrogate file), so before/after see the same machine
load (this machine is shared: compare the columns of one run, and read the load average it
prints). Every timing is repeated; min and median are printed.

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
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RPM = 600.0

# measured in a fresh interpreter (PYTHONPATH selects the source tree): import time, the first
# model build (one-off costs), then the default batch `repeat` times
_PROBE = r"""
import json, sys, time
t0 = time.perf_counter()
import pbmdem.pbm
t_import = time.perf_counter() - t0
from pbmdem.config import load_config
cfg = load_config(sys.argv[1])
try:                                       # trees with typed settings
    from pbmdem.pbm.setup import build_model, run_batch
    batch = cfg.pbm_batch("fine")
    t0 = time.perf_counter()
    build_model(batch.pbm, None, 600)
    t_build = time.perf_counter() - t0
    run = lambda: run_batch(batch, None, 600)
except ImportError:                        # trees before the settings layer
    from pbmdem.pbm import run_pbm
    t_build = None
    run = lambda: run_pbm(cfg, None, 600, "fine")
walls = []
for _ in range(int(sys.argv[2])):
    t0 = time.perf_counter()
    res = run()
    walls.append(time.perf_counter() - t0)
s = res.summary()
print(json.dumps({"import_s": t_import, "first_build_s": t_build, "walls": walls, "steps": int(res.info["steps"]),
                  "d50": [float(s.d50.iloc[0]), float(s.d50.iloc[-1])],
                  "final": [float(s[q].iloc[-1]) for q in ("d10", "d50", "d90")], "bins": int(res.grid.bins),
                  "step_limits": res.info.get("step_limits")}))
"""

# the PBM-ANN loop of the config with the surrogate file argv[2], argv[4] times, in folders under argv[5]
_ANN_PROBE = r"""
import json, logging, sys, time
from pathlib import Path
logging.disable(logging.WARNING)            # the loop logs every out-of-domain warning; they are counted
from pbmdem.config import load_config
from pbmdem.coupling.loop import run_loop
from pbmdem.coupling.providers import SurrogateProvider
from pbmdem.pbm.setup import build_model
cfg = load_config(sys.argv[1])
loop = cfg.coupled_loop()
rpm = float(sys.argv[3])
t0 = time.perf_counter()
build_model(loop.batch.pbm, None, rpm)      # the one-off costs of a first model build
t_build = time.perf_counter() - t0
t0 = time.perf_counter()
provider = SurrogateProvider(sys.argv[2], rpm)
t_load = time.perf_counter() - t0
runs = []
for r in range(int(sys.argv[4])):
    t0 = time.perf_counter()
    out = run_loop(loop, provider, rpm, Path(sys.argv[5]) / f"run{r}")
    wall = time.perf_counter() - t0
    s = out.result.summary()
    runs.append({"wall": wall, "surrogate": out.totals["provider_wall_time_s"], "pbm": out.totals["pbm_wall_time_s"],
                 "out_of_domain": out.totals.get("out_of_domain_count"), "intervals": out.totals["intervals"],
                 "final": [float(s[q].iloc[-1]) for q in ("d10", "d50", "d90")], "steps": int(out.result.state.steps)})
print(json.dumps({"first_build_s": t_build, "load_s": t_load, "runs": runs}))
"""


def _run(code: str, src: Path, *args) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    out = subprocess.run(
        [sys.executable, "-c", code, *map(str, args)],
        env=env,
        cwd=src.parent,
        check=False,
        capture_output=True,
        text=True,
    )
    if out.returncode != 0:
        raise RuntimeError(out.stderr.strip().splitlines()[-1] if out.stderr.strip() else f"exit {out.returncode}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _imports(src: Path, repeat: int) -> tuple[list[float], list[float]]:
    """(in-process import times, wall times of `python -c "import pbmdem.pbm"`)."""
    inner, whole = [], []
    env = dict(os.environ, PYTHONPATH=str(src))
    code = "import time; t = time.perf_counter(); import pbmdem.pbm; print(time.perf_counter() - t)"
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
        whole.append(time.perf_counter() - t0)
        inner.append(float(out.stdout.strip()))
    return inner, whole


def _fmt(values, scale=1e3, unit="ms") -> str:
    v = np.asarray(values, float) * scale
    return f"min {v.min():7.1f} {unit}, median {np.median(v):7.1f} {unit}"


def _checkout(ref: str, dest: Path) -> Path:
    """Source tree (src/, config/, workflow/) of git revision ``ref`` under ``dest``."""
    archive = dest / "src.tar"
    with open(archive, "wb") as fh:
        subprocess.run(["git", "archive", ref, "src", "config", "workflow"], cwd=ROOT, stdout=fh, check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(dest, filter="data")
    return dest / "src"


def train_surrogate(cfg, folder: Path) -> tuple[Path, float]:
    """A small surrogate (pairs, walls, the config's speed law) trained on synthetic tables
    (benchmarks/quick.py) in ``folder``: its path and the fit time."""
    import quick

    t0 = time.perf_counter()
    path = quick.surrogate(folder, cfg)
    return path, time.perf_counter() - t0


def cold_build(src: Path) -> float | None:
    """Wall time of the first model build in a fresh interpreter with an empty numba cache."""
    code = (
        "import time\nfrom pbmdem.config import load_config\nfrom pbmdem.pbm.setup import build_model\n"
        "cfg = load_config('config/config.yaml')\nt0 = time.perf_counter()\n"
        "build_model(cfg.pbm_batch('fine').pbm, None, 600)\nprint(time.perf_counter() - t0)"
    )
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, PYTHONPATH=str(src), NUMBA_CACHE_DIR=cache)
        out = subprocess.run(
            [sys.executable, "-c", code], env=env, cwd=src.parent, capture_output=True, text=True, check=False
        )
    return float(out.stdout.strip().splitlines()[-1]) if out.returncode == 0 else None


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--before", default="1b77f4f", help="git revision to compare with (default 1b77f4f)")
    ap.add_argument("--no-before", action="store_true", help="skip the comparison with --before")
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--ann-repeat", type=int, default=5, help="PBM-ANN loops per tree (the first is not counted)")
    ap.add_argument(
        "--quick", action="store_true", help="no --before, 2 repeats, no variants or per-evaluation timing (smoke test)"
    )
    args = ap.parse_args()
    if args.quick:
        args.no_before, args.repeat, args.ann_repeat = True, 2, 2
    load = os.getloadavg()
    print(f"load average (1, 5, 15 min): {', '.join(f'{x:.2f}' for x in load)} on {os.cpu_count()} cores")

    from pbmdem.config import load_config

    cfg = load_config(ROOT / "config" / "config.yaml")
    tmp = tempfile.TemporaryDirectory()
    model_path, fit = train_surrogate(cfg, Path(tmp.name) / "surrogate")
    loop = cfg.coupled_loop()
    print(
        f"surrogate for PBM-ANN: trained in {fit:.1f} s on synthetic tables (benchmarks/quick.py); loop: "
        f"{loop.coupling_intervals} intervals of {loop.batch.pbm.process.end / loop.coupling_intervals:g} s, "
        f"'{loop.batch.distribution}', {RPM:g} rpm, at most {loop.sample.max_classes} classes"
    )

    rows = [("this tree", ROOT / "src", ROOT / "config" / "config.yaml")]
    if not args.no_before:
        dest = Path(tmp.name) / "before"
        dest.mkdir()
        src = _checkout(args.before, dest)
        rows.append((f"before ({args.before})", src, dest / "config" / "config.yaml"))
    print(
        f"\n`import pbmdem.pbm` (fresh interpreter, {args.repeat} times), the default batch (480 s of process, "
        f"{args.repeat} times after a first call) and PBM-ANN ({args.ann_repeat} loops, the first not counted):"
    )
    results = {}
    for name, src, config in rows:
        imp, whole = _imports(src, args.repeat)
        r = _run(_PROBE, src, config, args.repeat + 1)
        walls = r["walls"][1:]  # the first call warms caches
        print(f"  {name:22s} import {_fmt(imp)} (python -c 'import pbmdem.pbm': {_fmt(whole)})")
        if r.get("first_build_s") is not None:
            print(f"  {'':22s} first model build in the process: {r['first_build_s'] * 1e3:.0f} ms")
        print(
            f"  {'':22s} batch  {_fmt(walls)} | {r['steps']} steps, {r['bins']} bins, d10 / d50 / d90 "
            + " / ".join(f"{q * 1e3:.6f}" for q in r["final"])
            + " mm"
        )
        if r.get("step_limits"):
            print(f"  {'':22s} step limits: {r['step_limits']}")
        try:
            a = _run(_ANN_PROBE, src, config, model_path, RPM, args.ann_repeat, Path(tmp.name) / f"ann{len(results)}")
        except RuntimeError as exc:
            print(f"  {'':22s} PBM-ANN: not measured ({exc})")
            results[name] = (r, None)
            continue
        runs = a["runs"][1:] if len(a["runs"]) > 1 else a["runs"]
        sur = [x["surrogate"] for x in runs]
        pbm = [x["pbm"] for x in runs]
        both = [x["surrogate"] + x["pbm"] for x in runs]
        rest = [x["wall"] - x["surrogate"] - x["pbm"] for x in runs]
        n = runs[0]["intervals"]
        print(
            f"  {'':22s} PBM-ANN surrogate + PBM {_fmt(both)} (surrogate {_fmt(sur)}, {n} calls; PBM {_fmt(pbm)}, "
            f"{runs[0]['steps']} steps)"
        )
        print(
            f"  {'':22s}         rest of the loop (sample, class source, files) {_fmt(rest)}; whole run_loop "
            f"{_fmt([x['wall'] for x in runs])}"
        )
        print(
            f"  {'':22s}         {runs[0]['out_of_domain']} out-of-domain warnings per loop; final d10 / d50 / d90 "
            + " / ".join(f"{q * 1e3:.6f}" for q in runs[0]["final"])
            + " mm; surrogate file load "
            f"{a['load_s'] * 1e3:.0f} ms, first model build {a['first_build_s'] * 1e3:.0f} ms"
        )
        results[name] = (r, runs)
    if len(rows) == 2:
        (r_new, a_new), (r_old, a_old) = results[rows[0][0]], results[rows[1][0]]
        rel = [abs(a / b - 1) for a, b in zip(r_new["final"], r_old["final"])]
        print(f"  default batch, relative change of d10 / d50 / d90: {' / '.join(f'{x:.2e}' for x in rel)}")
        if a_new and a_old:
            rel = [abs(a / b - 1) for a, b in zip(a_new[0]["final"], a_old[0]["final"])]
            print(f"  PBM-ANN, relative change of the final d10 / d50 / d90: {' / '.join(f'{x:.2e}' for x in rel)}")
    cold = None if args.quick else cold_build(ROOT / "src")
    if cold is not None:
        print(f"  this tree, first model build with an empty numba cache (compiling): {cold:.2f} s")
    print(f"load average after: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    tmp.cleanup()
    if args.quick:
        return

    from bench_pbm_accuracy import batch_with  # the config's batch with a pbm section over the defaults

    from pbmdem.pbm import SCHEMES, Grid
    from pbmdem.pbm.setup import run_batch

    sys.path.insert(0, str(ROOT / "tests"))
    import pbm_oracle  # the numpy oracle of the compiled rates

    print("\nvariants of the default batch (this tree):")
    ratio = cfg.pbm.grid.ratio
    for label, pbm in (
        ("fixed pivot", {"aggregation": {"scheme": "fixed_pivot"}}),
        ("4x finer grid", {"grid": {"ratio": ratio**0.25}}),
        ("feed shares bins", {"grid": {"separate_feed": False}}),
        ("heun (SSP-RK2)", {"solver": {"method": "heun"}}),
    ):
        batch = batch_with(cfg, pbm)
        run_batch(batch, None, 600)
        walls = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            res = run_batch(batch, None, 600)
            walls.append(time.perf_counter() - t0)
        s = res.summary()
        print(
            f"  {label:16s} {_fmt(walls)} | {res.info['steps']} steps, {res.grid.bins} bins, "
            f"d50 {s.d50.iloc[0] * 1e3:.2f} -> {s.d50.iloc[-1] * 1e3:.2f} mm"
        )

    print("aggregation-rate evaluation (full (K,K) kernel, totals; compiled loop / numpy sparse-map oracle):")
    rng = np.random.default_rng(0)
    for scheme, K in ((s, K) for s in SCHEMES for K in (40, 100, 200)):
        grid = Grid(K, 2.0 ** (34 / (K - 1)), v0=1.0)
        t0 = time.perf_counter()
        op = SCHEMES[scheme](grid.x, grid.edges[1:-1])
        setup = time.perf_counter() - t0
        beta = rng.random((K, K))
        beta = beta + beta.T
        nlg = rng.random((3, K))
        n = 2000 if K < 150 else 300
        per = {}
        oracle = partial(pbm_oracle.aggregation_totals, op, m=pbm_oracle.sparse_map(op))
        for label, fn in (("compiled", partial(pbm_oracle.compiled_totals, op)), ("numpy", oracle)):
            fn(beta, nlg)
            best = []
            for _ in range(3):
                t0 = time.perf_counter()
                for _ in range(n):
                    fn(beta, nlg)
                best.append((time.perf_counter() - t0) / n)
            per[label] = min(best)
        print(
            f"  {scheme:12s} K = {K:3d}: {per['compiled'] * 1e6:6.1f} / {per['numpy'] * 1e6:6.1f} us per evaluation "
            f"(min of 3); setup {setup * 1e3:.2f} ms"
        )


if __name__ == "__main__":
    main()
