"""Many short PBM batches at once, the engine of the design space and of the calibration: a `Case`
is one batch (speed, the pbm settings it changes, its frequency source), `run_cases` runs them
over forked processes (docs/design.md, "Many batches at once"; where the time goes:
benchmarks/bench_design_space.py).
"""

from __future__ import annotations

import functools
import logging
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.config import CoupledLoop
from pbmdem.config.design import with_pbm_values
from pbmdem.coupling import pbm_ann
from pbmdem.coupling.loop import CouplingError
from pbmdem.pbm.errors import PBMError
from pbmdem.pbm.setup import run_batch
from pbmdem.surrogate import load_surrogate
from pbmdem.surrogate._threads import single_threaded
from pbmdem.tables import STATISTICS

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Case:
    """One batch: `rpm`, the pbm settings it changes, and its source: `kernel` "ann" (the
    surrogate; `member` None: the ensemble mean, k: member k alone) or "constant"."""

    rpm: float
    values: tuple[tuple[str, float], ...] = ()
    member: int | None = None
    kernel: str = "ann"

    def loop(self, loop: CoupledLoop) -> CoupledLoop:
        """`loop` with this case's pbm settings."""
        if not self.values:
            return loop
        pbm = with_pbm_values(loop.batch.pbm, dict(self.values))
        return loop.replace(batch=loop.batch.replace(pbm=pbm))


@dataclass
class Outcome:
    """A finished (or failed) case: d10/d50/d90 (m) at the recorded times, its out-of-domain count and
    the error of a failed batch (e.g. granules that outgrew the PBM grid)."""

    case: Case
    times: np.ndarray = field(default_factory=lambda: np.empty(0))
    sizes: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))  # (T, 3): d10, d50, d90
    out_of_domain_intervals: int = 0
    out_of_domain_count: int = 0
    failed: str = ""

    def final(self) -> dict:
        """The final d10/d50/d90 (NaN for a failed case)."""
        if self.failed or not len(self.times):
            return dict.fromkeys(STATISTICS, float("nan"))
        return dict(zip(STATISTICS, (float(v) for v in self.sizes[-1]), strict=True))

    def at(self, times) -> np.ndarray:
        """(len(times), 3) d10/d50/d90 at `times` (s), linear between the recorded times."""
        times = np.asarray(times, float)
        if self.failed:
            return np.full((times.size, 3), np.nan)
        return np.column_stack([np.interp(times, self.times, self.sizes[:, k]) for k in range(3)])


@functools.lru_cache(maxsize=2)
def _surrogate(path: str, mtime: float):
    """The surrogate at `path` with its members, loaded once per process (and per file version)."""
    model = load_surrogate(path)
    return model, [model.member(k) for k in range(model.n_members)]


def run_case(loop: CoupledLoop, model_path: str | Path | None, case: Case) -> Outcome:
    """Run one case in memory. Out-of-domain warnings are counted in the outcome (the caller
    reports them); a batch the PBM or the loop refuses is a failed outcome with the error."""
    case_loop = case.loop(loop)  # a bad config key raises here, not as a failed case
    try:
        if case.kernel == "constant":
            result = run_batch(case_loop.batch, None, case.rpm)
            totals: dict = {}
        else:
            mean, members = _surrogate(str(model_path), Path(model_path).stat().st_mtime)
            model = mean if case.member is None else members[case.member]
            outcome = pbm_ann(case_loop, model, case.rpm, None, log_each=False)
            result, totals = outcome.result, outcome.totals
    except (PBMError, CouplingError, ValueError) as exc:
        # ValueError: a bed the granules outgrew so far that no representative DEM sample is left
        # (pbmdem.coupling.sample); the settings were checked before (case.loop)
        return Outcome(case, failed=str(exc))
    return Outcome(
        case,
        np.asarray(result.times, float),
        result.size_quantiles(),  # d10, d50, d90: STATISTICS
        int(totals.get("out_of_domain_intervals", 0)),
        int(totals.get("out_of_domain_count", 0)),
    )


#: Fewer cases run in this process: starting and ending a pool of forked processes costs about 0.1 s,
#: the time of 3-4 PBM-ANN batches of the default study (measured: 3 batches 0.21 s in order, 0.24 s
#: on 2 processes; PBM-constant 0.03 s against 0.14 s).
MIN_POOLED_CASES = 8


def _run_chunk(loop: CoupledLoop, model_path, cases: list[Case]) -> list[Outcome]:
    with single_threaded():
        return [run_case(loop, model_path, case) for case in cases]


def run_cases(loop: CoupledLoop, model_path, cases: list[Case], n_jobs: int = 1) -> list[Outcome]:
    """The outcomes of `cases` (in their order), over `n_jobs` processes forked from this one after it
    has loaded the surrogate and compiled the PBM; they end with the call."""
    cases = list(cases)
    if n_jobs <= 1 or len(cases) < MIN_POOLED_CASES:
        return _run_chunk(loop, model_path, cases)
    if model_path is not None and any(c.kernel == "ann" for c in cases):
        _surrogate(str(model_path), Path(model_path).stat().st_mtime)
    # the first case runs here: it compiles the PBM's kernels once, not in every process
    first = _run_chunk(loop, model_path, cases[:1])
    rest = cases[1:]
    # a few chunks per process: the load stays balanced and each chunk pays one transfer
    n_chunks = min(len(rest), 4 * n_jobs)
    bounds = np.linspace(0, len(rest), n_chunks + 1).astype(int)
    chunks = [rest[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    context = multiprocessing.get_context("fork")
    with ProcessPoolExecutor(max_workers=min(n_jobs, n_chunks), mp_context=context) as pool:
        done = list(pool.map(_run_chunk, [loop] * len(chunks), [model_path] * len(chunks), chunks))
    return first + [outcome for chunk in done for outcome in chunk]


def outcomes_table(outcomes: list[Outcome]) -> pd.DataFrame:
    """One row per case: rpm, member, changed settings, final d10/d50/d90, domain status, failure."""
    rows = []
    for o in outcomes:
        row = {"rpm": o.case.rpm, "member": -1 if o.case.member is None else o.case.member}
        row.update(dict(o.case.values))
        row.update(o.final())
        row.update(
            out_of_domain_intervals=o.out_of_domain_intervals,
            out_of_domain_count=o.out_of_domain_count,
            failed=o.failed,
        )
        rows.append(row)
    return pd.DataFrame(rows)
