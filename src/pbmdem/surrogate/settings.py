"""Building the surrogate from the `surrogate:` settings (a complete section: pbmdem.config)."""

from __future__ import annotations

from .model import CollisionSurrogate


def build_surrogate(settings: dict, impeller_radius: float,
                    n_jobs: int | None = None) -> CollisionSurrogate:
    """A :class:`CollisionSurrogate` configured from resolved settings."""
    return CollisionSurrogate(
        hidden_layer_sizes=tuple(tuple(h) for h in settings["hidden_layer_sizes"]),
        alpha=tuple(float(a) for a in settings["alpha"]),
        ensemble_size=int(settings["ensemble_size"]),
        seeds=None if settings["seeds"] is None else tuple(int(s) for s in settings["seeds"]),
        random_state=int(settings["random_state"]),
        max_iter=int(settings["max_iter"]),
        activation=settings["activation"],
        solver=settings["solver"],
        cv=settings["cv"]["strategy"],
        n_splits=int(settings["cv"]["n_splits"]),
        impeller_radius=float(impeller_radius),
        zero_policy=settings["zero_collisions"],
        domain_margin=float(settings["domain_margin"]),
        n_jobs=n_jobs,
        physics_offset=settings["physics_offset"],
    )
