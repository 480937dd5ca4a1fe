"""Where the pair encounter frequency misses the PBM-DEM loops' own samples, and features that target it.

The pair frequency's Kriging model (the family `auto` chose) is refitted on a finished run's grid
table (``results/dem/collisions.csv`` and ``impact_velocity.csv``, as rule ``train_surrogate``
builds the training data: ``surrogate:`` settings of ``--config``) in a few variants, each scored

* held out, on the workflow's grouped folds (``surrogate.cv``): MAE of log10 c pooled over every
  run and on the active-learning runs (``grid.extra_points``), and
* on the distinct samples of the run's PBM-DEM loops (``results/validation/rpm*/pbm_dem/rep*/
  intervals.csv``, as rule ``pair_samples`` reads them, :mod:`pbmdem.validation.pair_samples`):
  mean error and MAE of log10(model / DEM) per speed, and by the structure of the pair (classes in
  the sample, number fraction of the smaller class, its size relative to the sample's Sauter mean).

Variants (only the frequency model changes; offset, transform and kernel are the settings'):
``today`` the features of :data:`pbmdem.surrogate.features.FEATURE_NAMES`; ``norel`` without
``rel_small`` and ``rel_large`` (each class's size relative to its run's Sauter mean diameter: the
six features before 2026-12-06); ``ratio`` + the size ratio d_small / d_large; ``nooffset`` without
the cross-section offset (``physics_offset: none``).

``--replay``: PBM-ANN replayed in memory on each speed's stored loop settings (rep0's
loop_inputs.json; mean prediction, as ``bench_replay.py``'s "all surrogate") with the stored
surrogate, and with its pair speed law refitted from ``--law-from`` m/s up (the response surface on
every grid row, ``surrogate.speed_law_from``); final d10 / d50 / d90 beside the PBM-DEM loops' range.

Run: .venv/bin/python benchmarks/bench_pair_features.py --results <copy of results> [--rpm 300 750 900 1200]
     [--variants today norel ratio nooffset] [--replay] [--law-from 1.0]
Measured numbers: docs/validation.md, "Features for the pair frequency on the loops' samples".

``--quick`` (the suite's smoke test, no LIGGGHTS): the synthetic stored loops of ``bench_replay.py
--quick`` (1200 rpm, tiny config; its synthetic grid tables), variants ``today`` and ``norel``, and the
replay with the law from 0.1 m/s.
"""

from __future__ import annotations

import argparse
import copy
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.base import clone

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_replay import QUANTILES, final_sizes, quick_results, stored_loop  # noqa: E402

#: variant -> (extra features, physics offset; None: the settings')
VARIANTS = {"today": ("none", None), "norel": ("norel", None), "ratio": ("ratio", None), "nooffset": ("none", "none")}


def with_extra(F: pd.DataFrame, kind: str) -> pd.DataFrame:
    """The feature frame ``F`` with the variant's columns."""
    F = F.copy()
    if kind == "ratio":
        F["ratio"] = F["d_small"] / F["d_large"]
    elif kind == "norel":
        F = F.drop(columns=["rel_small", "rel_large"])
    return F


def loop_frames(results: Path, rpms) -> list:
    """(sample, its pair table with a point_id) of every distinct loop sample of ``rpms``."""
    from pbmdem.surrogate.features import pair_table
    from pbmdem.validation.pair_samples import loop_samples

    out = []
    for rpm in rpms:
        reps = len(list((results / "validation" / f"rpm{rpm}" / "pbm_dem").glob("rep*")))
        for s in loop_samples(results / "validation", [rpm], reps):
            frame, _, _ = pair_table(s.diameters, s.counts, s.rpm)
            frame["point_id"] = f"sample{len(out)}"
            out.append((s, frame))
    return out


