"""The coupled loop: the PBM over equal coupling intervals of the batch, with the collision
frequencies of each interval from a provider (LIGGGHTS for PBM-DEM, the surrogate for PBM-ANN).

At the start of each interval the PBM's size distribution becomes the representative DEM sample
(`sample.representative_sample`); the provider gives its class frequencies, which are
interpolated onto the PBM bins (`class_source.ClassFrequencySource`) and held for the interval.
Every finished interval is written to disk before the next begins (`intervals`); a rerun resumes
after the last finished interval.
"""

from __future__ import annotations

import functools
import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.atomic import write_csv, write_json
from pbmdem.config import CoupledLoop
from pbmdem.frequency import pair_weighted_mean, pairs_of
from pbmdem.impact import EncounterRates, ImpactRates
from pbmdem.pbm.impact_breakage import impact_selection
from pbmdem.pbm.kernels import ConstantFrequency
from pbmdem.pbm.results import Result, floor_words
from pbmdem.pbm.setup import build_model, initial_state, output_times

from . import intervals
from .class_source import ClassFrequencySource
from .sample import representative_sample

log = logging.getLogger(__name__)


class CouplingError(RuntimeError):
    """The coupled loop stopped; finished intervals are kept on disk."""


@dataclass
class LoopOutcome:
    """A finished loop: the PBM result of the whole batch, the per-interval records and the totals
    of timing.json (wall times, out-of-domain counts)."""

    result: object
    intervals: list[dict]
    totals: dict


@functools.lru_cache(maxsize=4)  # few: the design space and sensitivity run many batches of a few settings in turn
def _built(batch):
    """(model, its breakage selection from impacts or None, the initial state) of the batch
    settings ``batch``, built once in this process; building the model and its operators took about
    1 ms of a few-ms batch."""
    selection = impact_selection(batch.pbm)  # breakage from each interval's impacts (None: aggregation only)
    model = build_model(batch.pbm, ConstantFrequency(1.0), selection=selection)  # sources per interval
    return model, selection, initial_state(batch, model)


def _model_of(batch, rpm: float):
    """The model of ``batch`` (:func:`_built`) at ``rpm``, its selection and a copy of the initial
    state: the frequency source and the selection's source are set anew by every interval and the
    run state by every run (``GranulationPBM.run``: the classes, the kernel and the breakage
    reset), so a batch gives the same result to the bit whatever ran before
    (tests/test_pbm_fast_steps.py)."""
    model, selection, state = _built(batch)
    model.set_rpm(rpm)
    return model, selection, state.copy()


def _no_clock() -> float:
    """NaN: a CPU time not measured."""
    return float("nan")


def interval_bounds(loop: CoupledLoop) -> np.ndarray:
    """Start and end times (s) of the coupling intervals: equal parts of the whole batch."""
    return np.linspace(0.0, loop.batch.pbm.process.end, loop.coupling_intervals + 1)


def write_outputs(outdir: Path, result, rows: list[dict], totals: dict) -> None:
    """summary.csv (PBM time series), bins.csv (the size distribution at every recorded time),
    final_bins.csv (at the end), intervals.csv (if any) and timing.json."""
    write_csv(outdir / "summary.csv", result.summary())
    bins = result.bins()
    write_csv(outdir / "bins.csv", bins)
    write_csv(outdir / "final_bins.csv", bins[bins.time == bins.time.max()])
    if rows:
        write_csv(outdir / "intervals.csv", pd.DataFrame(rows))
    write_json(outdir / "timing.json", totals)


def _prepared(outdir, loop: CoupledLoop, rpm: float, provider) -> Path | None:
    """The loop's folder, made, with the finished intervals of other inputs discarded (None: in memory)."""
    if outdir is None:
        return None
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    intervals.discard_stale(outdir, {"loop": loop.to_dict(), "rpm": float(rpm), "provider": provider.fingerprint()})
    return outdir


