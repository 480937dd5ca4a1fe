"""The fast tail of the impact speeds that breakage counts: DEM tables against the surrogate, held out.

Breakage from impacts (pbmdem.pbm.impact_breakage) needs, per size class i and kind of impact k
(granule pairs, impeller, bowl), the fraction P_ik of impacts faster than the critical speed v* and
the breaking-impact rate per granule S_ik (1/s; pairs: sum_j c_ij (N_j - delta_ij) P_ij; walls:
f_wi P_wi). For every grid point of the DEM tables and v* in --speeds this prints how far three
estimates of P_ik and S_ik lie from the DEM's own (|log10(estimate / DEM)| where the DEM's is > 0):

* ``law fit``: the DEM's own frequencies with each row's bins replaced by the speed law fitted to
  those bins (no learning): the law's misfit alone;
* ``held out``: the surrogate's prediction for the point's classes (``impacts(d, n, rpm)``, the call
  PBM-ANN makes) when the point's run was held out: a family fitted on the other runs of the
  surrogate package's grouped folds (surrogate.cv, whole runs; pairs and walls on the same folds);
* ``in sample`` (with --model): a trained surrogate file, e.g. the default run's (the one PBM-ANN uses);
* ``noise floor`` (--floor draws): the DEM's own rates scored against DEM samples redrawn from its
  counts (every bin Poisson(count)): what a model that knew each row's true law would score against a
  DEM of this sampling. Column ``dem>0_few`` counts the scored rows whose DEM value rests on fewer than
  5 impacts above v*: there the DEM's own Poisson noise is 0.2 decades or more and the median is
  set by a handful of impacts (docs/measurements.md, "Breakage: the speed law's fast tail").

Where the DEM's value is 0 (no impact that fast recorded) the estimate cannot be scored on a log
scale: the count of such rows with an estimate > 0 is printed, and how many of them exceed the
detection limit 3 / (impacts sampled) (the 95 % upper bound of a rate with zero events): an
estimate above it is contradicted by the DEM's zero.

Run: .venv/bin/python benchmarks/bench_breakage_tail.py --tables results/dem
     [--config config/config.yaml] [--laws lognormal gengamma] [--family mlp] [--speeds 1 2 4]
     [--spread 0 0.5] [--model results/surrogate/model.skops] [--no-held-out] [--csv rows.csv]
     [--rpm 600 1200] [--law-from 1.0]
(--spread: pbm.breakage.strength_spread values to score, 0 the sharp criterion; --rpm: score only
the grid points of speeds in [lo, hi] rpm, the fits still on every run of the folds.) About 1 min per
law (fits and held-out MLP or Kriging) on the default grid (12 runs, 5 folds) on one core; measured
numbers in docs/measurements.md ("Breakage: the speed law's fast tail").

``--quick`` (the suite's smoke test): synthetic grid tables with known laws for the tiny
config/test.yaml (benchmarks/quick.py: 6 runs, 3 classes), its speed law, v* = 0.25 and 0.5 m/s
(its tip speeds are 0.4-1.7 m/s), spreads 0 and 0.5, and a surrogate trained here on the same
tables for the in-sample row; tables and model in a temporary folder.
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
KINDS = ("pairs", "impeller", "bowl")
#: a DEM rate counted from fewer impacts above v* than this is mostly its sampling noise (``dem>0_few``)
FEW_IMPACTS = 5
#: kind -> held-out total-variation distances of the last held_out_points call
TV: dict = {}


# ----------------------------------------------------------------------------- the DEM's own rates
def point_classes(pairs: pd.DataFrame, point: str) -> tuple[np.ndarray, np.ndarray, float]:
    """(diameters, numbers, rpm) of the classes of one grid point (classes sorted by index)."""
    from pbmdem.surrogate.features import run_classes

    rows = pairs[pairs["point_id"].astype(str) == point]
    classes = run_classes(rows)
    return classes["d"].to_numpy(float), classes["n"].to_numpy(float), float(rows["rpm"].iloc[0])


def dem_point(tables: dict, point: str, law: str | None = None, law_from: float | None = None) -> dict:
    """The DEM's impacts of one point as ``pbmdem.impact.ImpactRates`` plus the impacts sampled.

    Returns {"d", "n", "rpm", "rates", "sampled": {kind: (K,) impacts sampled per class, all replicates},
    "counts": (pair counts (K, K, bins), wall counts (walls, K, bins)), summed over the replicates};
    with ``law`` every row's bin fractions are replaced by the law fitted to its bins
    (:func:`pbmdem.surrogate.velocity.fit_speed_law`)."""
    from pbmdem.impact import N_VELOCITY_BINS, WALLS, EncounterRates, ImpactRates, WallRates, binned_counts
    from pbmdem.surrogate.velocity import fit_speed_law, speed_fractions

    def fractions(counts: np.ndarray) -> np.ndarray:
        out = np.zeros_like(counts)
        ok = counts.sum(axis=1) > 0
        if ok.any():
            out[ok] = counts[ok] / counts[ok].sum(axis=1, keepdims=True)
            if law is not None:
                mu, sigma, *shape = fit_speed_law(counts[ok], law, law_from)
                out[ok] = speed_fractions(mu, sigma, law, shape[0] if shape else None)
        return out

    d, n, rpm = point_classes(tables["pairs"], point)
    K = d.size
    rows = tables["pairs"][tables["pairs"]["point_id"].astype(str) == point]
    reps = float(rows["n_replicates"].iloc[0]) if "n_replicates" in rows else 1.0
    c = np.zeros((K, K))
    i, j = rows["class_i"].to_numpy(int), rows["class_j"].to_numpy(int)
    f = np.nan_to_num(rows["encounter_frequency_per_pair"].to_numpy(float))
    c[i, j] = c[j, i] = f
    vel = tables["velocities"][tables["velocities"]["point_id"].astype(str) == point]
    counts = np.zeros((K, K, N_VELOCITY_BINS))
    if len(vel):
        keys, binned = binned_counts(vel)
        ki, kj = keys["class_i"].to_numpy(int), keys["class_j"].to_numpy(int)
        counts[ki, kj] = binned
        counts[kj, ki] = binned
    frac = fractions(counts.reshape(K * K, -1)).reshape(K, K, -1)
    sampled = {"pairs": counts.sum(axis=(1, 2)) * reps}
    wf = np.zeros((len(WALLS), K))
    wfrac = np.zeros((len(WALLS), K, N_VELOCITY_BINS))
    wall_counts = np.zeros((len(WALLS), K, N_VELOCITY_BINS))
    walls = tables["walls"][tables["walls"]["point_id"].astype(str) == point]
    wvel = tables["wall_velocities"][tables["wall_velocities"]["point_id"].astype(str) == point]
    for w, wall in enumerate(WALLS):
        rw = walls[walls["wall"].astype(str) == wall]
        wf[w, rw["class_i"].to_numpy(int)] = np.nan_to_num(rw["encounter_frequency_per_particle"].to_numpy(float))
        vw = wvel[wvel["wall"].astype(str) == wall]
        wc = np.zeros((K, N_VELOCITY_BINS))
        if len(vw):
            keys, binned = binned_counts(vw.assign(class_j=vw["class_i"]))
            wc[keys["class_i"].to_numpy(int)] = binned
        wfrac[w] = fractions(wc)
        wall_counts[w] = wc
        sampled[wall] = wc.sum(axis=1) * reps
    rates = ImpactRates(EncounterRates(c, frac), WallRates(wf, wfrac))
    totals = (counts * reps, wall_counts * reps)  # impacts per bin over all replicates (floor_draw)
    return {"d": d, "n": n, "rpm": rpm, "rates": rates, "sampled": sampled, "counts": totals}


def floor_draw(ref: dict, rng: np.random.Generator) -> dict:
    """The point ``ref`` (:func:`dem_point`) as another DEM sample of the same beds could have
    counted it: every bin's impacts redrawn as Poisson(count) (summed over the replicates), the
    frequencies kept. Scoring the DEM's own rates against such draws gives the noise floor: what
    a model that knew every row's true speed law would score against a DEM of this sampling."""
    from pbmdem.impact import EncounterRates, ImpactRates, WallRates

    def drawn(counts: np.ndarray) -> np.ndarray:
        sim = rng.poisson(np.round(counts)).astype(float)
        total = sim.sum(axis=-1, keepdims=True)
        return np.divide(sim, total, out=np.zeros_like(sim), where=total > 0)

    pairs, walls = ref["counts"]
    frac = drawn(pairs)
    iu, ju = np.triu_indices(pairs.shape[0], 1)
    frac[ju, iu] = frac[iu, ju]  # one draw per class pair, as the DEM's one sample serves both orders
    rates = ref["rates"]
    walls_drawn = WallRates(rates.walls.frequency, drawn(walls), rates.walls.walls)
    return dict(ref, rates=ImpactRates(EncounterRates(rates.pairs.frequency, frac), walls_drawn))


