"""Why PBM-ANN and PBM-DEM part: replay the stored PBM-DEM loops with each input swapped.

A finished run keeps every PBM-DEM replicate loop of a validation speed on disk
(``results/validation/rpm<rpm>/pbm_dem/rep<r>/interval_NN/``: the interval's representative sample
in interval.json and its DEM tables in dem/, or the tables of an earlier interval with the same
sample, ``dem_reused_from_interval``, or of the grid run it borrowed, ``dem_borrowed_run``). This
benchmark runs each replicate's loop again (the loop settings of its loop_inputs.json, in memory)
with a provider that, for interval k, combines

* the stored DEM rates of that replicate's interval k (``pbmdem.coupling.providers.dem_rates``,
  what PBM-DEM handed to the PBM), put on the replay's current sample by the PBM's own
  interpolation (``ClassFrequencySource.impacts``; used as stored when the sample is the stored one);
* the surrogate's prediction for the replay's current sample (results/surrogate/*.skops, ensemble
  mean: ``SurrogateProvider``, the call PBM-ANN makes),

input by input: pair encounter frequencies (``pair_freq``), pair impact-speed fractions
(``pair_speed``), wall (impeller, bowl) impacts per granule (``wall_freq``) and wall impact-speed
fractions (``wall_speed``). Printed per combination (all DEM, all surrogate, each input alone from
the DEM, each input alone from the surrogate): final d10/d50/d90, mean and range over the replicate
loops. "All DEM" must reproduce the stored PBM-DEM loops: the replay prints the largest difference
of its final d10/d50/d90 from the stored summary.csv and in how many intervals the replay's sample
was the stored one (the same code as the run that wrote them gives 0 and all of them).

Run: .venv/bin/python benchmarks/bench_replay.py --results results --rpm 750 900 1200 [--model m.skops]
     [--csv replays.csv] [--members] [--finished-only] (--members: the member band per model, `member_band`;
     --finished-only: a run still running, its finished
     loops only, said in the output; otherwise an unfinished loop is an error naming it.)
About 1 s per replayed batch on the default configuration (10 combinations x 3 replicates per
speed). Measured numbers in docs/validation.md ("Why PBM-ANN misses above 900 rpm") and
docs/measurements.md.

``--quick`` (the suite's smoke test, no LIGGGHTS): the tiny config/test.yaml with breakage on
(Y = 1 kPa, so its 0.4-1.7 m/s tips break granules), a surrogate trained on benchmarks/quick.py's
synthetic grid tables, and two "PBM-DEM" loops at 1200 rpm whose interval tables are synthetic tables
of each interval's sample with pair impact speeds 1.6 times those the surrogate learned (its
``velocity_law`` + 0.2 decades); all in a temporary folder laid out as a run's results/.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from functools import partial
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.config import CoupledLoop
from pbmdem.coupling.class_source import ClassFrequencySource
from pbmdem.coupling.loop import run_loop
from pbmdem.coupling.providers import SurrogateProvider, dem_rates, interval_run_dir, surrogate_needs
from pbmdem.impact import EncounterRates, ImpactRates, WallRates
from pbmdem.readers import InputFileError, read_json
from pbmdem.surrogate.persistence import SurrogateLoadError

ROOT = Path(__file__).resolve().parents[1]
#: the provider's inputs, in the order of the table
INPUTS = ("pair_freq", "pair_speed", "wall_freq", "wall_speed")
QUANTILES = ("d10", "d50", "d90")


# ----------------------------------------------------------------------------- the stored loops
def stored_intervals(rep_dir: Path) -> list[dict]:
    """Per interval of one stored PBM-DEM loop: its sample's diameters and counts and the DEM's
    ImpactRates of them (the tables of the interval, or of the earlier interval it reused)."""
    out = []
    for folder in sorted(rep_dir.glob("interval_*")):
        info = read_json(folder / "interval.json", "coupling interval record")
        sample = info["sample"]
        run_dir = interval_run_dir(rep_dir, info)  # its own, the one it reused or the grid's it borrowed
        d = np.asarray(sample["diameters"], float)
        out.append({"d": d, "n": np.asarray(sample["counts"], float), "rates": dem_rates(run_dir, d.size)})
    if not out:
        raise SystemExit(f"{rep_dir}: no interval_NN/ folders (is it a PBM-DEM loop of a finished run?)")
    return out


def stored_loop(rep_dir: Path) -> CoupledLoop:
    """The loop settings a stored loop ran with (its loop_inputs.json)."""
    stamp = read_json(rep_dir / "loop_inputs.json", "coupled loop inputs")
    return CoupledLoop.from_dict(stamp["inputs"]["loop"])


def final_sizes(summary_csv: Path) -> dict:
    """Final d10/d50/d90 (mm) of a loop's summary.csv."""
    last = pd.read_csv(summary_csv).iloc[-1]
    return {q: 1e3 * float(last[q]) for q in QUANTILES}


