"""Train the surrogate on the collision and impact-velocity tables; write model, metadata, metrics, parity plot."""

from __future__ import annotations

import logging
import os
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.base import clone

from pbmdem.atomic import write_csv
from pbmdem.tables import GRID_PAIRS, GRID_VELOCITIES, GRID_WALL_VELOCITIES, GRID_WALLS

from .evaluation import METRIC_COLUMNS, cross_validate_models, sample_scores, select_per_target, summarise
from .features import training_data
from .persistence import save_surrogate, sha256_file
from .plots import empty_plot, parity_plot
from .settings import FAMILIES, build_baselines, build_families
from .walls import train_wall_models

log = logging.getLogger(__name__)


def _write_csv(frame: pd.DataFrame, path: Path) -> None:
    write_csv(path, frame, float_format="%.6g")


def _read_table(table, contract, need=()) -> tuple[pd.DataFrame, str]:
    """A table given as a frame or a CSV path, read and checked against its contract
    (pbmdem.tables; errors name the file, the row and the column)."""
    if isinstance(table, pd.DataFrame):
        return table, "<DataFrame>"
    return contract.read(table, need=need), str(table)


def _train_walls(surrogate, selected: str, metrics, tables, settings, impeller_radius, n_jobs):
    """The wall models (pbmdem.surrogate.walls: speed laws of the family ``selected``, the pairs' impact-speed law's)
    of the wall ``tables`` (collisions, impact velocities) into ``surrogate.wall_models_``:
    (``metrics`` with theirs appended, their summary); without wall tables (None) ``metrics`` and
    no summary."""
    wall_table, wall_velocity_table = tables
    if wall_table is None:
        return metrics, {}
    walls, source = _read_table(wall_table, GRID_WALLS)
    velocities, _ = _read_table(wall_velocity_table, GRID_WALL_VELOCITIES)
    log.info("wall tables %s: %d rows", source, len(walls))
    candidates = {**build_families(settings, impeller_radius, n_jobs=n_jobs), **build_baselines(settings)}
    models, wall_metrics, summary = train_wall_models(
        walls, velocities, candidates[selected], candidates, settings, impeller_radius
    )
    for wall, s in summary.items():
        for target, per_model in s.items():
            for name, row in per_model.items():
                log.info(
                    "%s wall, %-8s held-out %s: R2(log10) %.3f, MAE %.3f decades",
                    wall,
                    name,
                    target,
                    row["pooled_r2_log10"],
                    row["pooled_mae_log10"],
                )
    surrogate.wall_models_ = models
    return pd.concat([metrics, wall_metrics], ignore_index=True), summary


def _output_paths(model_path: Path, metadata_path, metrics_path, parity_path) -> tuple[Path, Path, Path]:
    """The metadata, metrics and parity-plot paths: as given, else siblings of ``model_path``
    (``model.json``, ``metrics.csv``, ``parity.png``)."""
    out = model_path.parent
    return (
        Path(metadata_path) if metadata_path else model_path.with_suffix(".json"),
        Path(metrics_path) if metrics_path else out / "metrics.csv",
        Path(parity_path) if parity_path else out / "parity.png",
    )