def ingredients(rates, numbers, speed: float, spread: float = 0.0) -> dict:
    """Per kind: (K,) fraction of impacts that break (faster than ``speed`` with ``spread`` 0) and
    (K,) breaking impacts per granule and second (:func:`pbmdem.pbm.impact_breakage.selection_rates`)."""
    from pbmdem.impact import breaking_probability
    from pbmdem.pbm.impact_breakage import selection_rates

    n = np.asarray(numbers, float)
    K = n.size
    breaking = selection_rates(rates, n, speed, spread=spread)
    partners = np.maximum(n[None, :] - np.eye(K), 0.0)
    impacts = {"pairs": (rates.pairs.frequency * partners).sum(axis=1)}
    for wall in rates.walls.walls:
        impacts[wall] = rates.walls.of(wall)[0]
    above = breaking_probability(speed, spread)
    out = {}
    for kind in KINDS:
        rate = breaking[kind]
        if kind == "pairs":
            with np.errstate(invalid="ignore", divide="ignore"):
                frac = np.where(impacts[kind] > 0, rate / impacts[kind], 0.0)
        else:
            frac = rates.walls.of(kind)[1] @ above
        out[kind] = (frac, rate)
    return out


# ----------------------------------------------------------------------------- held-out surrogate
def held_out_points(tables: dict, settings: dict, radius: float, family: str, law: str, law_from=None) -> dict:
    """point -> ImpactRates of the point's classes predicted by ``family`` fitted on the runs of the
    other folds (surrogate.cv's grouped folds over whole runs; walls on the same folds); the law
    fitted to the bins from ``law_from`` m/s up (None: every bin)."""
    from sklearn.base import clone

    from pbmdem.impact import WALLS
    from pbmdem.surrogate.ensemble import grouped_splits
    from pbmdem.surrogate.features import training_data
    from pbmdem.surrogate.settings import build_surrogate
    from pbmdem.surrogate.velocity import bin_counts, empirical_fractions, total_variation
    from pbmdem.surrogate.walls import wall_training_data

    s = {**settings, "speed_law": law}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        data = training_data(
            tables["pairs"], radius, s["zero_collisions"], tables["velocities"], speed_law=law, speed_law_from=law_from
        )
        walls = {
            w: wall_training_data(
                tables["walls"], tables["wall_velocities"], w, radius, s["zero_collisions"], law, law_from
            )
            for w in WALLS
        }
    template = build_surrogate(s, radius, n_jobs=1, family=family)
    out = {}
    for train, test in grouped_splits(data.groups, s["cv"]["strategy"], s["cv"]["n_splits"]):
        train_runs, test_runs = set(data.groups[train]), sorted(set(data.groups[test]))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = clone(template).fit(data.X.iloc[train], data.y[train], groups=data.groups[train],
                                        velocity=data.velocity[train],
                                        velocity_counts=data.velocity_counts[train])  # fmt: skip
            model.wall_models_ = {}
            for w, wd in walls.items():
                rows = np.flatnonzero(np.isin(wd.groups, list(train_runs)))
                model.wall_models_[w] = clone(template).fit(
                    wd.X.iloc[rows],
                    wd.y[rows],
                    groups=wd.groups[rows],
                    velocity=wd.velocity[rows],
                    velocity_counts=wd.velocity_counts[rows],
                )
            for point in test_runs:
                d, n, rpm = point_classes(tables["pairs"], point)
                out[point] = model.impacts(d, n, rpm, check_domain=False)
            # the whole distribution too: total-variation distance of the held-out rows' bin fractions
            for kind, (dd, m) in {
                "pairs": (data, model),
                **{w: (wd, model.wall_models_[w]) for w, wd in walls.items()},
            }.items():
                rows = np.flatnonzero(np.isin(dd.groups, test_runs) & np.isfinite(dd.velocity).all(axis=1))
                observed = empirical_fractions(bin_counts(dd.table.iloc[rows]))
                TV.setdefault(kind, []).extend(
                    total_variation(m.velocity_fractions(dd.X.iloc[rows], check_domain=False), observed)
                )
    return out


