"""Render the LIGGGHTS deck of every planned DEM run of a config into a folder (to diff two trees).

For each grid point and replicate: the bed deck (1 rank and dem.mpi_ranks), the fresh deck and the
deck from a settled bed; for each validation speed: the coupled loop's call with the largest
sample (dem.max_particles), as the Snakefile's limit check plans it; and each plan's record
(`to_dict`, written to plan.json and bed.json). Used to show that a change of the planner or the
renderer leaves every deck byte-identical: render with both versions, then `diff -r`.

    python benchmarks/render_decks.py CONFIG OUT_DIR
    python benchmarks/render_decks.py --quick     (config/test.yaml into a temporary folder)
"""

import json
import sys
import tempfile
from pathlib import Path

from pbmdem.config import load_config
from pbmdem.dem import deck
from pbmdem.dem.plan import class_counts, plan_point


def write_decks(cfg, out: Path) -> int:
    ranks = cfg.dem_execution.mpi_ranks
    loop = cfg.coupled_loop().dem_point()
    largest = class_counts(cfg.dem.max_particles, loop.sizes.number_fractions)
    runs = [
        (cfg.dem_point(dist), rpm, rep, None, "grid")
        for rpm, dist in cfg.grid.points()
        for rep in range(cfg.point_replicates(dist))
    ]
    runs += [(loop, rpm, 0, largest, "loop") for rpm in cfg.validation.rpm]
    n = 0
    for point, rpm, rep, counts, kind in runs:
        plan = plan_point(point, rpm, replicate=rep, counts=counts)
        stem = f"{kind}_{plan.point_id}_rep{rep}"
        # the plan's record (plan.json, and bed.json's "bed")
        record = {"plan": plan.to_dict(), "bed": plan.bed.to_dict()}
        (out / f"{stem}_plan.json").write_text(json.dumps(record, indent=1))
        for r in sorted({1, ranks}):
            bed = deck.render_bed(plan.bed, r)
            (out / f"{stem}_bed_{r}rank.in").write_text(bed)
            n += 1
        for from_bed in (False, True):
            text = deck.render_granulator(plan, ranks, from_bed=from_bed)
            (out / f"{stem}_{'from_bed' if from_bed else 'fresh'}.in").write_text(text)
            n += 1
    return n


def main(config: Path, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    print(f"{config}: {write_decks(load_config(config), out)} decks in {out}")


if __name__ == "__main__":
    if sys.argv[1:] == ["--quick"]:
        with tempfile.TemporaryDirectory() as tmp:
            main(Path(__file__).resolve().parents[1] / "config" / "test.yaml", Path(tmp))
    else:
        main(Path(sys.argv[1]), Path(sys.argv[2]))
