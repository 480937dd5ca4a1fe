"""What the surrogate was trained on (from the grid collision table, the points its model.json
names), beside its held-out accuracy (docs/validation.md, "Report").
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pbmdem.readers import InputFileError
from pbmdem.surrogate.plots import MODEL_LABELS

from . import words


def training_set(table: pd.DataFrame, source: str = "", point_ids=None) -> dict:
    """The DEM runs behind a surrogate (every replicate counted), its operating points, their distinct
    replicate counts, speeds (rpm) and feeds, from a grid collision table restricted to `point_ids` (the
    surrogate's metadata) when given; a point the metadata names but the table lacks is an error."""
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
    return {
        "runs": int(replicates.sum()),
        "points": len(points),
        "replicates": tuple(sorted(set(replicates.tolist()))),
        "speeds": tuple(sorted(set(points["rpm"].astype(float).tolist()))),
        "feeds": tuple(sorted(set(points["distribution"].astype(str).tolist()))),
    }


def training_words(training: dict, meta: dict, table: str = "results/dem/collisions.csv") -> str:
    """The training set and the held-out accuracy of the kernel source in one paragraph (rst)."""
    scores = meta.get("cv_scores") or {}
    family = scores.get("selected") or meta.get("family")
    summary = (scores.get("outer_summary") or {}).get(family) if family else None
    # a score the metadata left empty (None: e.g. no noise floor from single-replicate points) is NaN
    r2, mae, floor = (
        float(np.nan if not summary or summary.get(k) is None else summary[k])
        for k in ("pooled_r2_log10", "pooled_mae_log10", "noise_floor_r2_log10")
    )
    return words.paragraph(
        "training",
        **training,
        table=table,
        family=MODEL_LABELS.get(str(family), str(family)),
        scored=bool(summary),
        strategy=str(scores.get("strategy", "grouped")).replace("_", " "),
        folds=int((summary or {}).get("n_folds") or 0),
        r2=r2,
        mae=mae,
        floor=floor if np.isfinite(floor) else None,
    )