# ----------------------------------------------------------------------------- the replay provider
def combine(dem: ImpactRates, ann: ImpactRates, from_dem: frozenset) -> ImpactRates:
    """ImpactRates whose inputs in ``from_dem`` are the DEM's, the others the surrogate's."""

    def pick(name, a, b):
        return a if name in from_dem else b

    if tuple(dem.walls.walls) != tuple(ann.walls.walls):
        raise ValueError(f"walls of the DEM {dem.walls.walls} and the surrogate {ann.walls.walls} differ")
    pairs = EncounterRates(
        pick("pair_freq", dem.pairs.frequency, ann.pairs.frequency),
        pick("pair_speed", dem.pairs.velocity_fractions, ann.pairs.velocity_fractions),
    )
    walls = WallRates(
        pick("wall_freq", dem.walls.frequency, ann.walls.frequency),
        pick("wall_speed", dem.walls.velocity_fractions, ann.walls.velocity_fractions),
        dem.walls.walls,
    )
    return ImpactRates(pairs, walls)


class ReplayProvider:
    """Interval k: the stored DEM rates of interval k and the surrogate's for the current sample,
    input by input (``from_dem``: the inputs taken from the DEM)."""

    name = "replay"

    def __init__(self, stored: list[dict], surrogate: SurrogateProvider | None, rpm: float, from_dem):
        self.stored, self.surrogate, self.rpm = stored, surrogate, float(rpm)
        self.from_dem = frozenset(from_dem)
        self.same_sample = 0  # intervals whose sample was the stored one (bit for bit)
        self.out_of_domain = 0

    def __call__(self, sample, interval_dir, index: int):
        ref = self.stored[index]
        d, n = np.asarray(sample.diameters, float), np.asarray(sample.counts, float)
        same = d.shape == ref["d"].shape and np.array_equal(d, ref["d"]) and np.array_equal(n, ref["n"])
        self.same_sample += int(same)
        if same:
            dem = ref["rates"]
        else:  # the stored rates on the replay's classes, as the PBM interpolates them onto its bins
            dem = ClassFrequencySource(ref["d"], ref["rates"], f"stored interval {index}").impacts(d, n, self.rpm)
        if self.from_dem >= set(INPUTS):
            return dem, {}
        ann, info = self.surrogate(sample, interval_dir, index)
        self.out_of_domain += int(info["out_of_domain_count"])
        return combine(dem, ann, self.from_dem), {}


def combinations() -> list[tuple[str, frozenset]]:
    """(label, inputs from the DEM) of every combination printed."""
    rows = [("all DEM", frozenset(INPUTS)), ("all surrogate", frozenset())]
    rows += [(f"DEM {x} only", frozenset({x})) for x in INPUTS]
    rows += [(f"surrogate {x} only", frozenset(INPUTS) - {x}) for x in INPUTS]
    return rows


