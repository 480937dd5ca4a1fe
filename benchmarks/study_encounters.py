"""Sensitivity study of the encounter count (prints figures, asserts nothing).

For one operating point of a configuration (default: config/config.yaml, its lowest and highest
grid speed, feed `fine`) and a few replicates, it runs LIGGGHTS and reports:

* snapshot interval: contact and position snapshots at half the automatic intervals, counted
  with every snapshot (h/2) and with every second one (h) on the same trajectory;
* stiffness: Young's modulus as configured and 10x higher (a numerical choice that must not
  change an impact count), raw new contacts against encounters;
* history: encounters found within 1/8, 1/4, 1/2 and all of the position history before the
  window (the count must converge with history length);
* flow development: encounters in the first and second halves of the sampling window.

    .venv/bin/python benchmarks/study_encounters.py [--config FILE] [--rpm R ...] [--replicates N] [--quick]

``--quick`` (the suite's smoke test, about 20 s): config/test.yaml, feed `small`, 600 rpm, 2 replicates.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from pbmdem.config import load_config  # noqa: E402
from pbmdem.dem import collisions  # noqa: E402
from pbmdem.dem.plan import plan_point  # noqa: E402
from pbmdem.dem.run import run_point  # noqa: E402


def run(cfg, point, rpm, replicate, workdir, keep=True):
    point = point.replace(dem=point.dem.replace(keep_contact_dumps=keep))
    plan = plan_point(point, rpm, replicate=replicate)
    t0 = time.perf_counter()
    summary = run_point(plan, workdir, cfg.dem_execution.replace(timeout=7200.0))
    summary["study_wall_time_s"] = time.perf_counter() - t0
    return plan, summary


def mean_se(values):
    v = np.asarray(values, float)
    return v.mean(), (v.std(ddof=1) / np.sqrt(len(v)) if len(v) > 1 else float("nan"))


def fmt(values):
    m, se = mean_se(values)
    return f"{m:9.1f} +- {se:6.1f}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "config" / "config.yaml"))
    ap.add_argument("--distribution", default="fine")
    ap.add_argument("--rpm", type=float, nargs="*")
    ap.add_argument("--replicates", type=int, default=3)
    ap.add_argument("--json", help="write the figures to this file too")
    ap.add_argument("--quick", action="store_true", help="the tiny test config, one speed, 2 replicates (smoke test)")
    args = ap.parse_args(argv)
    if args.quick:
        args.config, args.distribution, args.rpm = str(ROOT / "config" / "test.yaml"), "small", [600.0]
        args.replicates = 2
    cfg = load_config(args.config)
    speeds = args.rpm or [min(cfg.grid.impeller_rpm), max(cfg.grid.impeller_rpm)]
    point = cfg.dem_point(args.distribution)
    results = {}
    for rpm in speeds:
        res = results.setdefault(f"{rpm:g}", {})
        with tempfile.TemporaryDirectory() as tmp:
            base_raw, base_enc, halves, history, fine, coarse, stiff_raw, stiff_enc = ([] for _ in range(8))
            for rep in range(args.replicates):
                plan, s = run(cfg, point, rpm, rep, Path(tmp) / f"base{rep}", keep=False)
                base_raw.append(s["collisions_every_snapshot"])
                base_enc.append(s["encounters_every_snapshot"])
                halves.append((s["encounters_first_half"], s["encounters_second_half"]))
                history.append([s[f"encounters_history_{f:g}"] for f in (0.125, 0.25, 0.5, 1.0)])
                print(
                    f"[{rpm:g} rpm rep {rep}] {plan.n_particles} particles, {s['study_wall_time_s']:.0f} s, "
                    f"raw {base_raw[-1]}, encounters {base_enc[-1]}",
                    flush=True,
                )
                # half intervals on the same seed: every snapshot = h/2, every second = h
                half = point.replace(dem=point.dem.replace(collision_interval=max(1, plan.collision_interval // 2)))
                plan_h, _ = run(cfg, half, rpm, rep, Path(tmp) / f"half{rep}")
                analysis = collisions.RunAnalysis(Path(tmp) / f"half{rep}" / "post", plan_h)
                fine.append(int(analysis.pair_events(stride=1)[0].encounter.sum()))
                coarse.append(int(analysis.pair_events(stride=2)[0].encounter.sum()))
                stiff = point.replace(
                    material=point.material.replace(youngs_modulus=10.0 * point.material.youngs_modulus)
                )
                _, s10 = run(cfg, stiff, rpm, rep, Path(tmp) / f"stiff{rep}", keep=False)
                stiff_raw.append(s10["collisions_every_snapshot"])
                stiff_enc.append(s10["encounters_every_snapshot"])
        rel = lambda a, b: (np.mean(b) - np.mean(a)) / np.mean(a)  # noqa: E731
        res.update(
            {
                "particles": plan.n_particles,
                "sampling_time_s": plan.sampling_time,
                "raw": base_raw,
                "encounters": base_enc,
                "interval_fine_h2": fine,
                "interval_coarse_h": coarse,
                "interval_change_h_vs_h2": float(np.mean([(c - f) / f for f, c in zip(fine, coarse)])),
                "stiff10_raw": stiff_raw,
                "stiff10_encounters": stiff_enc,
                "stiffness_change_raw": rel(base_raw, stiff_raw),
                "stiffness_change_encounters": rel(base_enc, stiff_enc),
                "history_fractions": [0.125, 0.25, 0.5, 1.0],
                "history_counts_mean": np.mean(history, axis=0).tolist(),
                "halves": halves,
            }
        )
        h = np.asarray(halves, float)
        diff = h[:, 1] / h[:, 0] - 1.0
        res["half_difference_mean"], res["half_difference_se"] = mean_se(diff)
        print(
            f"\n== {args.distribution} at {rpm:g} rpm, {args.replicates} replicates, {plan.n_particles} particles, "
            f"window {plan.sampling_time:.3f} s"
        )
        print(
            f"  raw new contacts          {fmt(base_raw)}   E x10: {fmt(stiff_raw)}  "
            f"change {res['stiffness_change_raw']:+.1%}"
        )
        print(
            f"  encounters                {fmt(base_enc)}   E x10: {fmt(stiff_enc)}  "
            f"change {res['stiffness_change_encounters']:+.1%}"
        )
        print(
            f"  snapshot interval h/2 -> h: encounters {fmt(fine)} -> {fmt(coarse)} "
            f"(change {res['interval_change_h_vs_h2']:+.2%})"
        )
        print(
            "  history (fraction of dem.history_time): "
            + ", ".join(f"{f:g}: {c:.0f}" for f, c in zip(res["history_fractions"], res["history_counts_mean"]))
        )
        print(
            f"  second/first half of the window - 1: {res['half_difference_mean']:+.1%} "
            f"+- {res['half_difference_se']:.1%}",
            flush=True,
        )
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1, default=float))


if __name__ == "__main__":
    main()
