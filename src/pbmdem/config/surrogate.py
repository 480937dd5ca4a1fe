"""Settings of the encounter surrogate (the `surrogate:` section)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from pbmdem.impact import velocity_edge_bin

from .errors import ConfigError
from .typed import Settings, setting


class SurrogateCV(Settings):
    """Grouped cross-validation (groups are DEM runs, point_id)."""

    strategy: Literal["leave_one_group_out", "group_kfold"] = setting(
        "group_kfold",
        "group_kfold: n_splits folds of whole runs (the cost stays flat as the grid grows); "
        "leave_one_group_out: one fold per run",
    )
    n_splits: int = setting(5, "folds of group_kfold (capped at the number of runs)", ge=2)


class KrigingSettings(Settings):
    """Gaussian-process (Kriging) family."""

    n_restarts_optimizer: int = setting(
        5, "random restarts of the kernel's likelihood optimisation (seeded with random_state)", ge=0, le=50
    )
    linear_trend: bool = setting(True, "add a linear trend (universal Kriging) to the anisotropic RBF kernel")


class ResponseSurfaceSettings(Settings):
    """Response-surface family (polynomial with Bayesian ridge)."""

    degree: tuple[Annotated[int, Field(ge=1, le=4)], ...] = setting(
        (1, 2),
        "candidate polynomial degrees, chosen per output by grouped CV (1: a power law in the log "
        "features; 2: the classical quadratic response surface)",
        min_length=1,
    )


class Surrogate(Settings):
    """Hyperparameter candidates, ensemble, cross-validation and target options of the surrogate."""

    hidden_layer_sizes: tuple[
        Annotated[tuple[Annotated[int, Field(ge=1, le=256)], ...], Field(min_length=1, max_length=4)], ...
    ] = setting(
        ((8,), (16,), (8, 8)),
        "candidate hidden-layer sizes of the grid search (layer widths per candidate)",
        min_length=1,
    )
    alpha: tuple[Annotated[float, Field(gt=0)], ...] = setting(
        (0.01, 0.1, 1.0), "candidate L2 penalties of the grid search", min_length=1
    )
    ensemble_size: int = setting(5, "MLPs fitted with different seeds; their spread is the uncertainty", ge=1, le=50)
    seeds: tuple[Annotated[int, Field(ge=0)], ...] | None = setting(
        None,
        "seeds of the ensemble members (ensemble_size of them); null: random_state, random_state+1, ...",
        min_length=1,
    )
    random_state: int = setting(0, "base seed when seeds is null; also the gradient-boosting baseline's", ge=0)
    max_iter: int = setting(2000, "iteration limit of every MLP fit", ge=1)
    activation: Literal["tanh", "relu", "logistic"] = setting(
        "relu", "relu: piecewise linear, so with log features and target the network extrapolates as a power law"
    )
    solver: Literal["lbfgs", "adam"] = setting("lbfgs", "lbfgs suits the small data sets of a DEM grid")
    cv: SurrogateCV = setting(SurrogateCV, "grouped cross-validation")
    zero_collisions: Literal["drop", "floor"] = setting(
        "drop", "rows with zero collisions: drop them (warning) or floor at half a collision"
    )
    domain_margin: float = setting(
        0.0, "relative slack of each feature's training range before an OutOfDomainWarning (at most 1)", ge=0, le=1
    )
    physics_offset: Literal["cross_section", "none"] = setting(
        "cross_section", "cross_section: learn log10 c_ij - 2 log10(d_i + d_j); none: plain log10 c_ij"
    )
    speed_law: Literal["lognormal", "weibull", "gengamma"] = setting(
        "gengamma", "the law of the impact speeds the surrogate learns (docs/surrogate.md)"
    )
    speed_law_from: float | None = setting(
        None,
        "m/s, an inner edge of the velocity bins: the speed law is fitted to the bins from this speed up, "
        "the slower impacts one cell (the fast tail breakage counts); null: to every bin",
    )
    speed_tail_from: float | None = setting(
        None,
        "m/s, an inner edge of the velocity bins: above it the pair impact speeds follow one stretched exponential "
        "in tip-speed units fitted to every run's pairs at once (the fast tail breakage counts); null: the speed law's",
    )
    model: Literal["auto", "mlp", "kriging", "rsm"] = setting(
        "auto",
        "the family PBM-ANN uses: auto, per target the least held-out error (docs/surrogate.md); or mlp, kriging, rsm",
    )
    feature_transform: Literal["log", "none"] = setting("log", "log: the models see log10 of every feature")
    kriging: KrigingSettings = setting(KrigingSettings, "Gaussian-process (Kriging) family")
    rsm: ResponseSurfaceSettings = setting(ResponseSurfaceSettings, "response-surface family")

    @classmethod
    def from_section(cls, section: dict) -> Surrogate:
        """Settings from a (partial) `surrogate:` section, checked and completed with the defaults
        (for library use without a whole configuration)."""
        settings = cls.from_dict(section, "surrogate")
        problems = settings.problems()
        if problems:
            raise ConfigError("invalid configuration:\n  " + "\n  ".join(problems))
        return settings

    def problems(self) -> list[str]:
        """What a field cannot check alone: one seed per ensemble member; the speeds from which the
        law and the tail are fitted are edges of the velocity bins."""
        found = []
        if self.seeds is not None and len(self.seeds) != self.ensemble_size:
            found.append(
                f"surrogate.seeds = {list(self.seeds)}: {len(self.seeds)} seeds but ensemble_size = "
                f"{self.ensemble_size}; one seed per ensemble member (or seeds: null)"
            )
        for key in ("speed_law_from", "speed_tail_from"):
            try:
                velocity_edge_bin(getattr(self, key), f"surrogate.{key}")
            except ValueError as error:
                found.append(str(error))
        return found

    @property
    def member_seeds(self) -> tuple[int, ...]:
        """Seeds of the ensemble members: `seeds`, or random_state, random_state + 1, ..."""
        if self.seeds is not None:
            return self.seeds
        return tuple(self.random_state + k for k in range(self.ensemble_size))
