"""Grouped cross-validation of the surrogate against its baselines (same folds for all models).

The outer folds hold out whole DEM runs. For the MLP the hyperparameter search runs *inside*
each outer training set (nested, again grouped), so the held-out runs never influence the model
that predicts them.
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
from .features import TARGET_NAME, prepare_training_table
from .model import CollisionSurrogate, grouped_splits

log = logging.getLogger(__name__)

MODEL_NAMES = ("mlp", "hgb", "physical")
METRIC_COLUMNS = ["model", "fold", "test_point_ids", "n_train_runs", "n_test", "r2_log10", "mae_log10"]


def _metrics(y: np.ndarray, p: np.ndarray) -> tuple[float, float]:
    r2 = float(r2_score(y, p)) if len(y) >= 2 and np.var(y) > 0 else float("nan")
    return r2, float(mean_absolute_error(y, p))


def default_baselines(surrogate: CollisionSurrogate) -> dict:
    """HGB and physical-scaling baselines sharing the surrogate's radius and zero policy."""
    return {
        "hgb": HGBBaseline(impeller_radius=surrogate.impeller_radius, zero_policy=surrogate.zero_policy,
                           random_state=surrogate.random_state),
        "physical": PhysicalScaling(impeller_radius=surrogate.impeller_radius, zero_policy=surrogate.zero_policy),
    }


def cross_validate_models(table: pd.DataFrame, surrogate: CollisionSurrogate, baselines: dict | None = None,
                          cv: str | None = None, n_splits: int | None = None):
    """Evaluate the surrogate (``mlp``) and the baselines on the same grouped outer folds.

    Returns ``(metrics, predictions)``: ``metrics`` has one row per (model, fold) plus, per model,
    a ``pooled`` row (all held-out predictions together) and a ``mean`` row (average over folds;
    ``r2_log10`` of the mean row averages the per-fold R2). ``predictions`` holds every held-out
    row with the DEM value and each model's prediction (log10), the MLP's ensemble spread and the
    fold number.
    """
    baselines = default_baselines(surrogate) if baselines is None else baselines
    models = {"mlp": surrogate, **baselines}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # reported once by the final fit
        data = prepare_training_table(table, surrogate.zero_policy).reset_index(drop=True)
    groups = data["point_id"].astype(str).to_numpy()
    splits = grouped_splits(groups, cv or surrogate.cv, n_splits or surrogate.n_splits)

    rows = []
    pred = data[["point_id", "rpm", "distribution", "class_i", "class_j", "d_i", "d_j",
                 "frequency_per_pair", TARGET_NAME]].copy() if "distribution" in data else \
        data[["point_id", "rpm", "class_i", "class_j", "d_i", "d_j", "frequency_per_pair", TARGET_NAME]].copy()
    pred["fold"] = -1
    for name in models:
        pred[f"{name}_log10"] = np.nan
    pred["mlp_std_log10"] = np.nan

    t_start = time.perf_counter()
    for k, (train, test) in enumerate(splits):
        tr, te = data.iloc[train], data.iloc[test]
        t_fold = time.perf_counter()
        y = te[TARGET_NAME].to_numpy(float)
        pred.loc[pred.index[test], "fold"] = k
        for name, model in models.items():
            fitted = clone(model).fit(tr)
            if name == "mlp":
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)  # held-out runs may lie at the edges
                    p, s = fitted.predict_log10(te, return_std=True)
                pred.loc[pred.index[test], "mlp_std_log10"] = s
            else:
                p = fitted.predict_log10(te)
            pred.loc[pred.index[test], f"{name}_log10"] = p
            r2, mae = _metrics(y, p)
            rows.append({"model": name, "fold": str(k), "test_point_ids": ";".join(sorted(set(groups[test]))),
                         "n_train_runs": len(set(groups[train])), "n_test": len(test),
                         "r2_log10": r2, "mae_log10": mae})
        elapsed = time.perf_counter() - t_start
        log.info("CV fold %d of %d done (held out %s) in %.1f s: %s; elapsed %.0f s, remaining ~%.0f s",
                 k + 1, len(splits), ";".join(sorted(set(groups[test]))), time.perf_counter() - t_fold,
                 ", ".join(f"{r['model']} R2 {r['r2_log10']:.3f} MAE {r['mae_log10']:.3f}" for r in rows[-len(models):]),
                 elapsed, elapsed / (k + 1) * (len(splits) - k - 1))

    metrics = pd.DataFrame(rows, columns=METRIC_COLUMNS)
    summary = []
    for name in models:
        r2, mae = _metrics(pred[TARGET_NAME].to_numpy(float), pred[f"{name}_log10"].to_numpy(float))
        per = metrics[metrics["model"] == name]
        summary.append({"model": name, "fold": "pooled", "test_point_ids": "all", "n_train_runs": np.nan,
                        "n_test": len(pred), "r2_log10": r2, "mae_log10": mae})
        summary.append({"model": name, "fold": "mean", "test_point_ids": "all",
                        "n_train_runs": float(per["n_train_runs"].mean()), "n_test": float(per["n_test"].mean()),
                        "r2_log10": float(per["r2_log10"].mean()), "mae_log10": float(per["mae_log10"].mean())})
    metrics = pd.concat([metrics, pd.DataFrame(summary, columns=METRIC_COLUMNS)], ignore_index=True)
    return metrics, pred


def summarise(metrics: pd.DataFrame) -> dict:
    """{model: {pooled_r2_log10, pooled_mae_log10, mean_fold_r2_log10, mean_fold_mae_log10, n_folds}}."""
    out = {}
    for name, g in metrics.groupby("model", sort=False):
        pooled = g[g["fold"] == "pooled"].iloc[0]
        mean = g[g["fold"] == "mean"].iloc[0]
        out[name] = {
            "pooled_r2_log10": float(pooled["r2_log10"]), "pooled_mae_log10": float(pooled["mae_log10"]),
            "mean_fold_r2_log10": float(mean["r2_log10"]), "mean_fold_mae_log10": float(mean["mae_log10"]),
            "n_folds": int((~g["fold"].isin(["pooled", "mean"])).sum()),
        }
    return out
