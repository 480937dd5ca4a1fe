"""Does a strength that rises as granules consolidate turn breakage's cliff into a gradual decline?

Runs the workflow's breakage study (pbmdem.coupling.studies.breakage_study: PBM-ANN with the
ensemble mean of the surrogate and each member, the study's step guard) for the loop's feed at
each speed of --rpm, once per variant:

* ``off``: aggregation only;
* ``n=0``: breakage as configured (one dynamic yield strength Y at every porosity);
* ``n=1``, ``n=2``: Y(eps) = Y [((1 - eps)/eps) / ((1 - eps_ref)/eps_ref)]^n (Rumpf 1962; Iveson
  et al. 2001), the configured Y at eps_ref;
* ``n=2 v*=X``: n = 2 with the Y that puts v* of a fresh granule (eps = eps_ref) at X m/s, for each
  X of --fresh-speeds: Y = rho X^2 / (2 St_def*);
* ``n=0 Y=Z``: one strength Z (Pa) at every porosity, for each Z of --fixed-strengths: the control
  that tells a porosity-dependent strength from a stronger granule (Z = Y [r(eps_min)/r(eps_ref)]^n,
  r = (1 - eps)/eps, is the strength of a fully consolidated granule with exponent n).

Prints final d10/d50/d90 (mm) per speed and variant with the members' d50 range, and writes the
study's rows to --csv. The config is a config file plus overlays (later ones win), e.g. the
breakage run of 2026-12-02:

    PYTHONPATH=src .venv/bin/python benchmarks/bench_porosity_strength.py \\
        --config /work/brkval/config/config.yaml /work/brkval/brk.yaml \\
        --model /work/brkval/results/surrogate/model.skops --fixed-strengths 4e4 1.6e5 --csv /tmp/rows.csv

One process; about 5 s per (speed, variant) with a 5-member ensemble (the study's step guard). Numbers in
docs/pbm.md ("Breakage selection from impacts").

``--quick`` (the suite's smoke test): config/test.yaml, a surrogate trained here in seconds on
synthetic tables (benchmarks/quick.py), two speeds and the variants off, n=0 and n=2.
"""

from __future__ import annotations

import argparse
import logging
import tempfile
from pathlib import Path

import numpy as np

from pbmdem.config import Config, load_yaml
from pbmdem.coupling.studies import BREAKAGE_STUDY_MAX_STEPS, breakage_study

ROOT = Path(__file__).resolve().parents[1]


def merged(base: dict, overlay: dict) -> dict:
    """``base`` with ``overlay``'s keys, mappings merged key by key (as Snakemake's --configfile)."""
    out = dict(base)
    for key, value in overlay.items():
        both = isinstance(value, dict) and isinstance(base.get(key), dict)
        out[key] = merged(base[key], value) if both else value
    return out


def variants(pbm, fresh_speeds, fixed_strengths=()) -> dict:
    brk = pbm.breakage.replace(enabled=True)
    out = {
        "off": pbm.breakage.replace(enabled=False),
        "n=0": brk,
        "n=1": brk.replace(strength_porosity_exponent=1.0),
        "n=2": brk.replace(strength_porosity_exponent=2.0),
    }
    rho = pbm.aggregation.success.stokes.granule_density
    for v in fresh_speeds:
        y = rho * v * v / (2.0 * brk.critical_stokes)
        out[f"n=2 v*={v:g}"] = brk.replace(strength_porosity_exponent=2.0, yield_strength=y)
    for y in fixed_strengths:
        out[f"n=0 Y={y:g}"] = brk.replace(yield_strength=y)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", nargs="+", default=[str(ROOT / "config" / "config.yaml")], help="config and overlays")
    ap.add_argument("--model", help="trained surrogate (model.skops); required unless --quick")
    ap.add_argument("--rpm", nargs="+", type=float, default=[150, 300, 450, 600, 750, 900, 1050, 1200])
    ap.add_argument("--fresh-speeds", nargs="*", type=float, default=[1.0, 2.0], help="v* (m/s) at eps_ref, n = 2")
    ap.add_argument("--fixed-strengths", nargs="*", type=float, default=[], help="Y (Pa) of n = 0 controls")
    ap.add_argument("--only", nargs="*", help="run only these variants (names as printed)")
    ap.add_argument("--csv", help="write the study's rows here")
    ap.add_argument("--quick", action="store_true", help="tiny config, quick surrogate, 2 speeds (smoke test)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    if args.model is None and not args.quick:
        ap.error("--model is required (or --quick)")
    with tempfile.TemporaryDirectory() as tmp:
        if args.quick:
            import quick

            args.config, args.rpm, args.only = [str(quick.TEST_CONFIG)], [600.0, 1200.0], ["off", "n=0", "n=2"]
            args.model = str(quick.timed_surrogate(tmp)[0])
        study(args)


def study(args) -> None:
    """Run the variants of ``args`` and print the final sizes."""
    data = {}
    for path in args.config:
        data = merged(data, load_yaml(path))
    cfg = Config.from_mapping(data)
    loop = cfg.coupled_loop()
    chosen = variants(loop.batch.pbm, args.fresh_speeds, args.fixed_strengths)
    if args.only:
        chosen = {k: v for k, v in chosen.items() if k in args.only}
    print(f"feed {loop.batch.distribution}, step guard {BREAKAGE_STUDY_MAX_STEPS}")
    for name, brk in chosen.items():
        print(
            f"  {name}: enabled={brk.enabled} Y={brk.yield_strength:g} Pa St_def*={brk.critical_stokes:g} "
            f"spread={brk.strength_spread:g} n={brk.strength_porosity_exponent:g} eps_ref={brk.reference_porosity:g}"
        )
    frame = breakage_study(loop, args.model, args.rpm, cfg.grid.speeds(), chosen)
    if args.csv:
        frame.to_csv(args.csv, index=False)
    mm = 1e3
    print(f"\n{'variant':<12} {'rpm':>6} {'d10':>6} {'d50':>6} {'d90':>6}  {'d50 members':>13} {'failed':>6} {'v*':>5}")
    for _, r in frame.iterrows():
        members = f"{mm * r.d50_member_min:.2f}-{mm * r.d50_member_max:.2f}"
        print(
            f"{r.variant:<12} {r.rpm:>6g} {mm * r.d10:>6.2f} {mm * r.d50:>6.2f} {mm * r.d90:>6.2f}  {members:>13} "
            f"{int(r.members_failed) + int(bool(r.mean_failed)):>3}/{int(r.members) + 1} "
            f"{r.critical_speed if np.isfinite(r.critical_speed) else float('nan'):>5.2f}"
        )


if __name__ == "__main__":
    main()