def sample_rows(model, kind: str, frames, radius: float) -> pd.DataFrame:
    """log10(model / DEM) of every pair with DEM encounters of every loop sample, with the pair's structure."""
    from pbmdem.surrogate.features import make_features, sauter_diameter

    rows = []
    for k, (s, frame) in enumerate(frames):
        F = with_extra(make_features(frame, radius), kind)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            c = 10.0 ** model.predict(F, check_domain=False)
        d32 = sauter_diameter(s.diameters, s.counts)
        ok = s.frequencies > 0
        rows.append(
            pd.DataFrame(
                {
                    "rpm": s.rpm,
                    "sample": k,
                    "classes": len(s.diameters),
                    "frac_small": F["frac_small"].to_numpy()[ok],
                    "rel_small": F["d_small"].to_numpy()[ok] / d32,
                    "ratio": (F["d_small"] / F["d_large"]).to_numpy()[ok],
                    "error": np.log10(c[ok] / s.frequencies[ok]),
                }
            )
        )
    return pd.concat(rows, ignore_index=True)


def variant(name: str, data, frames, settings: dict, radius: float, pbm_samples) -> tuple[dict, pd.DataFrame, object]:
    """Held-out and loop-sample scores of one variant, its loop-sample rows and its model fitted on every run."""
    from pbmdem.surrogate.ensemble import grouped_splits
    from pbmdem.surrogate.settings import build_surrogate

    kind, offset = VARIANTS[name]
    model = build_surrogate(settings, radius, family="kriging").set_params(velocity_model=None)
    if offset is not None:
        model.set_params(physics_offset=offset)
    X, y, g = with_extra(data.X, kind), data.y, data.groups
    pred = np.full(len(y), np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for train, test in grouped_splits(g, settings["cv"]["strategy"], settings["cv"]["n_splits"]):
            pred[test] = clone(model).fit(X.iloc[train], y[train], groups=g[train]).predict(X.iloc[test])
        fitted = clone(model).fit(X, y, groups=g)
    al = np.isin(g, list(pbm_samples))
    err = pred - y
    rows = sample_rows(fitted, kind, frames, radius)
    scores = {
        "variant": name,
        "held_out_mae": float(np.mean(np.abs(err))),
        "held_out_mae_al": float(np.mean(np.abs(err[al]))) if al.any() else float("nan"),
        "loop_mean": float(rows["error"].mean()),
        "loop_mae": float(rows["error"].abs().mean()),
    }
    for rpm, sub in rows.groupby("rpm"):
        scores[f"{rpm:g}"] = f"{sub['error'].mean():+.3f} / {sub['error'].abs().mean():.3f}"
    return scores, rows.assign(variant=name), fitted


def structure(rows: pd.DataFrame) -> pd.DataFrame:
    """Mean / MAE of the loop-sample error by the pair's structure, one column per variant."""
    cuts = {
        "classes in the sample": rows["classes"].astype(str),
        "frac_small": pd.cut(rows["frac_small"], [0, 0.15, 0.2, 0.3, 1.0]).astype(str),
        "d_small / d32": pd.cut(rows["rel_small"], [0, 0.5, 0.7, 0.9, 1.0, 10.0]).astype(str),
        "d_small / d_large": pd.cut(rows["ratio"], [0, 0.5, 0.7, 0.9, 0.999, 1.0]).astype(str),
    }
    out = []
    for what, key in cuts.items():
        for (value, name), sub in rows.groupby([key, rows["variant"]], sort=True):
            e = sub["error"]
            out.append({"by": what, "bin": value, "variant": name, "pairs": len(e),
                        "cell": f"{e.mean():+.3f} / {e.abs().mean():.3f}"})  # fmt: skip
    table = pd.DataFrame(out).pivot_table(
        index=["by", "bin", "pairs"], columns="variant", values="cell", aggfunc="first"
    )
    return table[[v for v in VARIANTS if v in table.columns]]


def replay(results: Path, rpms, models: dict) -> None:
    """PBM-ANN of every model on each speed's stored loop settings, beside the PBM-DEM loops' range."""
    from pbmdem.coupling.loop import run_loop
    from pbmdem.coupling.providers import SurrogateProvider, surrogate_needs

    print("\nPBM-ANN replayed (final d10 / d50 / d90, mm)")
    for rpm in rpms:
        reps = sorted((results / "validation" / f"rpm{rpm}" / "pbm_dem").glob("rep*"))
        dem = pd.DataFrame([final_sizes(r / "summary.csv") for r in reps])
        print(f"rpm {rpm}: PBM-DEM range " + " / ".join(f"{dem[q].min():.2f}-{dem[q].max():.2f}" for q in QUANTILES))
        loop = stored_loop(reps[0])
        for name, model in models.items():
            provider = SurrogateProvider(model, float(rpm), log_each=False, needs=surrogate_needs(loop.batch.pbm))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                last = run_loop(loop, provider, float(rpm), None).result.summary().iloc[-1]
            print(f"  {name:<34}" + " / ".join(f"{1e3 * float(last[q]):.2f}" for q in QUANTILES))


def law_from(stored, data_args, settings: dict, radius: float, speed: float):
    """A copy of ``stored`` with its pair speed law refitted from ``speed`` m/s up (response surface,
    every grid row)."""
    from pbmdem.surrogate.features import training_data
    from pbmdem.surrogate.settings import build_surrogate

    table, velocities = data_args
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = training_data(table, radius, settings["zero_collisions"], velocity_table=velocities,
                          speed_law=settings["speed_law"], speed_law_from=speed)  # fmt: skip
        rsm = build_surrogate({**settings, "speed_law_from": speed}, radius, family="rsm")
        rsm.fit(d.X, d.y, groups=d.groups, velocity=d.velocity)
    model = copy.deepcopy(stored)
    model.velocity_model_ = rsm.velocity_model_
    return model


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--results", type=Path, help="a finished run's results folder (a copy)")
    parser.add_argument("--config", type=Path, default=ROOT / "config" / "config.yaml", help="its configuration")
    parser.add_argument("--rpm", nargs="+", default=["300", "750", "900", "1200"], help="validation speeds")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--replay", action="store_true", help="also replay PBM-ANN with the speed law from --law-from")
    parser.add_argument("--law-from", type=float, default=1.0, help="the replay's refitted speed law from (m/s)")
    parser.add_argument("--quick", action="store_true", help="synthetic stored loops, seconds (the suite's smoke test)")
    args = parser.parse_args(argv)
    from pbmdem.config import load_config, point_id
    from pbmdem.surrogate import load_surrogate
    from pbmdem.surrogate.features import training_data

    with tempfile.TemporaryDirectory() as tmp:
        if args.quick:
            import quick

            args.results, args.rpm, args.variants = quick_results(Path(tmp)), ["1200"], ["today", "norel"]
            args.replay, args.law_from, cfg, tables = True, 0.1, quick.config(), Path(tmp) / "results/surrogate/dem"
        else:
            if args.results is None:
                parser.error("give --results (or --quick)")
            cfg, tables = load_config(args.config), args.results / "dem"
        training = cfg.surrogate_training()
        settings, radius = training.surrogate.to_dict(), training.granulator.impeller.tip_radius
        pbm_samples = [point_id(p.rpm, p.distribution) for p in cfg.grid.extra_points]
        table, velocities = pd.read_csv(tables / "collisions.csv"), pd.read_csv(tables / "impact_velocity.csv")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            law, law_from_ = settings["speed_law"], settings.get("speed_law_from")
            data = training_data(table, radius, settings["zero_collisions"], velocity_table=velocities,
                                 speed_law=law, speed_law_from=law_from_)  # fmt: skip
        frames = loop_frames(args.results, args.rpm)
        scores, rows, fitted = [], [], {}
        for name in args.variants:
            s, r, fitted[name] = variant(name, data, frames, settings, radius, pbm_samples)
            scores.append(s)
            rows.append(r)
        print(f"pair frequency (Kriging) per variant: held-out MAE (pooled, on the {len(pbm_samples)} active-learning "
              f"runs) and on the {len(frames)} loop samples (mean error / MAE per speed), decades")  # fmt: skip
        print(pd.DataFrame(scores).to_string(index=False, float_format=lambda x: f"{x:+.3f}"))
        print("\nloop-sample error by the pair's structure (mean / MAE, decades)")
        print(structure(pd.concat(rows, ignore_index=True)).to_string())
        if args.replay:
            stored = load_surrogate(args.results / "surrogate" / "model.skops")
            from_law = law_from(stored, (table, velocities), settings, radius, args.law_from)
            replay(args.results, args.rpm, {"stored": stored, f"law from {args.law_from:g} m/s": from_law})


if __name__ == "__main__":
    main()