def train_and_report(
    table: str | os.PathLike | pd.DataFrame,
    model_path: str | os.PathLike,
    metadata_path: str | os.PathLike | None = None,
    metrics_path: str | os.PathLike | None = None,
    parity_path: str | os.PathLike | None = None,
    *,
    settings: dict,
    impeller_radius: float,
    n_jobs: int | None = None,
    velocity_table: str | os.PathLike | pd.DataFrame | None = None,
    wall_table: str | os.PathLike | pd.DataFrame | None = None,
    wall_velocity_table: str | os.PathLike | pd.DataFrame | None = None,
    pbm_samples=None,
) -> dict:
    """Grouped CV of the model families and baselines, choice of the kernel source, final fit on
    every run, then write the outputs.

    Every family of :data:`~pbmdem.surrogate.settings.FAMILIES` and every baseline is scored on
    the same outer folds. The kernel source is ``surrogate.model`` for both targets, or with
    ``auto`` one family per target (:func:`~pbmdem.surrogate.evaluation.select_per_target`,
    held-out scores only): the pair encounter frequency's by its held-out MAE of log10 c on the
    runs ``pbm_samples`` (point ids of the active-learning runs, ``grid.extra_points``: samples of
    the PBM's own states; without them the best pooled R2 of log10 c), the impact-speed law's by
    its held-out error of the fast tail (the fractions of impacts faster than 1-5.6 m/s, which
    breakage reads) over every run. Each target's
    calibration factor (the held-out 90 % interval coverage made nominal), on the ``pbm_samples``
    rows when there are any, else on every held-out row, becomes ``uncertainty_scale`` and
    ``velocity_uncertainty_scale`` of the final model. The wall models take the speed law's family
    for their speed laws and, for their frequencies, the family with each wall's best held-out R2
    (:func:`~pbmdem.surrogate.walls.train_wall_models`).

    ``table`` is the collision table (``results/dem/collisions.csv``), ``velocity_table`` the
    impact-velocity table (``results/dem/impact_velocity.csv``); without it the surrogate learns
    the encounter frequency only (with a warning). ``wall_table``, ``wall_velocity_table``: the wall
    models (:mod:`pbmdem.surrogate.walls`, same folds; metrics rows with the wall in ``target``).
    ``settings`` is the complete ``surrogate:`` section (``pbmdem.config``:
    ``cfg.surrogate.to_dict()``); ``impeller_radius`` (m, required) is
    ``granulator.impeller.blade_length``, for the tip-speed feature. Output paths default to siblings of
    ``model_path``: ``model.json``, ``metrics.csv``, ``parity.png``.
    Returns the metadata written to ``model.json``.
    """
    model_path = Path(model_path)
    metadata_path, metrics_path, parity_path = _output_paths(model_path, metadata_path, metrics_path, parity_path)
    data, source, velocity_source = _training_data(table, velocity_table, impeller_radius, settings)
    families = build_families(settings, impeller_radius, n_jobs=n_jobs)
    t0 = time.perf_counter()
    metrics, predictions, summary, velocity_summary = _held_out(data, families, settings)
    t_cv = time.perf_counter() - t0
    pbm_scores = _pbm_sample_scores(predictions, families, pbm_samples)
    pooled_scores = {} if predictions is None else sample_scores(predictions, list(families))
    choice = _kernel_source(settings["model"], metrics, summary, pbm_scores, pooled_scores)
    selected, speed_family = choice["frequency"], choice["speed_law"]
    surrogate, calibration = _calibrated(families, choice, summary, velocity_summary, pbm_scores, pooled_scores)
    t0 = time.perf_counter()
    _logged(
        surrogate.fit, data.X, data.y, groups=data.groups, velocity=data.velocity, velocity_counts=data.velocity_counts
    )
    metrics, wall_summary = _train_walls(surrogate, speed_family, metrics, (wall_table, wall_velocity_table), settings,
                                         impeller_radius, n_jobs)  # fmt: skip
    t_fit = time.perf_counter() - t0
    state = surrogate.frequency_model_.fitted_state()
    fitted = state.get("best_params", state.get("fitted"))
    log.info("final fit of %s: %s, %.1f s (cross-validation %.1f s)", selected, fitted, t_fit, t_cv)
    cv_scores = {
        "strategy": settings["cv"]["strategy"],
        "selected": selected,
        "selection": choice["frequency_reason"],
        "selected_speed_law": speed_family,
        "speed_law_selection": choice["speed_law_reason"],
        "pbm_samples": {"point_ids": sorted(map(str, pbm_samples or ())), "scores": pbm_scores},
        "pooled_scores": pooled_scores,
        "calibration": calibration,
        **_cv_summaries(metrics, summary, velocity_summary, wall_summary),
    }
    meta = save_surrogate(
        surrogate,
        model_path,
        metadata_path,
        cv_scores=cv_scores,
        extra={
            "training_table": source,
            "velocity_table": velocity_source,
            "training_data_sha256": _file_hashes(table, velocity_table, wall_table, wall_velocity_table),
            "settings": settings,
            "n_dropped_rows": data.n_dropped,
            "n_floored_rows": data.n_floored,
            "timing_s": {"cross_validation": t_cv, "final_fit": t_fit},
        },
    )
    _write_csv(metrics, metrics_path)
    if predictions is not None:
        parity_plot(predictions, parity_path, metrics)
    else:
        empty_plot(parity_path, "parity plot needs at least two DEM runs")
    return meta