def replay_speed(results: Path, rpm: str, model_path: Path, finished_only: bool = False) -> dict:
    """Replay every stored PBM-DEM loop of one speed in every combination; prints the table."""
    speed_dir = results / "validation" / f"rpm{rpm}"
    reps = sorted((speed_dir / "pbm_dem").glob("rep*"))
    if not reps:
        raise SystemExit(
            f"{speed_dir}/pbm_dem: no replicate loops rep*/ (validation speeds: rpm* in {results}/validation)"
        )
    unfinished = [rep.name for rep in reps if not (rep / "summary.csv").exists()]
    if unfinished and not (finished_only and len(unfinished) < len(reps)):
        raise SystemExit(f"{speed_dir}/pbm_dem: loop(s) {unfinished} not finished (no summary.csv)")
    if unfinished:
        print(f"rpm {rpm}: loop(s) {unfinished} not finished: replaying the finished ones only (--finished-only)")
        reps = [rep for rep in reps if rep.name not in unfinished]
    stored = {rep.name: (stored_loop(rep), stored_intervals(rep), final_sizes(rep / "summary.csv")) for rep in reps}
    from pbmdem.surrogate import load_surrogate

    model = load_surrogate(model_path)
    rows, check = [], []
    t0 = time.perf_counter()
    for label, from_dem in combinations():
        for rep, (loop, intervals, _) in stored.items():
            ann = SurrogateProvider(model, float(rpm), log_each=False, needs=surrogate_needs(loop.batch.pbm))
            provider = ReplayProvider(intervals, ann, float(rpm), from_dem)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # out-of-domain warnings: counted
                outcome = run_loop(loop, provider, float(rpm), None)
            last = outcome.result.summary().iloc[-1]
            sizes = {q: 1e3 * float(last[q]) for q in QUANTILES}
            rows.append({"combination": label, "rep": rep, **sizes, "out_of_domain": provider.out_of_domain})
            if label == "all DEM":
                check.append((rep, sizes, provider.same_sample, len(intervals)))
    wall = time.perf_counter() - t0
    table = pd.DataFrame(rows)
    ann_dir = speed_dir / "pbm_ann" / "summary.csv"
    dem_final = pd.DataFrame([s for _, _, s in stored.values()])
    print(f"\nrpm {rpm}: {len(reps)} stored PBM-DEM loops ({', '.join(stored)}), "
          f"{len(stored[reps[0].name][1])} intervals each; {len(table)} replays in {wall:.1f} s")  # fmt: skip
    print("stored PBM-DEM  " + "  ".join(_band(q, dem_final[q]) for q in QUANTILES))
    ann = final_sizes(ann_dir) if ann_dir.exists() else None
    if ann is not None:
        print("stored PBM-ANN  " + "  ".join(f"{q} {ann[q]:.2f}" for q in QUANTILES))
    print(f"{'combination (inputs from the DEM)':<28}" + "".join(f"{q + ' mean (range) mm':>26}" for q in QUANTILES)
          + "  out-of-domain")  # fmt: skip
    for label, _ in combinations():
        sub = table[table.combination == label]
        print(
            f"{label:<28}" + "".join(f"{_band('', sub[q]):>26}" for q in QUANTILES) + f"  {sub.out_of_domain.sum():d}"
        )
    worst = max(abs(s[q] - stored[rep][2][q]) / stored[rep][2][q] for rep, s, _, _ in check for q in QUANTILES)
    same = sum(c[2] for c in check)
    total = sum(c[3] for c in check)
    print(
        f"all DEM reproduces the stored PBM-DEM loops: max |difference| of final d10/d50/d90 {worst:.3g} "
        f"(relative); replay's sample = stored sample in {same} of {total} intervals"
    )
    if ann is not None:  # all surrogate is PBM-ANN's loop: the same provider call on the same samples
        sub = table[table.combination == "all surrogate"]
        off = max(abs(float(v) - ann[q]) / ann[q] for q in QUANTILES for v in sub[q])
        print(
            "all surrogate reproduces the stored PBM-ANN batch: max |difference| of final d10/d50/d90 "
            f"{off:.3g} (relative)"
        )
    return {"table": table, "worst": worst, "same": same, "total": total}


#: what a surrogate member moves (``CollisionSurrogate.member``) -> the fitted attribute that carries it
MEMBER_PARTS = {
    "frequency": "frequency_model_",
    "speed law": "velocity_model_",
    "tail": "speed_tail_",
    "walls": "wall_models_",
}


