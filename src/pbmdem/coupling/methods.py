"""The three models of the validation study, one function each (docs/validation.md).

The surrogate is imported where it is loaded: a PBM-DEM job does not load scikit-learn.

* `pbm_dem`: the fully coupled PBM-DEM loop (LIGGGHTS at every coupling interval);
* `pbm_ann`: the same loop with the surrogate instead of LIGGGHTS. This is the one definition of
  PBM-ANN: the validation rules and `pbmdem pbm --kernel ann` both run it, with the frequencies
  refreshed at the start of each of `validation.coupling_intervals` intervals;
* `pbm_constant`: one constant c for every pair all along, calibrated to the surrogate's
  pair-weighted mean frequency of the initial sample (the same initial collision rate).
"""

from __future__ import annotations

import logging
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.config import CoupledLoop, DemExecution
from pbmdem.frequency import pair_weighted_mean
from pbmdem.pbm.breakage import ConstantSelection
from pbmdem.pbm.errors import PBMError
from pbmdem.pbm.kernels import ConstantFrequency
from pbmdem.pbm.results import floor_words
from pbmdem.pbm.setup import build_model, initial_state, run_batch
from pbmdem.surrogate import load_surrogate
from pbmdem.surrogate._threads import single_threaded
from pbmdem.surrogate.domain import out_of_domain_recorded

from .loop import CouplingError, LoopOutcome, interval_bounds, run_loop, write_outputs
from .providers import DemProvider, SurrogateProvider, surrogate_needs
from .sample import representative_sample


def pbm_dem(
    loop: CoupledLoop,
    rpm: float,
    outdir: str | Path,
    execution: DemExecution,
    replicate: int,
    grid_run: str | Path | None = None,
    bed_dir: str | Path | None = None,
) -> LoopOutcome:
    """PBM-DEM at `rpm`: LIGGGHTS runs the representative sample of every interval (insertion
    seeds of `replicate`). `grid_run`, `bed_dir`: the DEM grid's run of the feed at this speed and
    replicate and its settled bed, which an interval of the feed borrows where they are its own
    plan's (`providers.DemProvider`)."""
    provider = DemProvider(loop, rpm, execution, replicate, grid_run=grid_run, bed_dir=bed_dir)
    return run_loop(loop, provider, rpm, outdir)


def pbm_ann(
    loop: CoupledLoop,
    model_path,
    rpm: float,
    outdir: str | Path | None,
    member: int | None = None,
    log_each: bool = True,
) -> LoopOutcome:
    """PBM-ANN at `rpm`: the surrogate in `model_path` (its ensemble mean, or member `member`
    alone) gives the frequencies of every interval. `model_path` may be a loaded surrogate and
    `outdir` None for a batch run in memory (nothing written); `log_each=False`: the caller logs
    the out-of-domain warnings (their count is in the outcome's totals either way)."""
    provider = SurrogateProvider(model_path, rpm, member, log_each, needs=surrogate_needs(loop.batch.pbm))
    return run_loop(loop, provider, rpm, outdir)


#: in-memory PBM-ANN batches timed after one warm-up batch (:func:`warm_batch_times`)
WARM_BATCHES = 9


def warm_batch_times(loop: CoupledLoop, model, rpm: float, repeats: int = WARM_BATCHES) -> dict:
    """PBM-ANN's cost of one batch at `rpm` as a benchmark measures it: the surrogate (`model`: a
    path or a loaded one) loaded once, one batch to warm up (lazy imports, caches, thread pools),
    then `repeats` batches in memory, on one BLAS/OpenMP thread as the design space and the
    benchmarks run them (a job with two threads would otherwise count an idle thread pool's CPU).
    Returns the median, min and max of their wall and CPU seconds (CPU: this process's), keys
    ``warm_{wall,cpu}_time_s_{median,min,max}`` and ``warm_batches``: what the comparison's speed
    ratio uses (docs/validation.md)."""
    loaded = load_surrogate(model) if isinstance(model, (str, Path)) else model
    walls, cpus = [], []
    with single_threaded():
        pbm_ann(loop, loaded, rpm, None, log_each=False)
        for _ in range(int(repeats)):
            t0, c0 = time.perf_counter(), time.process_time()
            pbm_ann(loop, loaded, rpm, None, log_each=False)
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
    out = {"warm_batches": int(repeats)}
    for name, values in (("wall", walls), ("cpu", cpus)):
        out |= {
            f"warm_{name}_time_s_median": float(np.median(values)),
            f"warm_{name}_time_s_min": float(np.min(values)),
            f"warm_{name}_time_s_max": float(np.max(values)),
        }
    return out


