"""Parameter estimation: the pbm settings of `calibration.parameters` that make PBM-ANN reproduce
measured d10/d50/d90, by least squares in ln theta, with profile-likelihood and surrogate parts of
each interval and the parameters' correlation (the method and why: docs/calibration.md, "The fit"
and "Intervals, correlation and identifiability"); the measured table it fits (`read_measured`,
docs/calibration.md "The measured table").
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import least_squares
from scipy.stats import norm, qmc

from pbmdem.config import Calibration, CoupledLoop
from pbmdem.config.design import pbm_value
from pbmdem.readers import InputFileError, first_index
from pbmdem.surrogate import load_surrogate
from pbmdem.tables import MEASURED, STATISTICS

from .batches import Case, run_cases
from .profile import forward_jacobian, profile_widths

log = logging.getLogger(__name__)


def check_measured(frame: pd.DataFrame, source, end_time: float) -> pd.DataFrame:
    """`frame` (read against `MEASURED`) if its rows make one time series per speed within the batch
    with d10 <= d50 <= d90; InputFileError naming `source`, row and column otherwise."""
    if frame.empty:
        raise InputFileError(f"measured size table {source}: no data rows; at least one (rpm, time) is required")
    times = frame.time.to_numpy(float)
    if (row := first_index(times > end_time * (1 + 1e-12))) is not None:
        raise InputFileError(
            f"measured size table {source}: row {row + 1}, column 'time' = {times[row]:g}: allowed 0 .. "
            f"{end_time:g} s (the batch of pbm.process)"
        )
    last: dict[float, float] = {}
    for row, (rpm, t) in enumerate(zip(frame.rpm.to_numpy(float), times, strict=True)):
        if rpm in last and not t > last[rpm]:
            raise InputFileError(
                f"measured size table {source}: row {row + 1}, column 'time' = {t:g}: the times of rpm {rpm:g} "
                f"must be strictly ascending (previous: {last[rpm]:g})"
            )
        last[rpm] = t
    for small, large in (("d10", "d50"), ("d50", "d90")):
        if (row := first_index(frame[small].to_numpy(float) > frame[large].to_numpy(float))) is not None:
            raise InputFileError(
                f"measured size table {source}: row {row + 1}, column {large!r} = {frame[large].iloc[row]:g}: "
                f"must be at least {small} = {frame[small].iloc[row]:g} (sizes of a cumulative distribution)"
            )
    return frame


def read_measured(path: str | Path, end_time: float) -> pd.DataFrame:
    """The measured size table at `path`, checked (`check_measured`)."""
    return check_measured(MEASURED.read(path), path, end_time)


#: residual of a measured point whose batch failed (the search is pushed back from there)
FAILED_RESIDUAL = 1e3


@dataclass
class Model:
    """PBM-ANN (kernel "ann": the surrogate's mean, or `member`) or PBM-constant (kernel "constant")
    at the measured speeds; `fixed`: pbm settings held per speed (e.g. PBM-constant's frequency)."""

    loop: CoupledLoop
    model_path: object
    keys: tuple[str, ...]
    kernel: str = "ann"
    member: int | None = None
    fixed: dict | None = None
    n_jobs: int = 1

    def cases(self, x: np.ndarray, rpms) -> list[Case]:
        values = tuple(zip(self.keys, (float(v) for v in np.exp(x)), strict=True))
        fixed = self.fixed or {}
        return [Case(float(r), values + tuple(fixed.get(float(r), ())), self.member, self.kernel) for r in rpms]


class Residuals:
    """The normalised residuals of `model` against `data` as a function of ln theta, and their
    forward-difference Jacobian (the batches of all columns in one parallel call)."""

    def __init__(self, model: Model, data: pd.DataFrame, statistics, floor: float):
        self.model = model
        self.data = data
        self.statistics = list(statistics)
        self.rpms = sorted(data.rpm.unique())
        measured = data[self.statistics].to_numpy(float)
        sd = data[[f"{s}_sd" for s in self.statistics]].to_numpy(float)
        self.measured = measured
        self.sd = np.maximum(sd, floor * measured)
        self._cache: dict[bytes, np.ndarray] = {}
        self.out_of_domain: dict[bytes, int] = {}  # coupling intervals outside the training domain
        self.evaluations = 0

    def predicted(self, outcomes) -> np.ndarray:
        columns = [STATISTICS.index(s) for s in self.statistics]
        out = np.empty_like(self.measured)
        for rpm, outcome in zip(self.rpms, outcomes, strict=True):
            rows = (self.data.rpm == rpm).to_numpy()
            out[rows] = outcome.at(self.data.time[rows].to_numpy(float))[:, columns]
        return out

    def _normalised(self, predicted: np.ndarray) -> np.ndarray:
        r = (predicted - self.measured) / self.sd
        return np.where(np.isfinite(r), r, FAILED_RESIDUAL).ravel()

    def _evaluate(self, points: list[np.ndarray]) -> list[np.ndarray]:
        todo = [x for x in points if x.tobytes() not in self._cache]
        cases = [c for x in todo for c in self.model.cases(x, self.rpms)]
        outcomes = run_cases(self.model.loop, self.model.model_path, cases, self.model.n_jobs)
        self.evaluations += len(todo)
        n = len(self.rpms)
        for k, x in enumerate(todo):
            mine = outcomes[k * n : (k + 1) * n]
            self._cache[x.tobytes()] = self._normalised(self.predicted(mine))
            self.out_of_domain[x.tobytes()] = sum(o.out_of_domain_intervals for o in mine)
        return [self._cache[x.tobytes()] for x in points]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self._evaluate([np.asarray(x, float)])[0]

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return forward_jacobian(self._evaluate, x)


def screen(residuals: Residuals, x0: np.ndarray, lower: np.ndarray, upper: np.ndarray, keep: int) -> list[np.ndarray]:
    """The `keep` best of `x0` and a seeded scrambled Sobol sample of the search box (8 points per
    parameter, at least 16) by their sum of squares: the starts of the local fits."""
    n = 2 ** max(4, math.ceil(math.log2(8 * x0.size)))
    sample = qmc.scale(qmc.Sobol(x0.size, scramble=True, seed=0).random(n), lower, upper)
    points = [x0, *sample]
    costs = [float(np.sum(r**2)) for r in residuals._evaluate(points)]
    return [points[k] for k in np.argsort(costs, kind="stable")[:keep]]


def fit(residuals: Residuals, x0: np.ndarray, max_factor: float, starts: int = 3):
    """(ln theta estimate, Jacobian there, optimiser figures) of the least-squares fit: local fits
    from the `starts` best points of `screen` (from `x0` alone if `starts` is 1), the lowest kept."""
    span = math.log(max_factor)
    lower, upper = x0 - span, x0 + span
    candidates = [x0] if starts <= 1 else screen(residuals, x0, lower, upper, starts)
    results = [
        least_squares(
            residuals, c, jac=residuals.jacobian, bounds=(lower, upper), method="trf", xtol=1e-4, ftol=1e-6, max_nfev=60
        )
        for c in candidates
    ]
    result = min(results, key=lambda r: r.cost)
    jac = residuals.jacobian(result.x)
    at_bound = (np.isclose(result.x, lower, atol=1e-3) | np.isclose(result.x, upper, atol=1e-3)).tolist()
    info = {
        "cost": float(2 * result.cost),
        "nfev": int(sum(r.nfev for r in results)),
        "status": int(result.status),
        "message": str(result.message),
        "at_bound": at_bound,
        "starts": len(candidates),
        "local_minima_costs": sorted(round(float(2 * r.cost), 3) for r in results),
    }
    return result.x, jac, info


def measurement_covariance(jac: np.ndarray) -> tuple[np.ndarray, bool]:
    """(J^T J)^-1 and whether J has full rank (else a ridge-regularised inverse: the correlation of
    the parameters it cannot separate comes out near +-1)."""
    jtj = jac.T @ jac
    s = np.linalg.svd(jac, compute_uv=False)
    full_rank = bool(s.size and s.min() > 1e-8 * s.max())
    if full_rank:
        return np.linalg.inv(jtj), True
    ridge = 1e-10 * max(float(np.trace(jtj)), 1e-300)
    return np.linalg.inv(jtj + ridge * np.eye(jtj.shape[0])), False


def correlation(cov: np.ndarray) -> np.ndarray:
    sd = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    return np.clip(cov / np.outer(sd, sd), -1.0, 1.0)


def unidentifiable_pairs(keys, corr: np.ndarray, limit: float, full_rank: bool = True) -> list[tuple[str, str, float]]:
    """The pairs of parameters whose estimates the data cannot separate: |correlation| > `limit`."""
    pairs = []
    for i in range(len(keys)):
        for j in range(i + 1, len(keys)):
            if abs(corr[i, j]) > limit or not full_rank and abs(corr[i, j]) > 0.5:
                pairs.append((keys[i], keys[j], float(corr[i, j])))
    return pairs


def start_values(loop: CoupledLoop, keys, start: dict | None = None) -> np.ndarray:
    """ln of the start values: `start` where given, else the loop's own settings."""
    start = start or {}
    return np.log([float(start[k]) if k in start else pbm_value(loop.batch.pbm, k) for k in keys])


@dataclass
class Estimate:
    """A finished calibration (its files: docs/calibration.md)."""

    keys: tuple[str, ...]
    table: pd.DataFrame  # one row per parameter
    correlation: pd.DataFrame
    unidentifiable: list
    residuals: pd.DataFrame  # one row per measured (rpm, time, statistic)
    info: dict


def _member_estimates(model: Model, data, settings: Calibration, x: np.ndarray, n_members: int) -> np.ndarray:
    """ln theta fitted with each ensemble member in place of the mean, started from `x`."""
    estimates = []
    for k in range(n_members):
        member = Model(model.loop, model.model_path, model.keys, model.kernel, k, model.fixed, model.n_jobs)
        res = Residuals(member, data, settings.statistics, settings.relative_error_floor)
        xk, _, info = fit(res, x, settings.max_factor, starts=1)
        log.info("calibration with ensemble member %d: %s (%d evaluations)", k, np.exp(xk), info["nfev"])
        estimates.append(xk)
    return np.array(estimates)


def calibrate(model: Model, data: pd.DataFrame, settings: Calibration, start: dict | None = None) -> Estimate:
    """Estimate `model.keys` from the measured table `data` (see the module's description)."""
    keys = tuple(model.keys)
    x0 = start_values(model.loop, keys, start)
    residuals = Residuals(model, data, settings.statistics, settings.relative_error_floor)
    x, jac, info = fit(residuals, x0, settings.max_factor)
    log.info(
        "calibration (%s, %s): %s from %d start(s), sum of squares %.4g (local minima %s)",
        model.kernel,
        "ensemble mean" if model.member is None else f"member {model.member}",
        dict(zip(keys, (f"{v:.4g}" for v in np.exp(x)), strict=True)),
        info["starts"],
        info["cost"],
        info["local_minima_costs"],
    )
    cov_meas, full_rank = measurement_covariance(jac)
    cov_surr = np.zeros_like(cov_meas)
    members = np.empty((0, len(keys)))
    if model.kernel == "ann" and model.member is None:
        members = _member_estimates(model, data, settings, x, load_surrogate(model.model_path).n_members)
        if len(members) > 1:
            cov_surr = np.atleast_2d(np.cov(members, rowvar=False, ddof=1))
    corr = correlation(cov_meas + cov_surr)
    z = _z(settings.confidence)
    span = math.log(settings.max_factor)
    sd_curvature = np.sqrt(np.clip(np.diag(cov_meas), 0.0, None))
    widths = profile_widths(residuals, x, x0 - span, x0 + span, z, n_jobs=model.n_jobs)
    sd_surrogate = np.sqrt(np.diag(cov_surr))
    below, above = (np.hypot(widths[:, k], z * sd_surrogate) for k in (0, 1))
    sd_measurement = widths.mean(axis=1) / z  # the profile interval's half-width as an sd
    log.info(
        "calibration: profile-likelihood widths (ln, below/above) %s; curvature sd (ln) %s",
        np.round(widths, 4).tolist(),
        np.round(sd_curvature, 4).tolist(),
    )
    table = pd.DataFrame(
        {
            "parameter": keys,
            "start": np.exp(x0),
            "estimate": np.exp(x),
            # a side the data do not bound runs to 0 or infinity (exp of +-700 is the float range)
            "ci_low": np.exp(np.clip(x - below, -700.0, 700.0)),
            "ci_high": np.exp(np.clip(x + above, -700.0, 700.0)),
            "sd_ln_total": np.hypot(sd_measurement, sd_surrogate),
            "sd_ln_measurement": sd_measurement,
            "sd_ln_surrogate": sd_surrogate,
            "sd_ln_curvature": sd_curvature,
            "member_estimates": [" ".join(f"{v:.4g}" for v in np.exp(members[:, i])) for i in range(len(keys))],
            "at_bound": info["at_bound"],
        }
    )
    pairs = unidentifiable_pairs(keys, corr, settings.identifiability_correlation, full_rank)
    chi2 = float(np.sum(residuals(x) ** 2))
    ood = residuals.out_of_domain.get(np.asarray(x, float).tobytes(), 0)
    if ood:
        log.warning(
            "calibration: at the estimate PBM-ANN left the surrogate's training domain in %d coupling interval(s) "
            "over the measured speeds: the fit extrapolates the surrogate",
            ood,
        )
    dof = max(residuals.measured.size - len(keys), 1)
    info.update(
        out_of_domain_intervals=int(ood),
        chi2=chi2,
        dof=dof,
        chi2_reduced=chi2 / dof,
        full_rank=full_rank,
        confidence=settings.confidence,
        interval="profile likelihood",
        evaluations=residuals.evaluations,
        members=len(members),
    )
    return Estimate(
        keys, table, pd.DataFrame(corr, index=keys, columns=keys), pairs, _residual_table(residuals, x), info
    )


def _z(confidence: float) -> float:
    return float(norm.ppf(0.5 + confidence / 2))


def _residual_table(residuals: Residuals, x: np.ndarray) -> pd.DataFrame:
    r = residuals(x).reshape(residuals.measured.shape)
    rows = []
    for j, (rpm, t) in enumerate(zip(residuals.data.rpm, residuals.data.time, strict=True)):
        for i, s in enumerate(residuals.statistics):
            measured, sd = residuals.measured[j, i], residuals.sd[j, i]
            rows.append(
                {
                    "rpm": rpm,
                    "time": t,
                    "statistic": s,
                    "measured": measured,
                    "sd": sd,
                    "model": measured + r[j, i] * sd,
                    "residual": r[j, i],
                }
            )
    return pd.DataFrame(rows)