def _sample_record(sample, matrix: np.ndarray) -> dict:
    """An interval's sample and its class frequencies as intervals.csv records them (a loop in
    memory, one of the design space's many short batches, skips them: nothing reads them there)."""
    return {
        "class_diameters": json.dumps(sample.diameters),
        "class_counts": json.dumps(sample.counts),
        "sample_particles": sample.n_particles,
        "class_frequencies": json.dumps(pairs_of(matrix).tolist()),
        "mean_frequency_per_pair": pair_weighted_mean(matrix, sample.counts),
    }


def run_loop(loop: CoupledLoop, provider, rpm: float, outdir: str | Path | None) -> LoopOutcome:
    """Run the PBM of `loop` at `rpm` over its coupling intervals, asking
    `provider(sample, interval_dir, index) -> (rates, info)` for the frequencies of each.

    Writes `outdir/interval_NN/` per interval, then `summary.csv`, `intervals.csv` (per interval:
    classes, frequencies, wall times, out-of-domain warnings), `final_bins.csv` and `timing.json`.
    With `outdir=None` the loop runs in memory (nothing written, nothing resumed): the many short
    PBM-ANN batches of the design space and the calibration, whose time would otherwise go to
    writing files (`interval_dir` is then None; only the surrogate provider accepts that).
    """
    n_intervals = loop.coupling_intervals
    outdir = _prepared(outdir, loop, rpm, provider)
    pbm = loop.batch.pbm
    model, selection, state = _model_of(loop.batch, rpm)
    bounds = interval_bounds(loop)
    results, rows = [], []
    previous = None  # (rates, class diameters, source) of the last interval run here
    checked = True  # the state is the model's (initial, or a run's): not checked again; False: read from disk
    for k in range(n_intervals):
        folder = None if outdir is None else outdir / f"interval_{k:02d}"
        if folder is not None and intervals.is_finished(folder):
            result, info, _ = intervals.load(folder, model.grid)
            log.info("interval %d of %s: resumed from %s", k, provider.name, folder)
            results.append(result)
            rows.append({key: v for key, v in info.items() if key != "sample"})
            state, checked = result.state, False
            continue
        t0, t1 = bounds[k], bounds[k + 1]
        sample = representative_sample(*model.particle_classes(state), loop.sample)
        # CPU seconds only for a loop on disk (a system call each: the many in-memory batches skip them)
        cpu = time.process_time if outdir is not None else _no_clock
        t_provider, cpu_provider = time.perf_counter(), cpu()
        try:
            rates, extra = provider(sample, folder, k)
        except Exception as exc:
            raise CouplingError(
                f"{provider.name} at rpm {rpm:g}: interval {k} ({t0:g}-{t1:g} s) failed: {exc}. "
                f"Intervals 0..{k - 1} are kept in {outdir}; rerun to resume."
            ) from exc
        provider_wall, provider_cpu = time.perf_counter() - t_provider, cpu() - cpu_provider
        # LIGGGHTS work borrowed from the DEM grid (a run, a settled bed) counts as the interval's own
        provider_wall += float(extra.get("dem_borrowed_wall_time_s", 0.0))
        label = f"{provider.name} interval {k}"
        if previous is not None and previous[0] is rates and previous[1] == list(sample.diameters):
            # the provider's prediction of the interval before (the same sample): the same source,
            # whose interpolation and the selection's impacts on the pivots are those computed then
            source = previous[2]
            source.label = label
        else:
            source = ClassFrequencySource(sample.diameters, rates, label)
            model.kernel.set_source(source)
            if selection is not None:
                selection.set_source(source)
        previous = (rates, list(sample.diameters), source)
        pairs = rates.pairs if isinstance(rates, ImpactRates) else rates
        matrix = pairs.frequency if isinstance(pairs, EncounterRates) else np.asarray(pairs, float)
        t_pbm, cpu_pbm = time.perf_counter(), cpu()
        result = model.run(t0, t1, state, output_times=output_times(pbm, t0, t1), checked=checked)
        pbm_wall, pbm_cpu = time.perf_counter() - t_pbm, cpu() - cpu_pbm
        info = {
            "interval": k,
            "t_start": t0,
            "t_end": t1,
            "rpm": rpm,
            "method": provider.name,
            "classes": len(sample.counts),
            **(_sample_record(sample, matrix) if folder is not None else {}),
            "provider_wall_time_s": provider_wall,
            "pbm_wall_time_s": pbm_wall,
            # CPU seconds of this process (a DEM provider adds its LIGGGHTS processes' in dem_cpu_time_s)
            "provider_cpu_time_s": provider_cpu,
            "pbm_cpu_time_s": pbm_cpu,
            **extra,
        }
        if folder is not None:
            intervals.save(folder, result, sample, matrix, info)
        what, warned = "DEM" if provider.name == "pbm_dem" else "provider", int(extra.get("out_of_domain_count", 0))
        log.log(
            logging.INFO if folder is not None else logging.DEBUG,
            "%s at rpm %g: interval %d of %d (%.4g-%.4g s) done: %s wall time %.2f s, PBM wall time %.3f s, "
            "%d surrogate out-of-domain warning(s)",
            *(provider.name, rpm, k + 1, n_intervals, t0, t1, what, provider_wall, pbm_wall, warned),
        )
        results.append(result)
        rows.append(info)
        state, checked = result.state, True
    full = Result.concat(results)
    totals = _totals(provider.name, rpm, loop, rows, in_memory=outdir is None)
    totals["grid_floor"] = floor = full.info["grid_floor"]
    # breakage fragments merged into the first pivot: a warning above FLOOR_LIMIT of the final
    # number (for a loop in memory the caller reports it, as the out-of-domain counts)
    level = logging.WARNING if floor["flagged"] else logging.INFO
    log.log(
        logging.DEBUG if outdir is None else level,
        "%s",
        floor_words(floor, f"{provider.name} at rpm {rpm:g}, feed {loop.batch.distribution}"),
    )
    if outdir is not None:
        write_outputs(outdir, full, rows, totals)
    return LoopOutcome(full, rows, totals)


