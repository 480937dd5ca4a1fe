"""Settings of the encounter surrogate (the `surrogate:` section)."""

from __future__ import annotations

from dataclasses import dataclass

from .typed import Settings


@dataclass(frozen=True)
class SurrogateCV(Settings):
    """Grouped cross-validation: strategy and folds of group_kfold."""

    strategy: str
    n_splits: int


@dataclass(frozen=True)
class KrigingSettings(Settings):
    """Gaussian-process (Kriging) family: optimiser restarts and the linear trend."""

    n_restarts_optimizer: int
    linear_trend: bool


@dataclass(frozen=True)
class ResponseSurfaceSettings(Settings):
    """Polynomial response-surface family: its candidate degrees (chosen by grouped CV)."""

    degree: tuple[int, ...]


@dataclass(frozen=True)
class Surrogate(Settings):
    """Hyperparameter candidates, ensemble, cross-validation and target options of the surrogate."""

    hidden_layer_sizes: tuple[tuple[int, ...], ...]
    alpha: tuple[float, ...]
    ensemble_size: int
    seeds: tuple[int, ...] | None
    random_state: int
    max_iter: int
    activation: str
    solver: str
    cv: SurrogateCV
    zero_collisions: str
    domain_margin: float
    physics_offset: str
    speed_law: str
    model: str
    feature_transform: str
    kriging: KrigingSettings
    rsm: ResponseSurfaceSettings

    @classmethod
    def from_section(cls, section: dict) -> Surrogate:
        """Settings from a (partial) `surrogate:` section, validated and completed with the
        schema's defaults (for library use without a whole configuration)."""
        from .errors import ConfigError
        from .schema import complete_section

        settings = cls.from_dict(complete_section("surrogate", section), "surrogate")
        problems = settings.problems()
        if problems:
            raise ConfigError("invalid configuration:\n  " + "\n  ".join(problems))
        return settings

    def problems(self) -> list[str]:
        """What the schema cannot check: one seed per ensemble member."""
        if self.seeds is not None and len(self.seeds) != self.ensemble_size:
            return [
                f"surrogate.seeds = {list(self.seeds)}: {len(self.seeds)} seeds but ensemble_size = "
                f"{self.ensemble_size}; one seed per ensemble member (or seeds: null)"
            ]
        return []

    @property
    def member_seeds(self) -> tuple[int, ...]:
        """Seeds of the ensemble members: `seeds`, or random_state, random_state + 1, ..."""
        if self.seeds is not None:
            return self.seeds
        return tuple(self.random_state + k for k in range(self.ensemble_size))
