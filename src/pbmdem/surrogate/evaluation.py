"""Grouped cross-validation of the surrogate families against the baselines (:func:`cross_validate_models`:
the same folds for all models, whole DEM runs held out, the MLP's own search nested inside every
training set), its interval coverage and calibration, and the choice of the family per target.
"""

from __future__ import annotations

import logging
import time
import warnings

import numpy as np
import pandas as pd
from sklearn.base import clone
from sklearn.metrics import mean_absolute_error, r2_score

from .baselines import HGBBaseline, PhysicalScaling
from .calibration import calibration_scale, coverage, cross_fitted_coverage, run_calibration_scale
from .ensemble import grouped_splits
from .features import PAIR_ID_COLUMNS, TARGET_COLUMN, TARGET_NAME, TARGET_NOISE_VAR, TrainingData
from .velocity import TAIL_SPEEDS, bin_counts, empirical_fractions, tail_error, total_variation

log = logging.getLogger(__name__)

METRIC_COLUMNS = [
    "target",
    "model",
    "fold",
    "test_point_ids",
    "n_train_runs",
    "n_test",
    "r2_log10",
    "mae_log10",
    "noise_floor_r2_log10",
    "tv_distance",
    "coverage_90",
    "coverage_90_calibrated",
    "uncertainty_scale",
]


def noise_floor_r2(y, noise_var) -> float:
    """R2 that replicate noise alone allows: ``1 - mean(noise_var) / var(y)``.

    ``y``: the observed targets (log10 of the replicate means); ``noise_var``: the variance of each
    y from the spread between replicates, ``(SE / (c ln 10))^2`` by the delta method. A model that
    predicts every row's replicate-free value exactly has an expected residual sum of squares of
    ``sum(noise_var)``, so its expected R2 (population variance of y, as in ``r2_score``) is this
    value. Rows with unknown noise (NaN, e.g. one replicate) are left out; NaN if none is left
    or ``y`` has no spread.
    """
    y, noise_var = np.asarray(y, float), np.asarray(noise_var, float)
    ok = np.isfinite(y) & np.isfinite(noise_var)
    if ok.sum() < 2:
        return float("nan")
    var = float(np.var(y[ok]))
    if not var > 0:
        return float("nan")
    return float(1.0 - np.mean(noise_var[ok]) / var)


def _metrics(y: np.ndarray, p: np.ndarray) -> tuple[float, float]:
    r2 = float(r2_score(y, p)) if len(y) >= 2 and np.var(y) > 0 else float("nan")
    return r2, float(mean_absolute_error(y, p))


def _row(target, model, fold, ids, n_train, n_test, r2, mae, floor=np.nan, tv=np.nan, cov=(np.nan,) * 3) -> dict:
    """One row of the metrics (:data:`METRIC_COLUMNS`); ``cov``: coverage, calibrated coverage, scale."""
    return dict(zip(METRIC_COLUMNS, (target, model, fold, ids, n_train, n_test, r2, mae, floor, tv, *cov)))


def default_baselines(random_state: int | None = 0, speed_law: str = "lognormal") -> dict:
    """HGB (seeded with ``random_state``) and physical-scaling (impact-speed law ``speed_law``) baselines."""
    return {"hgb": HGBBaseline(random_state=random_state), "physical": PhysicalScaling(speed_law=speed_law)}


def _fit(model, data: TrainingData, rows: np.ndarray):
    """Clone of ``model`` fitted on ``rows`` of ``data`` (with velocity targets if it learns them)."""
    kwargs = {"velocity": data.velocity[rows]} if hasattr(model, "predict_velocity") else {}
    if hasattr(model, "speed_tail_from") and data.velocity_counts is not None:  # the pooled tail's bins
        kwargs["velocity_counts"] = data.velocity_counts[rows]
    return clone(model).fit(data.X.iloc[rows], data.y[rows], groups=data.groups[rows], **kwargs)


def _uncertain(model) -> bool:
    """True for the surrogate families (they predict with an uncertainty and the impact speeds)."""
    return hasattr(model, "predict_velocity") and hasattr(type(model), "n_members")