def _totals(method: str, rpm: float, loop: CoupledLoop, rows: list[dict], in_memory: bool = False) -> dict:
    """The loop's totals (timing.json): wall times, and the out-of-domain warnings over its
    intervals (logged as a warning when there were any; for a loop in memory, `in_memory`, the
    caller reports them). `run_loop` adds the grid floor (`Result.grid_floor`)."""
    totals = {
        "method": method,
        "rpm": rpm,
        "distribution": loop.batch.distribution,
        "intervals": loop.coupling_intervals,
        "provider_wall_time_s": float(sum(r["provider_wall_time_s"] for r in rows)),
        "pbm_wall_time_s": float(sum(r["pbm_wall_time_s"] for r in rows)),
        # CPU seconds: this process's in the provider and the PBM, and the DEM's LIGGGHTS processes
        # (0 for a surrogate); intervals resumed from an earlier run count as recorded then
        "provider_cpu_time_s": float(sum(r.get("provider_cpu_time_s", float("nan")) for r in rows)),
        "pbm_cpu_time_s": float(sum(r.get("pbm_cpu_time_s", float("nan")) for r in rows)),
        "dem_cpu_time_s": float(sum(r.get("dem_cpu_time_s", 0.0) for r in rows)),
    }
    if any("out_of_domain_count" in r for r in rows):
        per_interval = [int(r.get("out_of_domain_count", 0) or 0) for r in rows]
        totals["out_of_domain_count"] = int(sum(per_interval))
        totals["out_of_domain_intervals"] = int(sum(c > 0 for c in per_interval))
        if totals["out_of_domain_count"]:
            # a loop in memory hands its counts to the caller, which reports them (the design
            # space marks each point and warns with the number of such points)
            log.log(
                logging.DEBUG if in_memory else logging.WARNING,
                "%s at rpm %g: the surrogate was outside its training domain in %d of %d intervals "
                "(%d warnings; see intervals.csv)",
                method,
                rpm,
                totals["out_of_domain_intervals"],
                len(rows),
                totals["out_of_domain_count"],
            )
    totals["total_wall_time_s"] = totals["provider_wall_time_s"] + totals["pbm_wall_time_s"]
    totals["total_cpu_time_s"] = totals["provider_cpu_time_s"] + totals["pbm_cpu_time_s"] + totals["dem_cpu_time_s"]
    return totals