# ----------------------------------------------------------------------------- scoring
def rows_of(points: list, dem: dict, estimates: dict, speeds, source: str, spread: float = 0.0) -> list[dict]:
    """One row per (point, class, kind, v*) with the DEM's and the estimate's fraction and rate."""
    rows = []
    for point in points:
        ref, est = dem[point], estimates[point]
        for speed in speeds:
            a, b = ingredients(ref["rates"], ref["n"], speed, spread), ingredients(est, ref["n"], speed, spread)
            for kind in KINDS:
                for k in range(ref["n"].size):
                    rows.append(
                        {
                            "source": source,
                            "spread": spread,
                            "point_id": point,
                            "rpm": ref["rpm"],
                            "class": k,
                            "d": ref["d"][k],
                            "kind": kind,
                            "v_star": speed,
                            "sampled": ref["sampled"][kind][k],
                            "dem_fraction": a[kind][0][k],
                            "est_fraction": b[kind][0][k],
                            "dem_rate": a[kind][1][k],
                            "est_rate": b[kind][1][k],
                        }
                    )
    return rows


def scored(points, dem, estimates, speeds, source: str, spreads) -> list[dict]:
    """:func:`rows_of` for every spread of ``spreads`` (the source named with the spread if several)."""
    rows = []
    for spread in spreads:
        name = source if len(spreads) == 1 else f"{source} s={spread:g}"
        rows += rows_of(points, dem, estimates, speeds, name, spread)
    return rows


