"""The pair breaking-impact rate per class on the PBM-DEM loops' own samples: DEM against the surrogate.

Breakage from impacts (pbmdem.pbm.impact_breakage) selects granule i at the rate
S_i = sum_j c_ij (N_j - delta_ij) P_ij(v*), P_ij the fraction of the pair's impacts that break it
(``pbmdem.impact.breaking_probability``: the critical speed v* and the spread of ln Y). For every
interval of the stored PBM-DEM loops of a finished run (the interval's representative sample and
the DEM's tables of it, as ``benchmarks/bench_replay.py`` reads them) and every v* of --speeds, this
prints the median over the classes of log10(estimate / DEM) of S_i for

* ``surrogate``: the surrogate's impacts of the same sample (``impacts(d, n, rpm)``, PBM-ANN's call);
* ``surrogate c only``: the surrogate's encounter frequency with the DEM's impact speeds (the
  frequency's share; the rest is the speed law's);
* ``law fit``: the DEM's frequencies with each pair's speed bins replaced by the speed law fitted
  to those bins (``surrogate.speed_law``; no learning: the law's misfit alone), and with
  --law-from v the same law fitted from v m/s up (``fit_speed_law(..., fit_from=v)``);

separately for the loops' feed sample (interval 0 and those that reuse its sample) and the later ones, and, for the
later ones, per class: the smallest, the middle ones, the largest. The PBM's own v* rises as the
aggregates consolidate (``pbm.breakage.strength_porosity_exponent``: 2 m/s at porosity 0.5, 8 m/s
at 0.2); the number-weighted porosity of the loops' aggregates at each interval's start (their
bins.csv) and its v* are printed first.

Run: .venv/bin/python benchmarks/bench_breakage_samples.py --results results --rpm 900 1200
     [--model m.skops] [--speeds 2 4 6 8] [--spread 0.5] [--law-from 1.0] [--csv rows.csv]
Seconds per speed. Measured numbers in docs/validation.md ("Why PBM-ANN misses above 900 rpm").

``--quick`` (the suite's smoke test, no LIGGGHTS): the synthetic stored loops of
``bench_replay.py --quick`` (1200 rpm, tiny config) and v* = 0.25 and 0.5 m/s.
"""

from __future__ import annotations

import argparse
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
from bench_replay import quick_results, stored_intervals

from pbmdem.impact import N_VELOCITY_BINS, breaking_probability
from pbmdem.readers import read_json

#: porosity exponent and reference of the default strength (config/config.yaml, pbm.breakage)
V_REF, EPS_REF = 2.0, 0.5


def selection(frequency, fractions, numbers, speed: float, spread: float) -> np.ndarray:
    """(K,) pair breaking-impact rate per granule (1/s) of each class: S_i = sum_j c_ij (N_j - delta_ij) P_ij."""
    n = np.asarray(numbers, float)
    K = n.size
    above = np.broadcast_to(breaking_probability(speed, spread), (K, N_VELOCITY_BINS))
    partners = np.maximum(n[None, :] - np.eye(K), 0.0)
    return (frequency * np.einsum("ijb,ib->ij", fractions, above) * partners).sum(axis=1)


def law_fractions(fractions: np.ndarray, law: str, fit_from: float | None) -> np.ndarray:
    """(K, K, V) the speed law ``law`` fitted to every pair's bins (from ``fit_from`` m/s up)."""
    from pbmdem.surrogate.velocity import fit_speed_law, speed_fractions

    K = fractions.shape[0]
    flat = fractions.reshape(-1, N_VELOCITY_BINS)
    out = np.zeros_like(flat)
    ok = flat.sum(axis=1) > 0
    mu, sigma, *shape = fit_speed_law(flat[ok], law, fit_from)
    out[ok] = speed_fractions(mu, sigma, law, shape[0] if shape else None)
    return out.reshape(K, K, N_VELOCITY_BINS)


def aggregate_porosity(rep: Path, t: float) -> float:
    """Number-weighted porosity of the non-empty bins of a loop at time t (its bins.csv), NaN if none."""
    path = rep / "bins.csv"
    if not path.exists():
        return float("nan")
    bins = pd.read_csv(path)
    now = bins[np.isclose(bins["time"], t) & (bins["number"] > 0)]
    return float((now["number"] * now["porosity"]).sum() / now["number"].sum()) if len(now) else float("nan")