def _check_speed_laws(models: dict, speed_law: str) -> None:
    """ValueError unless every model that learns an impact-speed law learns the training data's."""
    laws = {name: model.speed_law for name, model in models.items() if hasattr(model, "speed_law")}
    wrong = {name: law for name, law in laws.items() if law != speed_law}
    if wrong:
        raise ValueError(
            f"models {wrong} learn another impact-speed law than the training data's {speed_law!r} "
            "(training_data(..., speed_law=...))"
        )


def _prediction_frame(table: pd.DataFrame, models: dict, families: list) -> pd.DataFrame:
    """The pairs' ids and DEM targets with empty columns for the fold and every model's held-out
    prediction (and the families' standard deviations)."""
    keep = [c for c in (*PAIR_ID_COLUMNS, TARGET_COLUMN, TARGET_NAME, TARGET_NOISE_VAR) if c in table]
    empty = {**{f"{name}_log10": np.nan for name in models}, **{f"{name}_std_log10": np.nan for name in families}}
    return table[keep].assign(fold=-1, **empty)


def _velocity_columns(pred: pd.DataFrame, data: TrainingData, models: dict):
    """The impact-velocity distribution of every row with bins: its DEM log-normal fit into ``pred``
    with empty columns for the models that learn it. Returns ``(vmask, vel_models, obs_frac_full)``:
    the rows with bins, those models (none without such rows) and the DEM bin fractions of every
    row (NaN where it has none; None without such rows)."""
    vmask = np.isfinite(data.velocity).all(axis=1)
    if not vmask.any():
        return vmask, [], None
    vel_models = [m for m, model in models.items() if hasattr(model, "predict_velocity")]
    obs_frac = empirical_fractions(bin_counts(data.table.loc[vmask]))
    pred["velocity_mu_log10"] = np.where(vmask, data.velocity[:, 0], np.nan)
    pred["velocity_sigma"] = np.where(vmask, data.velocity[:, 1], np.nan)
    for col in (
        f"{name}_velocity_{c}" for name in vel_models for c in ("mu_log10", "sigma", "tv", "tail", "mu_std_log10")
    ):
        pred[col] = np.nan
    obs_frac_full = np.full((len(data.table), obs_frac.shape[1]), np.nan)
    obs_frac_full[vmask] = obs_frac
    return vmask, vel_models, obs_frac_full


def cross_validate_models(data: TrainingData, models: dict, cv: str = "group_kfold", n_splits: int = 5):
    """Evaluate every model on the same grouped outer folds (whole DEM runs held out).

    ``models``: name -> unfitted estimator, the surrogate families (``CollisionSurrogate``s) and the
    baselines; ``data`` from :func:`~pbmdem.surrogate.features.training_data`; ``cv`` and ``n_splits``
    choose the outer folds (the MLP's own grouped search runs inside every training set: nested).
    Returns ``(metrics, predictions)``: one metrics row per (target, model, fold) plus the
    :func:`_summary_rows`; ``predictions`` every held-out row with the DEM value, each model's
    prediction (log10), the families' predictive standard deviations and the fold number.
    """
    groups = data.groups
    _check_speed_laws(models, data.speed_law)
    splits = grouped_splits(groups, cv, n_splits)
    families = [name for name, model in models.items() if _uncertain(model)]
    pred = _prediction_frame(data.table, models, families)
    vmask, vel_models, obs_frac_full = _velocity_columns(pred, data, models)

    rows = []
    t_start = time.perf_counter()
    for k, (train, test) in enumerate(splits):
        t_fold = time.perf_counter()
        y = data.y[test]
        ids = ";".join(sorted(set(groups[test])))
        n_train = len(set(groups[train]))
        floor = noise_floor_r2(y, data.noise_var[test])
        pred.loc[pred.index[test], "fold"] = k
        X_test = data.X.iloc[test]
        for name, model in models.items():
            fitted = _fit(model, data, train)
            with warnings.catch_warnings():
                # held-out runs may lie at the edges of the training ranges: expected here
                warnings.simplefilter("ignore", UserWarning)
                p, s = fitted.predict(X_test, return_std=True) if name in families else (fitted.predict(X_test), None)
            if s is not None:
                pred.loc[pred.index[test], f"{name}_std_log10"] = s
            pred.loc[pred.index[test], f"{name}_log10"] = p
            r2, mae = _metrics(y, p)
            rows.append(_row("encounter_frequency", name, str(k), ids, n_train, len(test), r2, mae, floor))
            vt = test[vmask[test]]
            if name in vel_models and len(vt):
                r2v, maev, tv = _velocity_fold(
                    name, fitted, data.X.iloc[vt], name in families, obs_frac_full[vt], pred, vt
                )
                rows.append(_row("impact_velocity", name, str(k), ids, n_train, len(vt), r2v, maev, tv=tv))
        done = [r for r in rows if r["fold"] == str(k) and r["target"] == "encounter_frequency"]
        scores = ", ".join(f"{r['model']} R2 {r['r2_log10']:.3f}" for r in done)
        elapsed, n = time.perf_counter() - t_start, len(splits)
        log.info("CV fold %d of %d done (held out %s) in %.1f s: %s; elapsed %.0f s, remaining ~%.0f s", k + 1, n, ids,
                 time.perf_counter() - t_fold, scores, elapsed, elapsed / (k + 1) * (n - k - 1))  # fmt: skip

    metrics = pd.DataFrame(rows, columns=METRIC_COLUMNS)
    summary = _summary_rows(metrics, pred, list(models), families, vel_models, vmask)
    metrics = pd.concat([metrics, pd.DataFrame(summary, columns=METRIC_COLUMNS)], ignore_index=True)
    return metrics, pred