def member_band(results: Path, rpm: str, model_path: Path) -> dict:
    """Where PBM-ANN's member band comes from: the final d50 of each member's batch (PBM-ANN on the
    first stored loop's settings) with every model moved to the member's quantile, and with one model
    of ``MEMBER_PARTS`` moved alone (the others the mean). Prints one row per variant, the PBM-DEM
    replicates' final d50 range and the band's target (3 x that range or 10 % of their mean)."""
    import copy

    from pbmdem.coupling.methods import pbm_ann
    from pbmdem.surrogate import load_surrogate

    speed_dir = results / "validation" / f"rpm{rpm}"
    reps = sorted(rep for rep in (speed_dir / "pbm_dem").glob("rep*") if (rep / "summary.csv").exists())
    if not reps:
        raise SystemExit(f"{speed_dir}/pbm_dem: no finished replicate loop (rep*/summary.csv)")
    model = load_surrogate(model_path)
    loop = stored_loop(reps[0])
    members = [model.member(k) for k in range(model.n_members)]

    def d50(surrogate) -> float:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return 1e3 * float(
                pbm_ann(loop, surrogate, float(rpm), None, log_each=False).result.summary().iloc[-1]["d50"]
            )

    def moved(member, attribute):
        out = copy.copy(model)
        setattr(out, attribute, getattr(member, attribute))
        return out

    variants = {"all models": [d50(m) for m in members]}
    for part, attribute in MEMBER_PARTS.items():
        variants[part] = [d50(moved(m, attribute)) for m in members]
    dem = np.array([final_sizes(rep / "summary.csv")["d50"] for rep in reps])
    target = max(3 * (dem.max() - dem.min()), 0.1 * dem.mean())
    print(f"\nrpm {rpm}: members' final d50 (mm), member 0 .. {model.n_members - 1}; PBM-DEM {_band('d50', dem)}, "
          f"band target {target:.2f} mm")  # fmt: skip
    for name, values in variants.items():
        width = max(values) - min(values)
        inside = "yes" if min(values) <= dem.mean() <= max(values) else "no"
        tail = f", contains the PBM-DEM mean: {inside}" if name == "all models" else ""
        print(f"  {name:<11}" + " ".join(f"{v:6.2f}" for v in values) + f"   width {width:.2f}{tail}")
    return variants


def _band(name: str, values) -> str:
    v = np.asarray(values, float)
    prefix = f"{name} " if name else ""
    return f"{prefix}{v.mean():.2f} ({v.min():.2f}-{v.max():.2f})"


# ----------------------------------------------------------------------------- quick mode
class SyntheticDem:
    """A stand-in for LIGGGHTS in the quick mode: synthetic run tables of each interval's sample
    (benchmarks/quick.py's laws, pair impact speeds ``speed_factor`` times faster) written to
    ``interval_dir/dem`` and read back as PBM-DEM reads them."""

    name = "pbm_dem"

    def __init__(self, radius: float, rpm: float, replicate: int, speed_factor: float = 10**0.2):
        self.radius, self.rpm, self.replicate, self.factor = radius, float(rpm), int(replicate), speed_factor

    def fingerprint(self) -> dict:
        return {"name": "synthetic", "rpm": self.rpm, "replicate": self.replicate}

    def __call__(self, sample, interval_dir: Path, index: int):
        from synthetic_tables import (  # tests/ (on the path: quick_results)
            make_synthetic_tables,
            make_synthetic_wall_tables,
            power_law,
            velocity_law,
        )

        def faster(d_i, d_j, rpm, radius):
            mu, sigma = velocity_law(d_i, d_j, rpm, radius)
            return mu + np.log10(self.factor), sigma

        total = int(sum(sample.counts))
        seed = 100 * self.replicate + index
        pairs, velocities = make_synthetic_tables(
            self.radius, rpms=(self.rpm,), distributions={f"interval{index:02d}": sample.counts},
            diameters=sample.diameters, n_total_range=(total, total), law=partial(power_law, c0=0.03),
            n_replicates=1, vlaw=faster, sample_velocities=True, seed=seed,
        )  # fmt: skip
        walls, wall_velocities = make_synthetic_wall_tables(pairs, self.radius, seed=seed + 1)
        run_dir = interval_dir / "dem"
        run_dir.mkdir(parents=True, exist_ok=True)
        for name, frame in {
            "collisions.csv": pairs,
            "impact_velocity.csv": velocities,
            "wall_collisions.csv": walls,
            "wall_impact_velocity.csv": wall_velocities,
        }.items():
            frame = frame.assign(replicate=self.replicate)
            for col in ("collisions", "encounters"):  # whole counts in a run's tables
                if col in frame:
                    frame[col] = np.round(frame[col]).astype(int)
            frame.to_csv(run_dir / name, index=False)
        return dem_rates(run_dir, len(sample.diameters)), {}