def score(frame: pd.DataFrame) -> pd.DataFrame:
    """Per source, kind and v*: median and 90th percentile of |log10(est / DEM)| of the fraction
    and the rate where the DEM's is > 0, the rows where it is 0 and the estimate > 0, and of those
    the rows whose estimated fraction exceeds the detection limit 3 / impacts sampled."""
    out = []
    for (source, kind, v), g in frame.groupby(["source", "kind", "v_star"], sort=False):
        rec = {"source": source, "kind": kind, "v_star": v}
        for what in ("fraction", "rate"):
            dem, est = g[f"dem_{what}"].to_numpy(float), g[f"est_{what}"].to_numpy(float)
            pos = dem > 0
            with np.errstate(divide="ignore"):
                err = np.abs(np.log10(np.maximum(est[pos], 1e-300) / dem[pos]))
                bias = np.log10(np.maximum(est[pos], 1e-300) / dem[pos])
            rec[f"{what}_n"] = int(pos.sum())
            rec[f"{what}_med"] = float(np.median(err)) if pos.any() else np.nan
            rec[f"{what}_p90"] = float(np.quantile(err, 0.9)) if pos.any() else np.nan
            rec[f"{what}_bias"] = float(np.median(bias)) if pos.any() else np.nan
        # rows whose DEM value rests on fewer than 5 impacts above v* (Poisson noise alone >= 0.2 decades)
        counted = g["sampled"].to_numpy(float) * g["dem_fraction"].to_numpy(float)
        rec["dem>0_few"] = int(((counted > 0) & (counted < FEW_IMPACTS - 1e-9)).sum())
        zero = g["dem_fraction"].to_numpy(float) <= 0
        est_f = g["est_fraction"].to_numpy(float)
        limit = 3.0 / np.maximum(g["sampled"].to_numpy(float), 1e-300)
        rec["dem0"] = int(zero.sum())
        rec["dem0_est>0"] = int((zero & (est_f > 0)).sum())
        rec["dem0_est>3/N"] = int((zero & (est_f > limit)).sum())
        out.append(rec)
    return pd.DataFrame(out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tables", type=Path, default=ROOT / "results" / "dem")
    parser.add_argument("--config", type=Path, default=ROOT / "config" / "config.yaml")
    parser.add_argument("--laws", nargs="+", default=["lognormal", "gengamma"])
    parser.add_argument(
        "--family",
        default="mlp",
        help="surrogate family of the held-out fits (mlp: the default run's choice on 2026-12-02)",
    )
    parser.add_argument("--speeds", nargs="+", type=float, default=[1.0, 2.0, 4.0])
    parser.add_argument(
        "--spread",
        nargs="+",
        type=float,
        default=[0.0],
        help="std of ln Y across granules (pbm.breakage.strength_spread; 0: sharp); each one scored",
    )
    parser.add_argument("--model", type=Path, default=None, help="a trained surrogate: also its in-sample error")
    parser.add_argument("--no-held-out", action="store_true", help="only the law fits (and --model)")
    parser.add_argument("--csv", type=Path, default=None, help="write every row (point, class, kind, v*, source)")
    parser.add_argument(
        "--rpm", nargs=2, type=float, default=None, metavar=("LO", "HI"), help="score the points of lo-hi rpm only"
    )
    parser.add_argument(
        "--law-from",
        type=float,
        default=None,
        help="fit the laws to the bins from this speed (m/s, a bin edge) up, as surrogate.speed_law_from",
    )
    parser.add_argument(
        "--floor",
        type=int,
        default=20,
        help="redrawn DEM samples for the noise floor (the error of a model that knew each row's true law; 0: none)",
    )
    parser.add_argument("--quick", action="store_true", help="synthetic tables, tiny config (smoke test)")
    args = parser.parse_args(argv)
    from pbmdem.surrogate._threads import single_threaded

    # one BLAS thread: the speed-law fits (an L-BFGS-B per row) ran 3x slower with two on a busy machine
    with tempfile.TemporaryDirectory() as tmp, single_threaded():
        if args.quick:
            import quick

            cfg = quick.config()
            args.config, args.tables = quick.TEST_CONFIG, quick.dem_tables(Path(tmp) / "dem", cfg)
            args.laws, args.speeds, args.spread = [cfg.surrogate.speed_law], [0.25, 0.5], [0.0, 0.5]
            args.model = quick.surrogate(tmp, cfg, tables=args.tables)
        return report(args)


def report(args) -> int:
    """Score the estimates of ``args`` against the DEM's tables and print the tables."""
    from pbmdem.config import load_config
    from pbmdem.tables import GRID_PAIRS, GRID_VELOCITIES, GRID_WALL_VELOCITIES, GRID_WALLS

    cfg = load_config(args.config)
    settings, radius = cfg.surrogate.to_dict(), cfg.granulator.impeller.tip_radius
    tables = {
        "pairs": GRID_PAIRS.read(args.tables / "collisions.csv"),
        "velocities": GRID_VELOCITIES.read(args.tables / "impact_velocity.csv"),
        "walls": GRID_WALLS.read(args.tables / "wall_collisions.csv"),
        "wall_velocities": GRID_WALL_VELOCITIES.read(args.tables / "wall_impact_velocity.csv"),
    }
    points = sorted(tables["pairs"]["point_id"].astype(str).unique())
    dem = {p: dem_point(tables, p) for p in points}
    if getattr(args, "rpm", None):
        lo, hi = args.rpm
        points = [p for p in points if lo <= dem[p]["rpm"] <= hi]
        if not points:
            raise SystemExit(f"--rpm {lo:g} {hi:g}: no grid point of {args.tables} in that range")
    print(
        f"{len(points)} grid points scored, v* = {args.speeds} m/s (spread of ln Y {args.spread}), "
        f"family {args.family}, folds {settings['cv']}"
    )
    rows = []
    if args.floor:
        # the noise floor: the DEM's own rates scored against redrawn DEM samples (floor_draw)
        rng = np.random.default_rng(20261206)
        own = {p: dem[p]["rates"] for p in points}
        for _ in range(args.floor):
            redrawn = {p: floor_draw(dem[p], rng) for p in points}
            rows += scored(points, redrawn, own, args.speeds, "noise floor", args.spread)
    for law in args.laws:
        t0 = time.perf_counter()
        fitted = {p: dem_point(tables, p, law, getattr(args, "law_from", None))["rates"] for p in points}
        rows += scored(points, dem, fitted, args.speeds, f"{law} fit", args.spread)
        print(f"{law}: fits to the DEM's own bins {time.perf_counter() - t0:.1f} s", flush=True)
        if not args.no_held_out:
            t0 = time.perf_counter()
            TV.clear()
            held = held_out_points(tables, settings, radius, args.family, law, getattr(args, "law_from", None))
            print(
                f"{law}: held-out bin fractions, mean total-variation distance "
                + ", ".join(f"{k} {np.mean(v):.3f} ({len(v)} rows)" for k, v in TV.items())
            )
            rows += scored(points, dem, held, args.speeds, f"{law} held out", args.spread)
            print(f"{law}: held-out {args.family} {time.perf_counter() - t0:.1f} s", flush=True)
    if args.model is not None:
        from pbmdem.surrogate import load_surrogate

        model = load_surrogate(args.model)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            est = {p: model.impacts(dem[p]["d"], dem[p]["n"], dem[p]["rpm"], check_domain=False) for p in points}
        rows += scored(points, dem, est, args.speeds, f"{model.speed_law} in sample", args.spread)
    frame = pd.DataFrame(rows)
    if args.csv:
        frame.to_csv(args.csv, index=False)
    pd.set_option("display.width", 200)
    pd.set_option("display.max_rows", 500)
    table = score(frame)
    print("\n|log10(estimate / DEM)| per (point, class) where the DEM's is > 0 (med / p90 / median signed);")
    print("dem0: rows with no DEM impact above v*; est>0, est>3/N: estimates > 0 and above the detection limit")
    print(f"dem>0_few: of the rows scored, those whose DEM value rests on fewer than {FEW_IMPACTS} impacts above v*;")
    print("noise floor: the DEM's own rates against redrawn DEM samples (floor_draw; discrete for such rows)")
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3g}"))
    # number-weighted selection rate per point, summed over kinds (the DEM's with the same spread)
    frame["N"] = [dem[p]["n"][k] for p, k in zip(frame["point_id"], frame["class"], strict=True)]
    agg = (
        frame.assign(dem=frame["N"] * frame["dem_rate"], est=frame["N"] * frame["est_rate"])
        .groupby(["spread", "v_star", "point_id", "source"], sort=True)[["dem", "est", "N"]]
        .sum()
    )
    agg["N"] /= len(KINDS)
    sel = pd.DataFrame({"DEM": agg["dem"] / agg["N"], "est": agg["est"] / agg["N"]}).reset_index()
    sel["source"] = sel["source"].str.replace(r" s=[0-9.]+$", "", regex=True)
    for spread, g in sel.groupby("spread"):
        wide = g.pivot_table(index=["v_star", "point_id"], columns="source", values="est")
        wide.insert(0, "DEM", g.groupby(["v_star", "point_id"])["DEM"].first())
        print(f"\nnumber-weighted selection rate S (1/s per granule, all kinds) per point, spread of ln Y {spread:g}:")
        print(wide.to_string(float_format=lambda x: f"{x:.3g}"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