def _summary_rows(metrics: pd.DataFrame, pred: pd.DataFrame, models: list, families: list, vel_models: list, vmask):
    """Per target and model a `pooled` row (all held-out rows together, with the families'
    interval coverage and calibration) and a `mean` row (the average over the folds)."""
    summary = []
    floor = noise_floor_r2(pred[TARGET_NAME].to_numpy(float), pred[TARGET_NOISE_VAR].to_numpy(float))
    folds = pred["fold"].to_numpy()
    for target, names in (("encounter_frequency", models), ("impact_velocity", vel_models)):
        for name in names:
            per = metrics[(metrics["model"] == name) & (metrics["target"] == target)]
            if target == "encounter_frequency":
                obs, p = pred[TARGET_NAME].to_numpy(float), pred[f"{name}_log10"].to_numpy(float)
                std = pred[f"{name}_std_log10"].to_numpy(float) if name in families else None
                sel, n_test, tv, fl = slice(None), len(pred), np.nan, floor
            else:
                sel = vmask
                obs = pred.loc[sel, "velocity_mu_log10"].to_numpy(float)
                p = pred.loc[sel, f"{name}_velocity_mu_log10"].to_numpy(float)
                std = pred.loc[sel, f"{name}_velocity_mu_std_log10"].to_numpy(float) if name in families else None
                n_test, tv, fl = int(sel.sum()), float(pred.loc[sel, f"{name}_velocity_tv"].mean()), np.nan
            r2, mae = _metrics(obs, p)
            cov = (np.nan,) * 3
            if std is not None:  # the families': raw and cross-fitted calibrated coverage, calibration factor
                held = (obs, p, std)
                cov = (coverage(*held), cross_fitted_coverage(*held, folds[sel]), calibration_scale(*held))
            summary.append(_row(target, name, "pooled", "all", np.nan, n_test, r2, mae, fl, tv, cov))
            means = ("n_train_runs", "n_test", "r2_log10", "mae_log10", "noise_floor_r2_log10", "tv_distance")
            summary.append(_row(target, name, "mean", "all", *(float(per[c].mean()) for c in means)))
    return summary