def quick_results(root: Path, rpm: float = 1200.0, replicates: int = 2) -> Path:
    """A run's results/ in ``root`` for the quick mode: the surrogate and the stored PBM-DEM (synthetic
    tables) and PBM-ANN loops of ``rpm``; returns the results folder."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    sys.path.insert(0, str(ROOT / "tests"))  # the synthetic tables live with the tests
    import quick

    from pbmdem.coupling.methods import pbm_ann

    cfg = quick.config()
    loop = cfg.coupled_loop()
    pbm = loop.batch.pbm.replace(breakage=loop.batch.pbm.breakage.replace(enabled=True, yield_strength=1.0e3))
    loop = loop.replace(batch=loop.batch.replace(pbm=pbm))
    results = root / "results"
    model = quick.surrogate(results / "surrogate", cfg)
    radius = cfg.granulator.impeller.tip_radius
    speed = results / "validation" / f"rpm{rpm:g}"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for rep in range(replicates):
            run_loop(loop, SyntheticDem(radius, rpm, rep), rpm, speed / "pbm_dem" / f"rep{rep}")
        pbm_ann(loop, model, rpm, speed / "pbm_ann", log_each=False)
    return results


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--results", type=Path, help="a finished run's results folder")
    parser.add_argument("--rpm", nargs="+", help="validation speeds to replay (rpm<rpm>/ of results/validation)")
    parser.add_argument("--model", type=Path, help="surrogate file (default: the only results/surrogate/*.skops)")
    parser.add_argument("--csv", type=Path, help="write every replay's final sizes here")
    parser.add_argument(
        "--finished-only", action="store_true", help="replay the finished loops of a run still running (said)"
    )
    parser.add_argument(
        "--members", action="store_true", help="also: the members' band, all models and each model alone"
    )
    parser.add_argument("--quick", action="store_true", help="synthetic stored loops, seconds (the suite's smoke test)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        if args.quick:
            t0 = time.perf_counter()
            args.results, args.rpm, args.members = quick_results(Path(tmp)), ["1200"], True
            print(f"quick: stored loops made in {time.perf_counter() - t0:.1f} s")
        if args.results is None or not args.rpm:
            parser.error("give --results and --rpm (or --quick)")
        model = args.model or _model(args.results)
        tables = []
        for rpm in args.rpm:
            try:
                out = replay_speed(args.results, rpm, model, args.finished_only)
            except (
                InputFileError,
                SurrogateLoadError,
            ) as exc:  # a missing or broken file of the run: named, no traceback
                raise SystemExit(f"bench_replay.py: {exc}") from None
            tables.append(out["table"].assign(rpm=rpm))
            if args.members:
                member_band(args.results, rpm, model)
        if args.csv:
            pd.concat(tables).to_csv(args.csv, index=False)


def _model(results: Path) -> Path:
    found = sorted((results / "surrogate").glob("*.skops"))
    if len(found) != 1:
        raise SystemExit(f"{results}/surrogate: expected one *.skops, found {[p.name for p in found]}; give --model")
    return found[0]


if __name__ == "__main__":
    main()
