"""DEM-stage benchmark: where a run's time goes, old against new settings, parse cost.

Prints figures; asserts nothing (timings on a shared machine are noisy; CPU times are given where
the runs recorded them).

    # one point with the real LIGGGHTS: engine speed, parser against a naive reader, snapshot interval
    .venv/bin/python benchmarks/bench_dem.py point [--config config/config.yaml] [--rpm 600] [--distribution fine]
    # per-phase profile (settling, spin-up, history + sampling) of the finished runs of a results/dem
    .venv/bin/python benchmarks/bench_dem.py profile results/dem [more results/dem ...]
    # acceptance of new DEM settings against old ones, every point and class pair (docs/dem.md, "Cost")
    .venv/bin/python benchmarks/bench_dem.py acceptance OLD/results/dem NEW/results/dem
    # how many pairs that acceptance fails from replicate noise alone (no change of settings)
    .venv/bin/python benchmarks/bench_dem.py null results/dem [--draws 4000]
    # one point with the settings before issue 20 and with the current ones, side by side (same load)
    .venv/bin/python benchmarks/bench_dem.py cost [--rpm 600] [--distribution fine] [--speeds 4] [--out DIR]
    # finished runs again with other neighbour skins (run: the deck's own; dmin, dmax: half the
    # smallest, largest diameter; or metres), interleaved, LIGGGHTS wall time of every run command
    .venv/bin/python benchmarks/bench_dem.py skin RUN_DIR [RUN_DIR ...] [--skins run,dmin,dmax] [--repeats 2]
    # run-level totals, half-window trend and wall encounters of two results/dem, many replicates each
    .venv/bin/python benchmarks/bench_dem.py runs OLD/results/dem NEW/results/dem [--skip-replicates 0]
    # every subcommand above once on the tiny test configuration, in a temporary folder (about 30 s;
    # the suite's smoke test): a DEM grid of one point, 2 replicates from settled beds, made here
    .venv/bin/python benchmarks/bench_dem.py --quick
"""

from __future__ import annotations

import argparse
import json
import math
import re
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.config import load_config
from pbmdem.dem import collisions
from pbmdem.dem.plan import plan_point
from pbmdem.dem.run import run_point

ROOT = Path(__file__).resolve().parents[1]

_LOOP = re.compile(r"^Loop time of (?P<wall>[\d.eE+-]+) on (?P<procs>\d+) procs for (?P<steps>\d+) steps")
_PART = re.compile(r"^(?P<name>Pair|Neigh|Comm|Outpt|Modfy|Other)\s+time \(%\) = (?P<seconds>[\d.eE+-]+)")


def loop_times(log: str | Path) -> list[dict[str, float]]:
    """The timing block LIGGGHTS writes after each `run` command of a log, in order: `wall` (s),
    `steps`, `procs`, and the seconds of its parts (`Pair`, `Neigh`, `Comm`, `Outpt` (dumps),
    `Other`: fixes such as the mesh walls, integration, thermo), as far as the log has them."""
    blocks: list[dict[str, float]] = []
    for line in Path(log).read_text(errors="replace").splitlines():
        loop = _LOOP.match(line)
        if loop:
            blocks.append({k: float(v) for k, v in loop.groupdict().items()})
            continue
        part = _PART.match(line)
        if part and blocks:
            blocks[-1][part.group("name")] = float(part.group("seconds"))
    return blocks


def naive_parse(path: Path) -> int:
    """Line-by-line reader with a Python set per frame (the approach the vectorised parser replaces)."""
    new = 0
    previous: set | None = None
    current: set = set()
    lines = iter(path.read_text().splitlines())
    for line in lines:
        if line.startswith("ITEM: TIMESTEP"):
            if previous is not None or current:
                if previous is not None:
                    new += len(current - previous)
                previous = current
            current = set()
            for _ in range(8):
                next(lines)
            continue
        a, b, delta = line.split()[:3]
        if float(delta) > 0:
            i, j = int(a), int(b)
            current.add((min(i, j), max(i, j)))
    if previous is not None:
        new += len(current - previous)
    return new