def _velocity_fold(name: str, fitted, X, uncertain: bool, observed, pred: pd.DataFrame, rows) -> tuple:
    """A fitted model's impact-speed law on held-out `rows` (features `X`, `observed` bin fractions)
    into `pred`; returns (R2, MAE of log10 median speed, mean total-variation distance)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # held-out runs at the edges of the ranges: expected
        if uncertain:
            mu, sigma, mu_std, _ = fitted.predict_velocity(X, return_std=True)
        else:
            (mu, sigma), mu_std = fitted.predict_velocity(X), np.full(len(rows), np.nan)
        frac = fitted.velocity_fractions(X)
    tv = total_variation(frac, observed)
    idx = pred.index[rows]
    pred.loc[idx, f"{name}_velocity_tail"] = tail_error(frac, observed)
    pred.loc[idx, f"{name}_velocity_mu_log10"] = mu
    pred.loc[idx, f"{name}_velocity_sigma"] = sigma
    pred.loc[idx, f"{name}_velocity_tv"] = tv
    pred.loc[idx, f"{name}_velocity_mu_std_log10"] = mu_std
    r2, mae = _metrics(pred.loc[idx, "velocity_mu_log10"].to_numpy(float), mu)
    return r2, mae, float(tv.mean())


def select_family(metrics: pd.DataFrame, families) -> str:
    """The family with the highest pooled held-out R2 of log10 c (the smallest squared error on
    the same rows); ties (within 1e-9) go to the earlier family in ``families``."""
    pooled = metrics[(metrics["target"] == "encounter_frequency") & (metrics["fold"] == "pooled")]
    scores = {name: {"r2_log10": float(pooled.loc[pooled["model"] == name, "r2_log10"].iloc[0])} for name in families}
    return _best(scores, families, "r2_log10", sign=-1.0)


def sample_scores(pred: pd.DataFrame, models, point_ids=None) -> dict:
    """Held-out errors of every model in ``models`` on the rows of the runs ``point_ids`` (all rows
    when None) of the held-out predictions ``pred`` (:func:`cross_validate_models`), per model:
    the frequency's MAE and mean error (prediction - DEM, decades) and calibration factor (families;
    else NaN), and where the rows have bins the impact-speed law's (``velocity_*``: log10 median
    speed, bin fractions, median :func:`tail_error` of the fast tail); {} when no row is of
    ``point_ids``. The active-learning runs (``grid.extra_points``) are samples of the PBM's own
    states, which the pooled score of every run does not weigh as the PBM does (docs/surrogate.md)."""
    rows = pred if point_ids is None else pred[pred["point_id"].astype(str).isin({str(p) for p in point_ids})]
    if rows.empty:
        return {}
    obs = rows[TARGET_NAME].to_numpy(float)
    vrows = rows[np.isfinite(rows["velocity_mu_log10"].to_numpy(float))] if "velocity_mu_log10" in rows else rows[:0]
    out = {}
    for name in models:
        p = rows[f"{name}_log10"].to_numpy(float)
        std = f"{name}_std_log10"
        s = {
            "n_runs": int(rows["point_id"].nunique()),
            "n_rows": int(len(rows)),
            "mae_log10": float(np.mean(np.abs(p - obs))),
            "mean_error_log10": float(np.mean(p - obs)),
            "uncertainty_scale": calibration_scale(obs, p, rows[std]) if std in rows else float("nan"),
            "run_uncertainty_scale": run_calibration_scale(rows["point_id"], obs, p, rows[std])
            if std in rows
            else np.nan,
        }
        mu = f"{name}_velocity_mu_log10"
        if mu in vrows and len(vrows):
            vobs, vp = vrows["velocity_mu_log10"].to_numpy(float), vrows[mu].to_numpy(float)
            vstd = f"{name}_velocity_mu_std_log10"
            s["velocity_mae_log10"] = float(np.mean(np.abs(vp - vobs)))
            s["velocity_tv_distance"] = float(vrows[f"{name}_velocity_tv"].mean())
            tail = vrows[f"{name}_velocity_tail"].to_numpy(float)
            s["velocity_tail_log10"] = float(np.nanmedian(tail)) if np.isfinite(tail).any() else float("nan")
            s["velocity_uncertainty_scale"] = (
                calibration_scale(vobs, vp, vrows[vstd]) if vrows[vstd].notna().any() else float("nan")
            )
        out[name] = s
    return out


def _best(scores: dict, families, key: str, sign: float = 1.0) -> str:
    """The family with the smallest ``sign * scores[family][key]`` (ties within 1e-9 to the earlier)."""
    values = {name: sign * float(scores[name][key]) for name in families}
    best = min(values.values())
    return next(name for name in families if values[name] <= best + 1e-9)


def select_per_target(
    metrics: pd.DataFrame, families, pbm_scores: dict | None = None, pooled: dict | None = None
) -> dict:
    """The family of each target of the PBM, chosen separately by held-out evidence, and why.

    * ``frequency``: with held-out rows of PBM samples (``pbm_scores``, :func:`sample_scores` on
      the active-learning runs) the smallest MAE of log10 c on them; else the highest pooled
      held-out R2 of log10 c (:func:`select_family`).
    * ``speed_law``: the smallest held-out error of the fast tail over every run (``pooled``,
      :func:`sample_scores` of all rows: ``velocity_tail_log10``, the median over rows of
      :func:`tail_error`, the fractions of impacts faster than :data:`TAIL_SPEEDS` that breakage
      reads); without it the frequency's family.

    Returns {"frequency": name, "frequency_reason": str, "speed_law": name, "speed_law_reason": str}.
    """
    families = list(families)
    pbm_scores = pbm_scores or {}
    if all(name in pbm_scores for name in families):
        frequency = _best(pbm_scores, families, "mae_log10")
        runs = next(iter(pbm_scores.values()))["n_runs"]
        reason = (
            f"the smallest held-out MAE of log10 c on the {runs} active-learning runs (samples of the PBM's "
            "own states), of " + ", ".join(f"{n} {pbm_scores[n]['mae_log10']:.3f}" for n in families)
        )
    else:
        frequency = select_family(metrics, families)
        reason = "the best pooled held-out R2 of log10 c of " + ", ".join(families) + " (no active-learning runs)"
    pooled = pooled or {}
    if all(np.isfinite(pooled.get(name, {}).get("velocity_tail_log10", np.nan)) for name in families):
        speed = _best(pooled, families, "velocity_tail_log10")
        speed_reason = (
            f"the smallest held-out error of the fractions of impacts faster than {TAIL_SPEEDS[0]:g}-"
            f"{TAIL_SPEEDS[-1]:.3g} m/s (median |log10 predicted / DEM| over every run's pairs), of "
            + ", ".join(f"{n} {pooled[n]['velocity_tail_log10']:.3f}" for n in families)
        )
    else:
        speed, speed_reason = frequency, "no held-out impact speeds: the frequency's family"
    return {"frequency": frequency, "frequency_reason": reason, "speed_law": speed, "speed_law_reason": speed_reason}


def summarise(metrics: pd.DataFrame, target: str = "encounter_frequency") -> dict:
    """{model: {pooled_r2_log10, pooled_mae_log10, mean_fold_r2_log10, mean_fold_mae_log10, n_folds,
    noise_floor_r2_log10, pooled_tv_distance}} of one target (``encounter_frequency`` or
    ``impact_velocity``, where R2/MAE refer to log10 of the median impact speed)."""
    out = {}
    if "target" in metrics:
        metrics = metrics[metrics["target"] == target]
    for name, g in metrics.groupby("model", sort=False):
        pooled = g[g["fold"] == "pooled"].iloc[0]
        mean = g[g["fold"] == "mean"].iloc[0]
        out[name] = {
            "pooled_r2_log10": float(pooled["r2_log10"]),
            "pooled_mae_log10": float(pooled["mae_log10"]),
            "mean_fold_r2_log10": float(mean["r2_log10"]),
            "mean_fold_mae_log10": float(mean["mae_log10"]),
            "n_folds": int((~g["fold"].isin(["pooled", "mean"])).sum()),
            "noise_floor_r2_log10": float(pooled["noise_floor_r2_log10"]),
            "pooled_tv_distance": float(pooled["tv_distance"]),
            "coverage_90": float(pooled["coverage_90"]),
            "coverage_90_calibrated": float(pooled["coverage_90_calibrated"]),
            "uncertainty_scale": float(pooled["uncertainty_scale"]),
        }
    return out
