"""Building the surrogate and its baselines from the `surrogate:` settings (a complete section
from pbmdem.config; no defaults here)."""

from __future__ import annotations

from sklearn.base import clone

from pbmdem.config import Surrogate

from .baselines import HGBBaseline, PhysicalScaling
from .ensemble import EnsembleMLPRegressorCV
from .features import check_impeller_radius
from .model import CollisionSurrogate


def build_surrogate(settings: dict, impeller_radius: float, n_jobs: int | None = None) -> CollisionSurrogate:
    """A :class:`CollisionSurrogate` configured from a complete ``surrogate:`` section.

    Every estimator parameter comes from ``settings`` (none from the estimators' defaults);
    ``impeller_radius`` (m) is ``granulator.impeller.blade_length``. The frequency and the
    impact-velocity model share the settings.
    """
    typed = Surrogate.from_dict(settings, "surrogate")
    ensemble = EnsembleMLPRegressorCV(
        hidden_layer_sizes=typed.hidden_layer_sizes,
        alpha=typed.alpha,
        seeds=typed.member_seeds,
        max_iter=typed.max_iter,
        activation=typed.activation,
        solver=typed.solver,
        cv=typed.cv.strategy,
        n_splits=typed.cv.n_splits,
        n_jobs=n_jobs,
    )
    return CollisionSurrogate(
        frequency_model=ensemble,
        velocity_model=clone(ensemble),
        impeller_radius=check_impeller_radius(impeller_radius),
        physics_offset=typed.physics_offset,
        domain_margin=typed.domain_margin,
    )


def build_baselines(settings: dict) -> dict:
    """The baselines of the evaluation (``hgb`` seeded with ``random_state``, ``physical``)."""
    return {"hgb": HGBBaseline(random_state=int(settings["random_state"])), "physical": PhysicalScaling()}