def pbm_ann_members(loop: CoupledLoop, model_path: str | Path, rpm: float):
    """PBM-ANN once per ensemble member of the surrogate: one row per (member, recorded time)
    with d10, d50, d90 (m), mean liquid content and porosity, and the member's wall time (s).
    The members' spread is PBM-ANN's uncertainty band (docs/validation.md). A member whose PBM
    fails (e.g. its extrapolated frequencies grow granules beyond the grid) is kept as one row
    with its error in `failed` and no sizes, and logged: it is reported, not dropped."""
    n = load_surrogate(model_path).n_members
    frames = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(n):
            t0 = time.perf_counter()
            try:
                outcome = pbm_ann(loop, model_path, rpm, Path(tmp) / f"member{k}", member=k)
            except (PBMError, CouplingError) as exc:
                logging.getLogger(__name__).warning("PBM-ANN at rpm %g with ensemble member %d failed: %s", rpm, k, exc)
                frames.append(
                    pd.DataFrame(
                        {
                            "member": [k],
                            "time": [np.nan],
                            "failed": [str(exc)],
                            "wall_time_s": [time.perf_counter() - t0],
                        }
                    )
                )
                continue
            s = outcome.result.summary()
            frames.append(
                pd.DataFrame(
                    {
                        "member": k,
                        "time": s.time,
                        "d10": s.d10,
                        "d50": s.d50,
                        "d90": s.d90,
                        "mean_liquid_content": s.mean_liquid_content,
                        "mean_porosity": s.mean_porosity,
                        "out_of_domain_intervals": outcome.totals.get("out_of_domain_intervals", 0),
                        "failed": "",
                        "wall_time_s": time.perf_counter() - t0,
                    }
                )
            )
    return pd.concat(frames, ignore_index=True)


def calibrated_frequency(loop: CoupledLoop, model_path: str | Path, rpm: float) -> tuple[float, list[str]]:
    """The surrogate's pair-weighted mean per-pair frequency of the initial sample (1/s), and its
    out-of-domain warnings (logged)."""
    model = build_model(loop.batch.pbm, ConstantFrequency(1.0), rpm=rpm, selection=constant_selection(loop))
    state = initial_state(loop.batch, model)
    sample = representative_sample(*model.particle_classes(state), loop.sample)
    surrogate = load_surrogate(model_path)
    with out_of_domain_recorded(f"constant-kernel calibration at rpm {rpm:g}") as found:
        c = surrogate.frequency_matrix(np.asarray(sample.diameters), np.asarray(sample.counts, float), rpm)
    return pair_weighted_mean(c, sample.counts), found


def constant_selection(loop: CoupledLoop):
    """PBM-constant's breakage selection: pbm.breakage.constant_rate for every aggregate (used
    only with pbm.breakage.enabled)."""
    return ConstantSelection(loop.batch.pbm.breakage.constant_rate)


def pbm_constant(loop: CoupledLoop, model_path: str | Path, rpm: float, outdir: str | Path) -> LoopOutcome:
    """PBM-constant at `rpm`: c for every pair = the calibrated frequency, and with breakage the
    selection rate pbm.breakage.constant_rate for every aggregate, for the whole batch."""
    frequency, found = calibrated_frequency(loop, model_path, rpm)
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    result = run_batch(loop.batch, ConstantFrequency(frequency), rpm, selection=constant_selection(loop))
    wall = time.perf_counter() - t0
    totals = {
        "method": "pbm_constant",
        "rpm": rpm,
        "distribution": loop.batch.distribution,
        "frequency": frequency,
        "total_wall_time_s": wall,
        "pbm_wall_time_s": wall,
        "provider_wall_time_s": 0.0,
        "out_of_domain": "; ".join(sorted(set(found))),
        "out_of_domain_count": len(found),
        "grid_floor": result.info["grid_floor"],
    }
    floor = totals["grid_floor"]
    logging.getLogger(__name__).log(
        logging.WARNING if floor["flagged"] else logging.INFO,
        "%s",
        floor_words(floor, f"pbm_constant at rpm {rpm:g}, feed {loop.batch.distribution}"),
    )
    write_outputs(outdir, result, [], totals)
    return LoopOutcome(result, [], totals)


__all__ = [
    "pbm_dem",
    "pbm_ann",
    "pbm_ann_members",
    "pbm_constant",
    "calibrated_frequency",
    "interval_bounds",
    "warm_batch_times",
]