def bench_point(args) -> None:
    cfg = load_config(args.config)
    point = cfg.dem_point(args.distribution)
    point = point.replace(dem=point.dem.replace(keep_contact_dumps=True))
    plan = plan_point(point, args.rpm)
    with tempfile.TemporaryDirectory() as tmp:
        summary = run_point(plan, tmp, cfg.dem_execution)
        post = Path(tmp) / "post"
        t0 = time.perf_counter()
        naive_total = naive_parse(post / "pairs.dump")
        naive = time.perf_counter() - t0
        t0 = time.perf_counter()
        analysis = collisions.RunAnalysis(post, plan)
        tables = analysis.tables()
        fast = time.perf_counter() - t0
        pairs = analysis.pairs
        counts = {s: int(len(analysis.pair_events(stride=s)[0].encounter)) for s in (1, 2, 4)}
        size_mb = (post / "pairs.dump").stat().st_size / 1e6
    run = summary["liggghts_wall_time_s"]
    print(
        f"operating point           {plan.point_id}: {plan.n_particles} particles, dt {plan.timestep:.3g} s, "
        f"{plan.settle_steps + plan.spinup_steps + plan.sampling_steps} steps"
    )
    print(f"LIGGGHTS wall time        {run:.1f} s  ({summary['particle_steps_per_s'] / 1e6:.2f} M particle-steps/s)")
    print(f"contact dump              {size_mb:.0f} MB, {pairs.frames} snapshots every {plan.collision_interval} steps")
    print(f"vectorised parse+count    {fast:.2f} s  = {100 * fast / run:.1f} % of the LIGGGHTS run (target < 10 %)")
    print(f"naive line-by-line        {naive:.2f} s  = {100 * naive / run:.1f} % of the LIGGGHTS run")
    print(
        f"new contacts (naive)      {naive_total} (every contact present in the whole record) vs "
        f"vectorised {counts[1]} (in the sampling window)"
    )
    for s, c in counts.items():
        print(
            f"interval {s * plan.collision_interval:4d} steps      {c} new contacts "
            f"({100 * (c - counts[1]) / counts[1]:+.2f} %)"
        )
    print(f"total in table            {int(tables.pairs['collisions'].sum())}")


# ------------------------------------------------------------------------------ profile
def _run_dirs(dem: Path) -> list[Path]:
    return sorted(p.parent for p in dem.glob("rpm*/rep*/summary.json"))


def run_profile(run_dir: Path) -> dict:
    """Per-phase LIGGGHTS wall time of one finished run (and its settled bed, if it had one)."""
    plan = json.loads((run_dir / "plan.json").read_text())
    summary = json.loads((run_dir / "summary.json").read_text())
    blocks = loop_times(run_dir / "log.liggghts")
    bed = plan.get("settled_bed")
    if bed:  # plan.json names the settled bed's restart file; its log lies beside it
        bed_log = Path(bed).parent / "log.liggghts"
        (settle,) = loop_times(bed_log) if bed_log.exists() else [{}]
        spin, record = blocks
    else:
        settle, spin, record = blocks
    history_share = plan["history_steps"] / (plan["history_steps"] + plan["sampling_steps"])
    return {
        "point_id": plan["point_id"],
        "replicate": plan["replicate"],
        "particles": plan["n_particles"],
        "dt": plan["timestep"],
        "settling_s": settle.get("wall", math.nan),
        "spinup_s": spin["wall"],
        "history_s": history_share * record["wall"],  # one `run` records both; split by steps
        "sampling_s": (1 - history_share) * record["wall"],
        "dumps_s": record.get("Outpt", 0.0) + spin.get("Outpt", 0.0),
        "parse_s": summary["parse_time_s"],
        "steps": plan["settle_steps"] + plan["spinup_steps"] + plan["sampling_steps"],
        "run_steps": summary.get("run_steps", summary["steps"]),
        "from_bed": bool(bed),
        "wall_s": summary["liggghts_wall_time_s"],
        "cpu_s": summary.get("liggghts_cpu_time_s", math.nan),
        "psteps_per_s": summary["particle_steps_per_s"],
        "psteps_per_cpu_s": summary.get("particle_steps_per_cpu_s", math.nan),
    }