def _cv_summaries(metrics: pd.DataFrame, summary: dict, velocity_summary: dict, wall_summary: dict) -> dict:
    """The held-out scores that ``model.json`` keeps under ``cv_scores``, besides the choice of the
    kernel source: the summaries per model and target and every outer fold's row of ``metrics``."""
    return {
        "outer_summary": summary,
        "noise_floor_r2_log10": (next(iter(summary.values()))["noise_floor_r2_log10"] if summary else None),
        "velocity_summary": velocity_summary,
        "wall_summary": wall_summary,
        "outer_folds": metrics[~metrics["fold"].isin(["pooled", "mean"])].to_dict(orient="records"),
    }


def _file_hashes(*tables) -> dict[str, str]:
    """The SHA-256 of every training table read from a file (one given as a DataFrame has none)."""
    return {str(t): sha256_file(t) for t in tables if t is not None and not isinstance(t, pd.DataFrame)}


def _logged(fn, *args, **kwargs):
    """`fn(*args, **kwargs)` with the warnings it raises written to the log (the job's log file)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = fn(*args, **kwargs)
    for w in caught:
        log.warning("%s: %s", w.category.__name__, w.message)
    return result


def _training_data(table, velocity_table, impeller_radius: float, settings: dict):
    """(training data, name of the collision table, name of the impact-velocity table or None)."""
    frame, source = _read_table(table, GRID_PAIRS, need=("point_id",))
    if "point_id" not in frame:
        raise ValueError(f"collision table {source} lacks column 'point_id'")
    log.info("collision table %s: %d rows, %d runs", source, len(frame), frame["point_id"].nunique())
    vframe, velocity_source = None, None
    if velocity_table is not None:
        vframe, velocity_source = _read_table(velocity_table, GRID_VELOCITIES)
        log.info("impact-velocity table %s: %d rows", velocity_source, len(vframe))
    data = _logged(
        training_data,
        frame,
        impeller_radius,
        settings["zero_collisions"],
        velocity_table=vframe,
        velocity_source=f"impact-velocity table {velocity_source}",
        speed_law=settings.get("speed_law", "lognormal"),
        speed_law_from=settings.get("speed_law_from"),
    )
    return data, source, velocity_source


def _held_out(data, families: dict, settings: dict):
    """Every family and baseline on the same grouped outer folds: (metrics, predictions, summary
    of the frequency, summary of the impact speed), logged; empty with a single DEM run."""
    if len(np.unique(data.groups)) >= 2:
        cv = settings["cv"]
        metrics, predictions = cross_validate_models(
            data, {**families, **build_baselines(settings)}, cv["strategy"], cv["n_splits"]
        )
    else:
        log.warning("a single DEM run: no held-out evaluation possible (metrics and parity plot are empty)")
        metrics, predictions = pd.DataFrame(columns=METRIC_COLUMNS), None
    summary = summarise(metrics)
    velocity_summary = summarise(metrics, "impact_velocity")
    for name, s in summary.items():
        log.info(
            "%-8s held-out R2(log10 c) %.3f (pooled; replicate noise floor %.3f), MAE %.3f decades, "
            "90 %% interval coverage %.2f (calibrated %.2f)",
            name,
            s["pooled_r2_log10"],
            s["noise_floor_r2_log10"],
            s["pooled_mae_log10"],
            s["coverage_90"],
            s["coverage_90_calibrated"],
        )
    for name, s in velocity_summary.items():
        log.info(
            "%-8s held-out median impact speed: MAE %.3f decades, R2(log10) %.3f; bin fractions: "
            "mean total-variation distance %.3f",
            name,
            s["pooled_mae_log10"],
            s["pooled_r2_log10"],
            s["pooled_tv_distance"],
        )
    return metrics, predictions, summary, velocity_summary


def _pbm_sample_scores(predictions, families: dict, pbm_samples) -> dict:
    """Every family's held-out scores on the rows of the runs ``pbm_samples`` (empty without them or
    without held-out predictions), logged."""
    if predictions is None or not pbm_samples:
        return {}
    scores = sample_scores(predictions, list(families), pbm_samples)
    for name, s in scores.items():
        log.info(
            "%-8s held-out on the %d active-learning runs: log10 c MAE %.3f, mean error %+.3f decades",
            name,
            s["n_runs"],
            s["mae_log10"],
            s["mean_error_log10"],
        )
    return scores


def _kernel_source(choice: str, metrics: pd.DataFrame, summary: dict, pbm_scores: dict, pooled: dict) -> dict:
    """The family of each target PBM-ANN uses (`surrogate.model`, or with auto
    :func:`~pbmdem.surrogate.evaluation.select_per_target`) and why."""
    if choice != "auto":
        reason = f"surrogate.model = {choice}"
        out = {"frequency": choice, "frequency_reason": reason, "speed_law": choice, "speed_law_reason": reason}
    elif not summary:
        reason = "surrogate.model = auto with a single DEM run: no held-out score, the first of " + ", ".join(FAMILIES)
        out = {
            "frequency": FAMILIES[0],
            "frequency_reason": reason,
            "speed_law": FAMILIES[0],
            "speed_law_reason": reason,
        }
    else:
        out = select_per_target(metrics, FAMILIES, pbm_scores, pooled)
        out["frequency_reason"] = "surrogate.model = auto: " + out["frequency_reason"]
        out["speed_law_reason"] = "surrogate.model = auto: " + out["speed_law_reason"]
    log.info("pair encounter frequency: %s (%s)", out["frequency"], out["frequency_reason"])
    log.info("impact-speed law: %s (%s)", out["speed_law"], out["speed_law_reason"])
    return out


def _calibrated(families: dict, choice: dict, summary: dict, velocity_summary: dict, pbm_scores: dict, runs: dict):
    """The surrogate of the chosen families (frequency model of one, impact-speed law of the other),
    with the held-out calibration factor of each as its uncertainty scale. The frequency's on the
    means of every held-out run (``runs``: :func:`~.evaluation.sample_scores` of every row): a member shifts every pair
    of a bed alike, and the PBM's growth follows a bed's mean error, not one pair's; the speed law's
    on the active-learning runs' rows (``pbm_scores``) when there are any, else on every held-out row.
    Returns (surrogate, {target: {family, scale, rows}})."""
    freq, speed = choice["frequency"], choice["speed_law"]
    surrogate = clone(families[freq]).set_params(velocity_model=clone(families[speed].velocity_model))
    scales, calibration = {}, {}
    # per target: the scores it is calibrated on first, their key and what they hold; the pooled rows next
    frequency_first = (runs, "run_uncertainty_scale", "means of every held-out run")
    speed_first = (pbm_scores, "velocity_uncertainty_scale", "active-learning runs")
    for key, target, family, pooled, (first, first_key, first_rows) in (
        ("uncertainty_scale", "frequency", freq, summary, frequency_first),
        ("velocity_uncertainty_scale", "speed_law", speed, velocity_summary, speed_first),
    ):
        scale, rows = first.get(family, {}).get(first_key, float("nan")), first_rows
        if not (np.isfinite(scale) and scale > 0):
            scale, rows = pooled.get(family, {}).get("uncertainty_scale", float("nan")), "every held-out run"
        if not (np.isfinite(scale) and scale > 0):
            scale, rows = 1.0, "none (no held-out rows)"
        scales[key] = float(scale)
        calibration[target] = {"family": family, "scale": float(scale), "rows": rows}
    surrogate.set_params(**scales)
    log.info(
        "calibrated uncertainty: standard deviations x %.3g (frequency, %s on %s), x %.3g (impact speed, %s on %s)",
        scales["uncertainty_scale"],
        freq,
        calibration["frequency"]["rows"],
        scales["velocity_uncertainty_scale"],
        speed,
        calibration["speed_law"]["rows"],
    )
    return surrogate, calibration