def sample_rows(results: Path, rpm: str, model, speeds, spread: float, law: str, law_from) -> pd.DataFrame:
    """One row per loop, interval, class, v* and estimate: S_i of the DEM and of the estimate."""
    rows = []
    for rep in sorted((results / "validation" / f"rpm{rpm}" / "pbm_dem").glob("rep*")):
        folders = sorted(rep.glob("interval_*"))
        intervals = stored_intervals(rep)
        for k, iv in enumerate(intervals):
            d, n, dem = iv["d"], iv["n"], iv["rates"]
            feed = d.shape == intervals[0]["d"].shape and np.array_equal(d, intervals[0]["d"])
            feed = feed and np.array_equal(n, intervals[0]["n"])
            t0 = float(read_json(folders[k] / "interval.json", "coupling interval record")["t_start"])
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # out-of-domain warnings: the loops' own samples
                ann = model.impacts(d, n, float(rpm))
            estimates = {
                "surrogate": (ann.pairs.frequency, ann.pairs.velocity_fractions),
                "surrogate c only": (ann.pairs.frequency, dem.pairs.velocity_fractions),
                "law fit": (dem.pairs.frequency, law_fractions(dem.pairs.velocity_fractions, law, None)),
            }
            if law_from is not None:
                fitted = law_fractions(dem.pairs.velocity_fractions, law, law_from)
                estimates[f"law fit from {law_from:g} m/s"] = (dem.pairs.frequency, fitted)
            porosity = aggregate_porosity(rep, t0)
            for v in speeds:
                ref = selection(dem.pairs.frequency, dem.pairs.velocity_fractions, n, v, spread)
                for name, (c, f) in estimates.items():
                    est = selection(c, f, n, v, spread)
                    for i in range(d.size):
                        pos = "smallest" if i == 0 else "largest" if i == d.size - 1 else "middle"
                        rows.append(
                            {"rpm": rpm, "rep": rep.name, "interval": k, "t_start": t0, "porosity": porosity,
                             "stage": "feed" if feed else "later",
                             "class": i, "position": pos, "vstar": v, "estimate": name,
                             "S_dem": ref[i], "S": est[i]}
                        )  # fmt: skip
    table = pd.DataFrame(rows)
    with np.errstate(divide="ignore", invalid="ignore"):
        table["log10_ratio"] = np.where(table["S_dem"] > 0, np.log10(table["S"] / table["S_dem"]), np.nan)
    return table


def report(table: pd.DataFrame, rpm: str) -> None:
    """Print the speed's tables (module docstring)."""
    pd.set_option("display.width", 200)
    first = table[table["vstar"] == table["vstar"].iloc[0]].drop_duplicates(["rep", "interval"])
    por = first.groupby("interval").agg(t_start=("t_start", "first"), porosity=("porosity", "median"))
    por["v_star_own"] = V_REF * ((1 - por["porosity"]) / por["porosity"]) / ((1 - EPS_REF) / EPS_REF)
    print(f"\nrpm {rpm}: aggregates' porosity at each interval's start (median over the loops) and its v* (m/s)")
    print(por.to_string(float_format=lambda x: f"{x:.3g}"))
    med = table.pivot_table(index=["vstar", "stage"], columns="estimate", values="log10_ratio", aggfunc="median")
    dem = table[table.estimate == "surrogate"].groupby(["vstar", "stage"])["S_dem"].median().rename("S_dem (1/s)")
    print(f"rpm {rpm}: median log10(estimate / DEM) of the pair breaking-impact rate S_i over classes and loops")
    both = pd.concat([dem.map(lambda x: f"{x:.2g}"), med.map(lambda x: f"{x:+.2f}")], axis=1)
    print(both.to_string())
    later = table[table.stage == "later"]
    if later.empty:
        print(f"rpm {rpm}: every interval's sample is the feed's (no later samples)")
        return
    by = later.pivot_table(index=["vstar", "position"], columns="estimate", values="log10_ratio", aggfunc="median")
    print(f"rpm {rpm}, later samples, by class: median log10(estimate / DEM)")
    print(by.to_string(float_format=lambda x: f"{x:+.2f}"))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--results", type=Path, help="a finished run's results folder")
    parser.add_argument("--rpm", nargs="+", help="validation speeds (rpm<rpm>/ of results/validation)")
    parser.add_argument("--model", type=Path, help="surrogate file (default: results/surrogate/model.skops)")
    parser.add_argument("--speeds", nargs="+", type=float, default=[2.0, 4.0, 6.0, 8.0], help="v* (m/s)")
    parser.add_argument("--spread", type=float, default=0.5, help="pbm.breakage.strength_spread")
    parser.add_argument("--law", default="gengamma", help="speed law of the law fits (surrogate.speed_law)")
    parser.add_argument("--law-from", type=float, default=None, help="also the law fitted from this speed (m/s) up")
    parser.add_argument("--csv", type=Path, help="write every row here")
    parser.add_argument("--quick", action="store_true", help="synthetic stored loops, seconds (the suite's smoke test)")
    args = parser.parse_args(argv)
    from pbmdem.surrogate import load_surrogate

    with tempfile.TemporaryDirectory() as tmp:
        if args.quick:
            args.results, args.rpm, args.speeds = quick_results(Path(tmp)), ["1200"], [0.25, 0.5]
            args.law_from = 0.1
        if args.results is None or not args.rpm:
            parser.error("give --results and --rpm (or --quick)")
        model = load_surrogate(args.model or args.results / "surrogate" / "model.skops")
        tables = []
        for rpm in args.rpm:
            table = sample_rows(args.results, rpm, model, args.speeds, args.spread, args.law, args.law_from)
            report(table, rpm)
            tables.append(table)
        if args.csv:
            pd.concat(tables).to_csv(args.csv, index=False)


if __name__ == "__main__":
    main()