def profile_table(dem: Path) -> pd.DataFrame:
    rows = [run_profile(d) for d in _run_dirs(dem)]
    return pd.DataFrame(rows).groupby("point_id", sort=False).mean(numeric_only=True).reset_index()


def bench_profile(args) -> None:
    pd.set_option("display.width", 250)
    for dem in args.dem:
        table = profile_table(Path(dem))
        print(f"\n{dem}: LIGGGHTS wall time per phase (s, mean over replicates); the settled bed's time is")
        print("shared by every speed that starts from it; dumps = Output time of the spin-up and recording")
        cols = ["particles", "dt", "settling_s", "spinup_s", "history_s", "sampling_s", "dumps_s", "parse_s"]
        cols += ["wall_s", "cpu_s", "psteps_per_s", "psteps_per_cpu_s"]
        print(table.set_index("point_id")[cols].to_string(float_format=lambda v: f"{v:.3g}"))


# --------------------------------------------------------------------------- acceptance
def _points(dem: Path) -> pd.DataFrame:
    """Per point and class pair: the grid table's frequency (mean, SE) and median impact speed,
    with the standard error of that median over the replicates (collisions_replicates.csv)."""
    keys = ["point_id", "class_i", "class_j"]
    table = pd.read_csv(dem / "collisions.csv")
    runs = pd.read_csv(dem / "collisions_replicates.csv").groupby(keys)["impact_velocity_median"]
    se = (runs.std(ddof=1) / np.sqrt(runs.count())).rename("impact_velocity_median_se").reset_index()
    cols = ["n_replicates", "encounter_frequency_per_pair", "encounter_frequency_per_pair_se", "impact_velocity_median"]
    return table[keys + cols].merge(se, on=keys)


def _cost(dem: Path) -> pd.DataFrame:
    """Per point: LIGGGHTS time and steps of a run (mean over replicates) with its share of the
    settled bed (the bed's time and steps over the number of grid speeds that start from it)."""
    runs = pd.read_csv(dem / "runs.csv")
    nan = pd.Series(np.nan, index=runs.index)
    zero = pd.Series(0.0, index=runs.index)
    share = runs["distribution"].map(runs.groupby("distribution")["rpm"].nunique())
    run_steps = runs.get("run_steps", runs["steps"])
    runs = runs.assign(
        wall_total=runs["liggghts_wall_time_s"] + runs.get("bed_liggghts_wall_time_s", zero) / share,
        cpu_total=runs.get("liggghts_cpu_time_s", nan) + runs.get("bed_liggghts_cpu_time_s", zero) / share,
        steps_total=run_steps + (runs["steps"] - run_steps) / share,
    )
    return runs.groupby("point_id")[["wall_total", "cpu_total", "steps_total", "timestep"]].mean()


def acceptance_table(old: Path, new: Path) -> pd.DataFrame:
    """Every point and class pair: the encounter frequency per pair (mean +- SE over replicates)
    and the median impact speed of both settings, and whether they agree: frequencies within
    max(2 combined SE, 3 %), median impact speeds within 5 %."""
    both = _points(old).merge(_points(new), on=["point_id", "class_i", "class_j"], suffixes=("_old", "_new"))
    f_old, f_new = both["encounter_frequency_per_pair_old"], both["encounter_frequency_per_pair_new"]
    se = np.hypot(both["encounter_frequency_per_pair_se_old"], both["encounter_frequency_per_pair_se_new"])
    both["freq_change"] = f_new / f_old - 1
    both["freq_z"] = (f_new - f_old) / se
    both["freq_ok"] = (f_new - f_old).abs() <= np.maximum(2 * se, 0.03 * f_old)
    v_old, v_new = both["impact_velocity_median_old"], both["impact_velocity_median_new"]
    both["v_change"] = v_new / v_old - 1
    both["v_ok"] = both["v_change"].abs() <= 0.05
    # the median of a pair with few encounters scatters more than 5 % between replicates of one
    # setting: the same test with the replicate error of the medians as the floor
    v_se = np.hypot(both["impact_velocity_median_se_old"], both["impact_velocity_median_se_new"])
    both["v_z"] = (v_new - v_old) / v_se
    both["v_ok_noise"] = (v_new - v_old).abs() <= np.maximum(2 * v_se, 0.05 * v_old)
    return both


