"""Global sensitivity: Sobol' indices (SALib's estimator) of PBM-ANN's final d10/d50/d90 to impeller
speed and pbm settings over stated ranges, for the ensemble mean and every member on one sample,
and their figure (docs/design.md, "Global sensitivity").
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from SALib.analyze import sobol as sobol_analyze
from SALib.sample import sobol as sobol_sample

from pbmdem.config import CoupledLoop, Sensitivity, SobolFactor
from pbmdem.config.design import SPEED
from pbmdem.plotting import pyplot, save_figure
from pbmdem.surrogate import load_surrogate

from .batches import STATISTICS, Case, outcomes_table, run_cases

log = logging.getLogger(__name__)

#: the columns of the indices table
COLUMNS = ("parameter", "output", "member", "S1", "S1_conf", "ST", "ST_conf")
#: the words for the factors in figures and text
LABELS = {
    SPEED: "impeller speed",
    "pbm.liquid_addition.rate": "binder rate",
    "pbm.process.wet_massing_time": "wet-massing time",
    "pbm.breakage.yield_strength": "granule strength Y",
    "pbm.aggregation.beta0": "coalescence fraction beta0",
}
#: SALib's name of each scale's distribution
_DISTS = {"linear": "unif", "log": "logunif"}


def label(key: str) -> str:
    """A factor's name in words (its config key if it has none)."""
    return LABELS.get(key, key)


def salib_problem(factors: Sequence[SobolFactor]) -> dict:
    """SALib's problem of `factors`: names, bounds and distributions (uniform, log-uniform)."""
    return {
        "num_vars": len(factors),
        "names": [f.key for f in factors],
        "bounds": [[f.low, f.high] for f in factors],
        "dists": [_DISTS[f.scale] for f in factors],
    }


def sample(problem: dict, base_samples: int, seed: int) -> np.ndarray:
    """Saltelli's sample matrix, N (D + 2) rows of the D factors (SALib; no second-order indices)."""
    return sobol_sample.sample(problem, base_samples, calc_second_order=False, scramble=True, seed=seed)


def indices(problem: dict, outputs: pd.DataFrame, columns: Sequence[str], *, confidence, resamples, seed):
    """S1, ST and their interval half-widths of each output column (rows: parameter, output)."""
    rows = []
    for column in columns:
        y = outputs[column].to_numpy(float)
        constant = np.isfinite(y).all() and np.ptp(y) <= 1e-12 * np.abs(y).max()
        if constant:
            log.warning("sensitivity: %s does not vary over the samples: its indices are undefined", column)
        if constant or not np.isfinite(y).all():
            s = dict.fromkeys(("S1", "S1_conf", "ST", "ST_conf"), np.full(len(problem["names"]), np.nan))
        else:
            s = sobol_analyze.analyze(
                problem, y, calc_second_order=False, num_resamples=resamples, conf_level=confidence, seed=seed
            )
        for k, name in enumerate(problem["names"]):
            rows.append({"parameter": name, "output": column, **{key: float(s[key][k]) for key in COLUMNS[3:]}})
    return pd.DataFrame(rows)


@dataclass(frozen=True)
class Study:
    """A finished study: the indices table (`COLUMNS`), the sample matrix and each model's outputs."""

    table: pd.DataFrame
    samples: np.ndarray
    outputs: dict[str, pd.DataFrame]


def sobol_study(
    factors: Sequence[SobolFactor],
    models: Mapping[str, Callable[[np.ndarray], pd.DataFrame]],
    columns: Sequence[str],
    *,
    base_samples: int,
    seed: int,
    confidence: float,
    resamples: int,
) -> Study:
    """Sobol' indices of the output `columns` of every model (name -> function of the sample
    matrix) over `factors`, all models on one sample. The table's `member` is the model's name."""
    problem = salib_problem(factors)
    x = sample(problem, base_samples, seed)
    tables, outputs = [], {}
    for name, model in models.items():
        y = model(x)
        bad = int((~np.isfinite(y[list(columns)].to_numpy(float))).any(axis=1).sum())
        if bad:
            reasons = y["failed"].astype(str) if "failed" in y else pd.Series([], dtype=str)
            first = next((r for r in reasons if r), "no reason recorded")
            log.warning(
                "sensitivity: %s: %d of %d samples without a result; its indices are undefined (first: %s)",
                name,
                bad,
                len(x),
                first,
            )
        table = indices(problem, y, columns, confidence=confidence, resamples=resamples, seed=seed)
        tables.append(table.assign(member=name))
        outputs[name] = y
    return Study(pd.concat(tables, ignore_index=True)[list(COLUMNS)], x, outputs)


