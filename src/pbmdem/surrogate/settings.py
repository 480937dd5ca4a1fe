"""Building the surrogate's model families and baselines from the `surrogate:` settings (a complete
section from pbmdem.config; no defaults here)."""

from __future__ import annotations

from sklearn.base import clone

from pbmdem.config import Surrogate

from .ensemble import EnsembleMLPRegressorCV
from .evaluation import default_baselines
from .families import KrigingRegressor, ResponseSurface
from .features import check_impeller_radius
from .model import CollisionSurrogate

#: The families that can be the PBM's kernel source (frequency, impact-speed law and uncertainty),
#: in the order of preference when their held-out errors tie.
FAMILIES = ("mlp", "kriging", "rsm")


def _inner_model(typed: Surrogate, family: str, n_jobs: int | None):
    if family == "mlp":
        return EnsembleMLPRegressorCV(
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
    if family == "kriging":
        return KrigingRegressor(
            n_restarts_optimizer=typed.kriging.n_restarts_optimizer,
            linear_trend=typed.kriging.linear_trend,
            random_state=typed.random_state,
            n_members=typed.ensemble_size,
        )
    if family == "rsm":
        return ResponseSurface(
            degree=typed.rsm.degree, cv=typed.cv.strategy, n_splits=typed.cv.n_splits, n_members=typed.ensemble_size
        )
    raise ValueError(f"surrogate family {family!r}; allowed: {FAMILIES}")


def build_surrogate(
    settings: dict, impeller_radius: float, n_jobs: int | None = None, family: str | None = None
) -> CollisionSurrogate:
    """A :class:`CollisionSurrogate` of one family configured from a complete ``surrogate:`` section.

    ``family`` defaults to ``surrogate.model`` (``auto`` builds the MLP: the choice among the
    families is made by :func:`pbmdem.surrogate.train.train_and_report` from held-out scores).
    Every estimator parameter comes from ``settings``; ``impeller_radius`` (m) is
    ``granulator.impeller.blade_length``. The frequency and the impact-velocity model share the settings.
    """
    typed = Surrogate.from_dict(settings, "surrogate")
    family = family or (typed.model if typed.model != "auto" else "mlp")
    inner = _inner_model(typed, family, n_jobs)
    return CollisionSurrogate(
        frequency_model=inner,
        velocity_model=clone(inner),
        impeller_radius=check_impeller_radius(impeller_radius),
        physics_offset=typed.physics_offset,
        domain_margin=typed.domain_margin,
        feature_transform=typed.feature_transform,
        speed_law=typed.speed_law,
        speed_tail_from=typed.speed_tail_from,
    )


def build_families(settings: dict, impeller_radius: float, n_jobs: int | None = None) -> dict:
    """Every kernel-source family (:data:`FAMILIES`) as a configured :class:`CollisionSurrogate`."""
    return {name: build_surrogate(settings, impeller_radius, n_jobs, family=name) for name in FAMILIES}


def build_baselines(settings: dict) -> dict:
    """The baselines of the evaluation (``hgb`` seeded with ``random_state``, ``physical`` with
    the impact-speed law ``speed_law``)."""
    return default_baselines(int(settings["random_state"]), settings.get("speed_law", "lognormal"))