def bench_acceptance(args) -> None:
    old, new = Path(args.old), Path(args.new)
    table = acceptance_table(old, new)
    flow = pd.read_csv(new / "flow_development.csv").set_index("point_id")
    flow_old = pd.read_csv(old / "flow_development.csv").set_index("point_id")
    cost_old, cost_new = _cost(old), _cost(new)
    print(
        "| point | pair | freq. per pair old (1/s) | new | change | z | ok | median impact speed old (m/s) "
        "| new | change | z | within 5 % | within max(5 %, 2 SE) |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in table.itertuples():
        print(
            f"| {r.point_id} | {r.class_i}-{r.class_j} | {r.encounter_frequency_per_pair_old:.4g} +- "
            f"{r.encounter_frequency_per_pair_se_old:.2g} | {r.encounter_frequency_per_pair_new:.4g} +- "
            f"{r.encounter_frequency_per_pair_se_new:.2g} | {100 * r.freq_change:+.1f} % | {r.freq_z:+.1f} | "
            f"{'yes' if r.freq_ok else '**no**'} | {r.impact_velocity_median_old:.3g} | "
            f"{r.impact_velocity_median_new:.3g} | {100 * r.v_change:+.1f} % | {r.v_z:+.1f} | "
            f"{'yes' if r.v_ok else '**no**'} | {'yes' if r.v_ok_noise else '**no**'} |"
        )
    print()
    print(
        "| point | pairs ok (freq. / speed 5 % / speed 2 SE) | flow check old / new (halves, z) "
        "| LIGGGHTS s per run old (wall) | new (wall / CPU, with bed share) | steps old / new "
        "| speed-up (old wall / new CPU) |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for point, rows in table.groupby("point_id", sort=False):
        fo, fn = flow_old.loc[point], flow.loc[point]
        co, cn = cost_old.loc[point], cost_new.loc[point]
        print(
            f"| {point} | {int(rows.freq_ok.sum())} / {int(rows.v_ok.sum())} / {int(rows.v_ok_noise.sum())} "
            f"of {len(rows)} | "
            f"{100 * fo.half_difference:+.1f} % ({fo.half_z:+.1f}) / {100 * fn.half_difference:+.1f} % "
            f"({fn.half_z:+.1f}){'' if fn.within_error else ' **fails**'} | {co.wall_total:.1f} | "
            f"{cn.wall_total:.1f} / {cn.cpu_total:.1f} | {co.steps_total:.0f} / {cn.steps_total:.0f} | "
            f"{co.wall_total / cn.cpu_total:.1f}x |"
        )
    common = sorted(set(table.point_id))
    total_old, total_new = cost_old.loc[common, "wall_total"].sum(), cost_new.loc[common, "cpu_total"].sum()
    print(
        f"\npairs within the frequency criterion: {int(table.freq_ok.sum())} of {len(table)}; median impact "
        f"speed within 5 %: {int(table.v_ok.sum())} of {len(table)} (within max(5 %, 2 combined SE): "
        f"{int(table.v_ok_noise.sum())}); flow check passing at "
        f"{int(flow.within_error.sum())} of {len(flow)} points (old settings: "
        f"{int(flow_old.loc[flow.index.intersection(flow_old.index)].within_error.sum())})"
    )
    print(
        f"LIGGGHTS time of one replicate of the {len(common)} points: old {total_old:.0f} s (wall), new "
        f"{total_new:.0f} s (CPU) "
        f"= {total_old / total_new:.1f}x"
    )


def bench_null(args) -> None:
    """How many pairs the acceptance fails when nothing changes: both sides drawn from the same
    normal law per pair (the mean and replicate sd of `dem`'s replicates), 3 replicates each."""
    keys = ["point_id", "class_i", "class_j"]
    runs = pd.read_csv(Path(args.dem) / "collisions_replicates.csv").groupby(keys)
    rng = np.random.default_rng(args.seed)
    n, draws = 3, args.draws

    def sides(column):
        mean, sd = runs[column].mean().to_numpy(), runs[column].std(ddof=1).to_numpy()
        x = mean[None, :, None] + sd[None, :, None] * rng.standard_normal((draws, mean.size, n))
        return x.mean(-1), x.std(-1, ddof=1) / np.sqrt(n)

    (f_old, se_old), (f_new, se_new) = sides("encounter_frequency_per_pair"), sides("encounter_frequency_per_pair")
    freq_fail = (np.abs(f_new - f_old) > np.maximum(2 * np.hypot(se_old, se_new), 0.03 * f_old)).sum(axis=1)
    (v_old, _), (v_new, _) = sides("impact_velocity_median"), sides("impact_velocity_median")
    speed_fail = (np.abs(v_new / v_old - 1) > 0.05).sum(axis=1)
    pairs = f_old.shape[1]
    for name, fails in (("frequency criterion", freq_fail), ("median impact speed within 5 %", speed_fail)):
        lo, hi = np.percentile(fails, [5, 95])
        print(
            f"{name}: pairs failing without any change, of {pairs}: mean {fails.mean():.1f}, 5-95 % {lo:.0f}-{hi:.0f}; "
            f"all pass in {100 * np.mean(fails == 0):.2f} % of {draws} draws"
        )


# --------------------------------------------------------------------------------- cost
#: the DEM settings before issue 20: E = 1e7 Pa, two contact snapshots per contact time, positions
#: every fourth snapshot, every run settling its own bed
OLD_YOUNGS_MODULUS = 1.0e7
OLD_SNAPSHOTS_PER_CONTACT = 2
OLD_POSITION_EVERY = 4


def _old_point(point, rpm):
    """`point` with the settings before issue 20 (its snapshot interval as the old rule made it)."""
    old = point.replace(material=point.material.replace(youngs_modulus=OLD_YOUNGS_MODULUS))
    plan = plan_point(old, rpm)
    interval = max(1, int(plan.contact_time / (OLD_SNAPSHOTS_PER_CONTACT * plan.timestep)))
    return old.replace(dem=old.dem.replace(collision_interval=interval, position_every=OLD_POSITION_EVERY))


def _cost_job(job):
    """One side of `cost`, in its own process (its CPU time is its own LIGGGHTS children's)."""
    from pbmdem.dem.plan import plan_bed
    from pbmdem.dem.run import settle_bed

    side, config, rpm, dist, out, baseline = job
    cfg = load_config(baseline if side == "old" and baseline else config)
    point = cfg.dem_point(dist)
    out = Path(out) / side
    if side == "old" and not baseline:
        point = _old_point(point, rpm)
        summary = run_point(plan_point(point, rpm), out / "run", cfg.dem_execution, force=True)
        return side, summary, None
    bed = settle_bed(plan_bed(point), out / "bed", cfg.dem_execution)
    summary = run_point(plan_point(point, rpm), out / "run", cfg.dem_execution, force=True, bed_dir=out / "bed")
    return side, summary, bed


def bench_cost(args) -> None:
    from multiprocessing import Pool

    jobs = [(side, args.config, args.rpm, args.distribution, args.out, args.baseline) for side in ("old", "new")]
    with Pool(2) as pool:
        results = {side: (summary, bed) for side, summary, bed in pool.map(_cost_job, jobs)}
    rows = []
    for side, (summary, bed) in results.items():
        prof = run_profile(Path(args.out) / side / "run")
        bed_cpu = bed["liggghts_cpu_time_s"] / args.speeds if bed else 0.0
        if bed:
            (settle,) = loop_times(Path(args.out) / side / "bed" / "log.liggghts")
            prof["settling_s"] = settle["wall"] / args.speeds
        rows.append(
            prof
            | {
                "side": side,
                "cpu_with_bed_s": summary["liggghts_cpu_time_s"] + bed_cpu,
                "encounters": summary["total_encounters"],
            }
        )
    table = pd.DataFrame(rows).set_index("side")
    cols = ["particles", "dt", "steps", "run_steps", "settling_s", "spinup_s", "history_s", "sampling_s", "dumps_s"]
    cols += ["parse_s", "wall_s", "cpu_s", "cpu_with_bed_s", "psteps_per_cpu_s", "encounters"]
    print(f"{args.distribution} at {args.rpm:g} rpm, old and new DEM settings run at the same time (same load);")
    print(f"the new run's settled bed is shared by {args.speeds} speeds (its settling time divided by that)")
    if args.baseline:
        print(f"old side: {args.baseline}, from its own settled bed, shared likewise")
    print(table[cols].T.to_string(float_format=lambda v: f"{v:.3g}"))
    old, new = table.loc["old"], table.loc["new"]
    with_parse = (old.cpu_with_bed_s + old.parse_s, new.cpu_with_bed_s + new.parse_s)
    print(
        f"speed-up per point: LIGGGHTS CPU {old.cpu_with_bed_s:.1f} s -> {new.cpu_with_bed_s:.1f} s = "
        f"{old.cpu_with_bed_s / new.cpu_with_bed_s:.2f}x; "
        f"with parsing {with_parse[0]:.1f} s -> {with_parse[1]:.1f} s = "
        f"{with_parse[0] / with_parse[1]:.2f}x"
    )


def _skin_value(spec: str, deck: str, diameters) -> float:
    if spec == "run":
        return float(next(line.split()[1] for line in deck.splitlines() if line.startswith("neighbor ")))
    if spec in ("dmin", "dmax"):
        return 0.5 * (min(diameters) if spec == "dmin" else max(diameters))
    return float(spec)


def bench_skin(args) -> None:
    """The deck of each finished run, again, with each skin (interleaved, `repeats` rounds): a
    skin changes which pairs are checked, never the contacts, so only the time differs."""
    import shutil
    import subprocess

    rows = []
    for run_dir in map(Path, args.runs):
        plan = json.loads((run_dir / "plan.json").read_text())
        deck = (run_dir / "in.granulator").read_text()
        skins = {spec: _skin_value(spec, deck, plan["diameters"]) for spec in args.skins.split(",")}
        with tempfile.TemporaryDirectory() as tmp:
            for repeat in range(args.repeats):
                for spec, skin in skins.items():
                    work = Path(tmp) / f"{spec}_{repeat}"
                    (work / "post").mkdir(parents=True)
                    for name in ("bowl.stl", "impeller.stl"):
                        shutil.copy(run_dir / name, work / name)
                    if plan.get("settled_bed"):
                        shutil.copy(Path(args.root) / plan["settled_bed"], work / "bed.restart")
                    lines = [
                        f"neighbor        {skin!r} bin" if line.startswith("neighbor ") else line
                        for line in deck.splitlines()
                    ]
                    (work / "in.granulator").write_text("\n".join(lines) + "\n")
                    subprocess.run(
                        ["liggghts", "-in", "in.granulator", "-log", "log.liggghts"],
                        cwd=work,
                        check=True,
                        stdout=subprocess.DEVNULL,
                    )
                    blocks = loop_times(work / "log.liggghts")
                    rows.append(
                        {
                            "run": f"{plan['point_id']}/rep{plan['replicate']}",
                            "particles": plan["n_particles"],
                            "rpm": plan["rpm"],
                            "skin": spec,
                            "skin_mm": 1e3 * skin,
                            "repeat": repeat,
                            "wall_s": sum(b["wall"] for b in blocks),
                            "neigh_s": sum(b.get("Neigh", 0.0) for b in blocks),
                            "pair_s": sum(b.get("Pair", 0.0) for b in blocks),
                        }
                    )
                    shutil.rmtree(work)
                    print(rows[-1], flush=True)
    table = pd.DataFrame(rows).groupby(["run", "particles", "rpm", "skin", "skin_mm"], sort=False).mean()
    table = table.drop(columns="repeat").reset_index()
    first = table.groupby("run")["wall_s"].transform("first")
    table["against_first"] = table["wall_s"] / first - 1
    print(table.to_markdown(index=False, floatfmt=".3g"))


# --------------------------------------------------------------------------- run totals
RUN_COUNTS = (
    "total_encounters",
    "encounters_first_half",
    "encounters_second_half",
    "wall_encounters_impeller",
    "wall_encounters_bowl",
)


def _half_changes(runs: pd.DataFrame) -> np.ndarray:
    return (runs["encounters_second_half"] / runs["encounters_first_half"] - 1).to_numpy()


def bench_runs(args) -> None:
    """Run-level counts of two results/dem with several replicates per point: the window's totals,
    its two halves and the wall encounters (new / old - 1 with the combined replicate error), and
    per point the change of the half-window trend, with a permutation test of the replicates'
    labels (no normality assumed) over the points together."""
    old, new = (pd.read_csv(Path(d) / "runs.csv") for d in (args.old, args.new))
    if args.skip_replicates:
        skip = {int(k) for k in args.skip_replicates.split(",")}
        old, new = (r[~r["replicate"].isin(skip)] for r in (old, new))
    points = sorted(set(old.point_id) & set(new.point_id))
    print("| point | runs old / new | quantity | new / old - 1 | z |")
    print("| --- | --- | --- | --- | --- |")
    groups = []
    for point in points:
        a, b = new[new.point_id == point], old[old.point_id == point]
        for col in RUN_COUNTS:
            ma, mb = a[col].mean(), b[col].mean()
            se = math.hypot(
                a[col].std(ddof=1) / math.sqrt(len(a)) / mb, b[col].std(ddof=1) / math.sqrt(len(b)) * ma / mb**2
            )
            print(
                f"| {point} | {len(b)} / {len(a)} | {col} | {100 * (ma / mb - 1):+.1f} % +- {100 * se:.1f} % | "
                f"{(ma / mb - 1) / se:+.1f} |"
            )
        ha, hb = _half_changes(a), _half_changes(b)
        se = math.hypot(ha.std(ddof=1) / math.sqrt(ha.size), hb.std(ddof=1) / math.sqrt(hb.size))
        print(
            f"| {point} | {len(b)} / {len(a)} | second half / first half - 1 | old {100 * hb.mean():+.1f} %, new "
            f"{100 * ha.mean():+.1f} % (sd per run {100 * hb.std(ddof=1):.1f} / {100 * ha.std(ddof=1):.1f} %) | "
            f"{(ha.mean() - hb.mean()) / se:+.1f} |"
        )
        groups.append((ha, hb))

    def spread(pairs):
        return sum(abs(x.mean() - y.mean()) for x, y in pairs)

    rng = np.random.default_rng(args.seed)
    observed, beyond = spread(groups), 0
    for _ in range(args.draws):
        shuffled = []
        for ha, hb in groups:
            both = rng.permutation(np.concatenate([ha, hb]))
            shuffled.append((both[: ha.size], both[ha.size :]))
        beyond += spread(shuffled) >= observed
    print(
        f"\nhalf-window trend, sum over the {len(points)} points of |new - old|: {100 * observed:.1f} %; "
        f"permutation p = {beyond / args.draws:.4f} ({args.draws} draws)"
    )


def bench_quick() -> None:
    """Every subcommand on the tiny test configuration (config/test.yaml), in a temporary folder:
    a DEM grid of one point with 2 replicates (quick.dem_grid) stands for results/dem; acceptance
    and runs compare it with itself (no change: every pair agrees)."""
    import quick

    ns = argparse.Namespace
    config, rpm, dist = str(quick.TEST_CONFIG), 600.0, "small"
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        dem = str(quick.dem_grid(tmp, rpm=rpm, distribution=dist, replicates=2))
        print(f"quick: DEM grid of {dist} at {rpm:g} rpm, 2 replicates, {time.perf_counter() - t0:.1f} s", flush=True)
        steps = {
            "point": (bench_point, ns(config=config, rpm=rpm, distribution=dist)),
            "profile": (bench_profile, ns(dem=[dem])),
            "acceptance": (bench_acceptance, ns(old=dem, new=dem)),
            "null": (bench_null, ns(dem=dem, draws=200, seed=1)),
            "runs": (bench_runs, ns(old=dem, new=dem, skip_replicates=None, draws=200, seed=1)),
            "skin": (
                bench_skin,
                ns(runs=[str(next(Path(dem).glob("rpm*/rep0")))], skins="run,dmax", repeats=1, root="."),
            ),
            "cost": (
                bench_cost,
                ns(config=config, rpm=rpm, distribution=dist, speeds=2, out=str(Path(tmp) / "cost"), baseline=None),
            ),
        }
        for name, (command, args) in steps.items():
            print(f"\n=== bench_dem.py {name} (quick)", flush=True)
            t0 = time.perf_counter()
            command(args)
            print(f"=== {name}: {time.perf_counter() - t0:.1f} s", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="every subcommand on the tiny config (smoke test)")
    sub = parser.add_subparsers(dest="command")
    point = sub.add_parser("point", help="one point with the real LIGGGHTS: speed, parse cost, snapshot interval")
    point.add_argument("--config", default=str(ROOT / "config" / "config.yaml"))
    point.add_argument("--rpm", type=float, default=600.0)
    point.add_argument("--distribution", default="fine")
    profile = sub.add_parser("profile", help="per-phase LIGGGHTS time of the finished runs of a results/dem")
    profile.add_argument("dem", nargs="+")
    accept = sub.add_parser("acceptance", help="old against new DEM settings, every point and pair")
    accept.add_argument("old")
    accept.add_argument("new")
    null = sub.add_parser("null", help="pairs the acceptance fails when nothing changes (replicate noise)")
    null.add_argument("dem")
    null.add_argument("--draws", type=int, default=4000)
    null.add_argument("--seed", type=int, default=1)
    cost = sub.add_parser("cost", help="one point with the old and the new DEM settings side by side")
    cost.add_argument("--config", default=str(ROOT / "config" / "config.yaml"))
    cost.add_argument("--rpm", type=float, default=600.0)
    cost.add_argument("--distribution", default="fine")
    cost.add_argument("--speeds", type=int, default=4, help="speeds that share one settled bed")
    cost.add_argument("--out", default="results/bench_dem_cost")
    cost.add_argument(
        "--baseline",
        help="config of the old side (run like the new side, from its own settled bed); "
        "default: the settings before issue 20",
    )
    skin = sub.add_parser("skin", help="finished runs again with other neighbour skins, side by side")
    skin.add_argument("runs", nargs="+", help="run folders (results/dem/rpm*/rep*, or a coupled loop's dem/)")
    skin.add_argument("--skins", default="run,dmin,dmax")
    skin.add_argument("--repeats", type=int, default=2)
    skin.add_argument("--root", default=".", help="the project the runs' settled beds are relative to")
    runs = sub.add_parser("runs", help="run-level totals, halves and wall encounters of two results/dem")
    runs.add_argument("old")
    runs.add_argument("new")
    runs.add_argument("--skip-replicates", help="replicates to leave out, e.g. 0 (runs chosen for failing)")
    runs.add_argument("--draws", type=int, default=20000)
    runs.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    if args.quick:
        bench_quick()
        return
    if args.command is None:
        parser.error("a subcommand is required (or --quick)")
    commands = {"point": bench_point, "profile": bench_profile, "acceptance": bench_acceptance, "cost": bench_cost}
    commands["null"] = bench_null
    commands["skin"] = bench_skin
    commands["runs"] = bench_runs
    commands[args.command](args)


if __name__ == "__main__":
    main()