@dataclass(frozen=True)
class PbmAnnOutputs:
    """PBM-ANN as a model in SALib's shape: the final d10/d50/d90 (m), out-of-domain intervals and
    failure of one batch per row of a sample matrix whose columns are `keys` (`SPEED` or pbm keys)."""

    loop: CoupledLoop
    model_path: str
    keys: tuple[str, ...]
    member: int | None
    n_jobs: int
    rpm: float  # the speed when it is not a factor

    def cases(self, x: np.ndarray) -> list[Case]:
        cases = []
        for row in np.asarray(x, float):
            values = dict(zip(self.keys, (float(v) for v in row)))
            rpm = values.pop(SPEED, self.rpm)
            cases.append(Case(rpm, tuple(values.items()), self.member))
        return cases

    def __call__(self, x: np.ndarray) -> pd.DataFrame:
        table = outcomes_table(run_cases(self.loop, self.model_path, self.cases(x), self.n_jobs))
        return table[[*STATISTICS, "out_of_domain_intervals", "failed"]]


def sensitivity(
    loop: CoupledLoop, model_path: str | Path, settings: Sensitivity, members: bool = True
) -> tuple[pd.DataFrame, dict]:
    """Rule sensitivity: the indices table of PBM-ANN's final d10/d50/d90 (the mean and, with
    `members`, every member; `member` 'mean' or k) and the figures of merit: batches, wall time,
    samples out of the training domain or failed, per model."""
    n_members = load_surrogate(model_path).n_members if members else 0
    factors = settings.factors()
    keys = tuple(f.key for f in factors)
    speed = float(settings.impeller_rpm.low)
    models = {
        ("mean" if m is None else str(m)): PbmAnnOutputs(loop, str(model_path), keys, m, settings.n_jobs, speed)
        for m in (None, *range(n_members))
    }
    t0 = time.perf_counter()
    study = sobol_study(
        factors,
        models,
        STATISTICS,
        base_samples=settings.base_samples,
        seed=settings.seed,
        confidence=settings.confidence,
        resamples=settings.resamples,
    )
    wall = time.perf_counter() - t0
    n = len(study.samples)
    out_of_domain = {m: int((y.out_of_domain_intervals > 0).sum()) for m, y in study.outputs.items()}
    failed = {m: int((y.failed.astype(str) != "").sum()) for m, y in study.outputs.items()}
    info = {
        "factors": [f.to_dict() for f in factors],
        "base_samples": settings.base_samples,
        "samples": n,
        "batches": n * len(models),
        "wall_time_s": wall,
        "wall_time_per_batch_s": wall / (n * len(models)),
        "batches_per_minute": 60.0 * n * len(models) / wall,
        "n_jobs": settings.n_jobs,
        "out_of_domain_samples": out_of_domain,
        "failed_samples": failed,
    }
    log.info(
        "sensitivity: %(batches)d PBM-ANN batches (%(samples)d samples x (mean + %(members)d members), N = "
        "%(base_samples)d, %(k)d factors) in %(wall_time_s).1f s on %(n_jobs)d process(es): %(ms).1f ms per batch, "
        "%(batches_per_minute).0f batches per minute",
        {**info, "members": n_members, "k": len(factors), "ms": 1e3 * info["wall_time_per_batch_s"]},
    )
    if any(out_of_domain.values()):
        log.warning(
            "sensitivity: samples with the surrogate outside its training domain (extrapolated, included in the "
            "indices), of %d per model: %s",
            n,
            out_of_domain,
        )
    return study.table, info


#: colour of each index's bar
COLORS = {"ST": "#4575b4", "S1": "#fdae61"}


def plot_sensitivity(table: pd.DataFrame, path: str | Path, confidence: float) -> None:
    """The bars of `table` (`sensitivity.COLUMNS`) as a PNG at `path`."""
    plt = pyplot()

    outputs = [s for s in STATISTICS if s in set(table.output)]
    params = list(dict.fromkeys(table.parameter))
    fig, axes = plt.subplots(1, len(outputs), figsize=(4.2 * len(outputs) + 0.6, 4.6), squeeze=False, sharey=True)
    x = np.arange(len(params))
    width = 0.38
    for ax, output in zip(axes[0], outputs):
        rows = table[table.output == output]
        mean = rows[rows.member.astype(str) == "mean"].set_index("parameter").reindex(params)
        members = rows[rows.member.astype(str) != "mean"]
        for offset, index in ((-width / 2, "ST"), (width / 2, "S1")):
            ax.bar(
                x + offset,
                mean[index].to_numpy(float),
                width,
                yerr=mean[f"{index}_conf"].to_numpy(float),
                color=COLORS[index],
                capsize=3,
                label=f"{index} (mean; bars {100 * confidence:g} %)",
            )
            for k, p in enumerate(params):
                values = members.loc[members.parameter == p, index].to_numpy(float)
                ax.scatter(
                    np.full(values.size, x[k] + offset),
                    values,
                    s=12,
                    color="black",
                    zorder=5,
                    label="members" if (k == 0 and index == "ST") else None,
                )
        ax.axhline(0.0, color="0.4", lw=0.8)
        ax.set_xticks(x, [label(p) for p in params], rotation=30, ha="right", fontsize=8)
        ax.set_title(f"final {output}")
        ax.grid(alpha=0.3, axis="y")
    axes[0, 0].set_ylabel("Sobol' index (share of the variance)")
    axes[0, 0].legend(fontsize=7, loc="upper left")
    fig.suptitle("Global sensitivity of PBM-ANN's final granule size (ST total, S1 first order)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
