"""What the surrogate was trained on, beside its accuracy on DEM runs it never saw.

The training set is read from the collision table the surrogate was fitted on (the grid table,
results/dem/collisions.csv: one row per operating point and class pair, with the replicates behind
each mean), restricted to the operating points its metadata (results/surrogate/model.json) names;
the accuracy is the pooled held-out score of its kernel source that the metadata records
(`cv_scores`, grouped cross-validation: whole operating points held out). A reader judging how far
to trust PBM-ANN needs both: how many DEM runs, operating points and replicates, which speeds and
feeds, and how well the surrogate predicts the points it did not see.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from pbmdem.readers import InputFileError
from pbmdem.surrogate.plots import MODEL_LABELS


@dataclass(frozen=True)
class TrainingSet:
    """The DEM runs behind a surrogate: `runs` (every replicate counted), `points` (operating
    points: a speed and a feed), the replicates per point (sorted, distinct), the impeller speeds
    (rpm) and the feeds (size distributions)."""

    runs: int
    points: int
    replicates: tuple[int, ...]
    speeds: tuple[float, ...]
    feeds: tuple[str, ...]


def training_set(table: pd.DataFrame, source: str = "", point_ids=None) -> TrainingSet:
    """The training set of a grid collision table (columns point_id, rpm, distribution,
    n_replicates), restricted to `point_ids` (the surrogate's metadata) when given; a point the
    metadata names but the table lacks is an InputFileError naming `source`."""
    points = table.groupby("point_id", sort=True).agg(
        rpm=("rpm", "first"), distribution=("distribution", "first"), n_replicates=("n_replicates", "max")
    )
    if point_ids is not None:
        missing = sorted(set(map(str, point_ids)) - set(points.index.astype(str)))
        if missing:
            raise InputFileError(
                f"collision table {source}: the surrogate was trained on operating point(s) {missing} that it "
                "lacks (the table was rewritten after training; rerun the workflow to retrain the surrogate)"
            )
        points = points[points.index.astype(str).isin(set(map(str, point_ids)))]
    replicates = points["n_replicates"].astype(int)
    return TrainingSet(
        runs=int(replicates.sum()),
        points=len(points),
        replicates=tuple(sorted(set(replicates.tolist()))),
        speeds=tuple(sorted(set(points["rpm"].astype(float).tolist()))),
        feeds=tuple(sorted(set(points["distribution"].astype(str).tolist()))),
    )


def _listed(items) -> str:
    items = list(items)
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _replicates(replicates: tuple[int, ...]) -> str:
    if len(replicates) == 1:
        n = replicates[0]
        return f"{n} replicate{'s' if n != 1 else ''} each (DEM insertion seeds)"
    return f"{replicates[0]} to {replicates[-1]} replicates per point (DEM insertion seeds)"


def _plural(n: int, noun: str) -> str:
    return f"{n} {noun}{'s' if n != 1 else ''}"


def training_words(training: TrainingSet, meta: dict, table: str = "results/dem/collisions.csv") -> str:
    """The training set and the held-out accuracy of the kernel source in one paragraph (rst)."""
    speed_noun = "impeller speeds" if len(training.speeds) != 1 else "impeller speed"
    feed_noun = "feeds" if len(training.feeds) != 1 else "feed"
    text = (
        f"The surrogate was trained on {_plural(training.runs, 'DEM run')}: "
        f"{_plural(training.points, 'operating point')} ({speed_noun} {_listed([f'{s:g}' for s in training.speeds])} "
        f"rpm; {feed_noun} {_listed(training.feeds)}) with {_replicates(training.replicates)}, the table "
        f"``{table}``. "
    )
    return text + _accuracy_words(meta)


def _accuracy_words(meta: dict) -> str:
    scores = meta.get("cv_scores") or {}
    family = scores.get("selected") or meta.get("family")
    summary = (scores.get("outer_summary") or {}).get(family) if family else None
    label = MODEL_LABELS.get(str(family), str(family))
    if not summary:
        return f"Its kernel source, the {label}, has no held-out score (a single operating point: nothing to hold out)."
    # a score the metadata left empty (None: e.g. no noise floor from single-replicate points) is NaN
    r2, mae, floor = (
        float(np.nan if summary.get(k) is None else summary[k])
        for k in ("pooled_r2_log10", "pooled_mae_log10", "noise_floor_r2_log10")
    )
    folds = int(summary.get("n_folds") or 0)
    strategy = str(scores.get("strategy", "grouped")).replace("_", " ")
    ceiling = (
        f"the spread between DEM replicates allows R2 = {floor:.3f} at best (the noise floor)"
        if np.isfinite(floor)
        else "the noise floor is not known (no point was run more than once)"
    )
    return (
        f"On operating points it never saw ({strategy} cross-validation, {folds} folds, whole points held out) "
        f"its kernel source, the {label}, predicts log10 of the encounter frequency per particle pair with "
        f"R2 = {r2:.3f} and a mean absolute error of {mae:.3f} decades; {ceiling}."
    )
