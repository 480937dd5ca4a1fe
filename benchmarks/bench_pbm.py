"""PBM benchmark (prints figures, no assertions): the default granulation run (all processes,
35 bins, whole process time), the same with 100 bins and with the fixed pivot scheme, and the time
per aggregation-rate evaluation of both schemes. Run: .venv/bin/python benchmarks/bench_pbm.py
(accuracy against analytical solutions: benchmarks/bench_pbm_accuracy.py)"""

from __future__ import annotations

import copy
import time
from pathlib import Path

import numpy as np

from pbmdem.config import load_config
from pbmdem.pbm import SCHEMES, Grid, run_pbm
from pbmdem.pbm.settings import process_times, resolve_settings

ROOT = Path(__file__).resolve().parents[1]


def best_of(fn, repeat=3):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main():
    cfg = load_config(ROOT / "config" / "config.yaml")
    settings = resolve_settings(cfg)
    t_end = process_times(settings)[2]
    print(f"default granulation run ({t_end:g} s of process, constant c_ij, 600 rpm, 'fine'):")
    for bins, ratio, scheme in ((35, 2.0, "cell_average"), (100, 2.0 ** (34 / 99), "cell_average"),
                                (35, 2.0, "fixed_pivot")):
        c = copy.deepcopy(cfg)
        c["pbm"] = {"grid": {"bins": bins, "ratio": ratio}, "aggregation": {"scheme": scheme}}
        wall, res = best_of(lambda: run_pbm(c, None, 600, "fine"))
        s = res.summary()
        print(f"  {scheme:12s} {bins:3d} bins (ratio {ratio:.4f}): wall {wall * 1e3:7.1f} ms, {res.info['steps']} steps, "
              f"{wall / res.info['steps'] * 1e6:6.1f} us/step, d50 {s.d50.iloc[0] * 1e3:.2f} -> "
              f"{s.d50.iloc[-1] * 1e3:.2f} mm, number-mean d x{s.number_mean_diameter.iloc[-1] / s.number_mean_diameter.iloc[0]:.2f}")
    print("aggregation-rate evaluation (full (K,K) kernel):")
    rng = np.random.default_rng(0)
    for scheme, K in ((s, K) for s in SCHEMES for K in (35, 100, 200)):
        g = Grid(K, 2.0, v0=1.0)
        t0 = time.perf_counter()
        op = SCHEMES[scheme](g.x, g.edges[1:-1])
        setup = time.perf_counter() - t0
        beta = rng.random((K, K))
        beta = beta + beta.T
        N, l, gas = rng.random(K), rng.random(K), rng.random(K)
        n = 2000 if K < 150 else 500
        t0 = time.perf_counter()
        for _ in range(n):
            op.rates(beta, N, l, gas)
        per = (time.perf_counter() - t0) / n
        print(f"  {scheme:12s} K = {K:3d}: {per * 1e6:7.1f} us per evaluation ({K * (K + 1) // 2} pairs); "
              f"operator setup {setup * 1e3:.2f} ms")


if __name__ == "__main__":
    main()
