"""Wall impacts in the surrogate: per wall (bowl, impeller), the impacts per granule of each class
and their impact-speed law, learned like the pair model (what breakage from impacts needs).

A wall row of the DEM's tables (point, class i, wall) is put into the collision table's form as the
diagonal pair (i, i): the same features (d_small = d_large = d_i, frac_small = frac_large = the
class's number fraction, rel_small = rel_large = d_i / d32, n_total, tip speed), the target
``encounter_frequency_per_pair`` taken from the wall table's ``encounter_frequency_per_particle``
(and its replicate standard error), and the velocity bins of results/dem/wall_impact_velocity.csv.
:func:`~pbmdem.surrogate.features.training_data`, the held-out evaluation
(:func:`~pbmdem.surrogate.evaluation.cross_validate_models`, the same grouped folds) and
:class:`~pbmdem.surrogate.model.CollisionSurrogate` then apply unchanged: one fitted
``CollisionSurrogate`` per wall, held in the pair model's ``wall_models_``: its frequency model of
the family with the wall's own best held-out score, its speed law of the family chosen for the
pairs' speed law. With ``physics_offset = cross_section`` the wall model learns the residual after
log10 (2 d)^2 (a granule's target area; the wall's is fixed) and the speed law after the tip speed.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from sklearn.base import clone

from pbmdem.impact import WALLS

from .evaluation import cross_validate_models, select_family, summarise
from .features import pair_features, training_data

#: wall-table columns -> collision-table columns of the diagonal pair
_RENAME = {"encounter_frequency_per_particle": "encounter_frequency_per_pair"}

#: Feature pairs equal on the diagonal by construction (their duplicate warning is expected).
DIAGONAL_TWINS = ("d_small and d_large", "frac_small and frac_large", "rel_small and rel_large")


def wall_collision_table(walls: pd.DataFrame, wall: str) -> pd.DataFrame:
    """The grid wall-collision table's rows of ``wall`` in the collision table's form (see above)."""
    rows = walls[walls["wall"].astype(str) == wall].copy()
    if rows.empty:
        raise ValueError(
            f"wall-collision table has no rows for the {wall}; walls present: {sorted(set(walls['wall']))}"
        )
    rows = rows.rename(columns=_RENAME | {f"{k}_se": f"{v}_se" for k, v in _RENAME.items()})
    rows["class_j"], rows["d_j"], rows["n_j"] = rows["class_i"], rows["d_i"], rows["n_i"]
    # a wall row is one granule's impacts: never "no pairs" for a class of one granule
    rows.loc[rows["n_i"] < 2, ["n_i", "n_j"]] = 2
    return rows.drop(columns=["wall"]).reset_index(drop=True)


def wall_velocity_table(velocities: pd.DataFrame, wall: str) -> pd.DataFrame:
    """The wall impact-velocity table's rows of ``wall`` in the pair velocity table's form."""
    rows = velocities[velocities["wall"].astype(str) == wall].copy()
    rows["class_j"] = rows["class_i"]
    return rows.drop(columns=["wall"]).reset_index(drop=True)


def wall_training_data(
    walls,
    velocities,
    wall: str,
    impeller_radius: float,
    zero_policy: str,
    speed_law: str = "lognormal",
    speed_law_from: float | None = None,
):
    """:class:`~pbmdem.surrogate.features.TrainingData` of one wall (impact-speed law ``speed_law``,
    fitted from ``speed_law_from`` m/s up)."""
    return training_data(
        wall_collision_table(walls, wall),
        impeller_radius,
        zero_policy,
        velocity_table=wall_velocity_table(velocities, wall),
        velocity_source=f"wall impact-velocity table ({wall})",
        speed_law=speed_law,
        speed_law_from=speed_law_from,
    )


def diagonal_features(diameters, numbers, rpm: float, impeller_radius: float) -> np.ndarray:
    """Feature rows (K, n_features) of the diagonal pairs (i, i): one per class."""
    X, iu, ju = pair_features(diameters, numbers, rpm, impeller_radius)
    return X[iu == ju]


def wall_laws(surrogate, X: np.ndarray, check_domain: bool = True):
    """Per wall of :data:`pbmdem.impact.WALLS` (ValueError naming the missing wall models), from
    the diagonal pairs' feature array ``X`` (:func:`diagonal_features`): the (walls, K) impacts per
    granule and the speed laws (entries of :func:`~.tail.law_fractions`) that
    :func:`~.tail.law_fractions` turns into bin fractions. A wall model fitted on the
    feature frame predicts from ``X`` (the pair model's array path: the same numbers as its
    ``predict`` on the frame, without its DataFrames and without the members' spread, which the
    PBM does not use), another from the frame; each warns of features outside its own training range."""
    models = getattr(surrogate, "wall_models_", None) or {}
    missing = [w for w in WALLS if w not in models]
    if missing:
        raise ValueError(
            f"this surrogate has no wall model for {missing}: retrain it with the wall tables "
            "(results/dem/wall_collisions.csv, wall_impact_velocity.csv) to predict wall impacts"
        )
    frequency = np.empty((len(WALLS), len(X)))
    laws, frame = [], None
    for w, wall in enumerate(WALLS):
        model = models[wall]
        if model._array_path():
            if check_domain:
                model._warn_domain(X, stacklevel=4)
            frequency[w] = 10.0 ** model._pair_log10(X)
            laws.append(model._pair_law(X))
            continue
        if frame is None:
            frame = pd.DataFrame(X, columns=surrogate._feature_names())
        frequency[w] = 10.0 ** model.predict(frame, check_domain=check_domain)
        laws.append(model._pair_law(frame))
    return frequency, laws


def train_wall_models(walls, velocities, template, candidates: dict, settings: dict, impeller_radius: float):
    """Per wall of :data:`pbmdem.impact.WALLS`: the held-out evaluation of ``candidates`` (the
    families and baselines, name -> unfitted estimator) on the grouped folds of ``settings["cv"]``
    (as the pair model's), and the final wall model fitted on every run: the frequency model of the
    family with the wall's own best pooled held-out R2 of log10 (:func:`~.evaluation.select_family`
    among the candidates that are surrogate families), the impact-speed law of ``template`` (the
    family chosen for the pairs' speed law), each with its uncertainty calibrated on its own
    held-out coverage.

    Returns ``(models, metrics, summaries)``: wall -> fitted CollisionSurrogate; the metric rows
    with ``target`` prefixed by the wall (``impeller_encounter_frequency``, ...); wall -> the
    pooled held-out summary of the frequency and the speed law (:func:`~.evaluation.summarise`).
    """
    family = next(name for name, model in candidates.items() if model is template)
    families = [name for name, model in candidates.items() if hasattr(model, "frequency_model")]
    models, frames, summaries = {}, [], {}
    for wall in WALLS:
        data = wall_training_data(
            walls,
            velocities,
            wall,
            impeller_radius,
            settings["zero_collisions"],
            settings.get("speed_law", "lognormal"),
            settings.get("speed_law_from"),
        )
        metrics, _ = cross_validate_models(
            data,
            {name: clone(m) for name, m in candidates.items()},
            settings["cv"]["strategy"],
            settings["cv"]["n_splits"],
        )
        frequency, speed = summarise(metrics), summarise(metrics, "impact_velocity")
        summaries[wall] = {"frequency": frequency, "impact_velocity": speed}
        # the frequency's family by the wall's own held-out score: the speed law's family (chosen by the
        # pairs' fast tail) had R2 0.720 for the impeller where Kriging had 0.894 (docs/surrogate.md)
        chosen = select_family(metrics, families)
        scales = {}
        for key, s, name in (("uncertainty_scale", frequency, chosen), ("velocity_uncertainty_scale", speed, family)):
            scale = s.get(name, {}).get("uncertainty_scale", float("nan"))
            scales[key] = float(scale) if np.isfinite(scale) and scale > 0 else 1.0
        # as the pair model's (train._calibrated): the family's frequency, the template's speed law
        model = clone(candidates[chosen]).set_params(velocity_model=clone(template.velocity_model), **scales)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=f"features ({'|'.join(DIAGONAL_TWINS)}) are")
            models[wall] = model.fit(
                data.X, data.y, groups=data.groups, velocity=data.velocity, velocity_counts=data.velocity_counts
            )
        frames.append(metrics.assign(target=wall + "_" + metrics["target"]))
    return models, pd.concat(frames, ignore_index=True), summaries
