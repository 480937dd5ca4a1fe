"""Settings of the population balance model (the `pbm:` section; meaning of every key: docs/pbm.md)."""

from __future__ import annotations

from dataclasses import dataclass

from .typed import Settings


@dataclass(frozen=True)
class GridSettings(Settings):
    """Geometric solid-volume grid: ratio of neighbouring pivots, first pivot diameter (m; resolved
    to the smallest feed class when the config says null), largest diameter reached (m), or a
    fixed number of bins; whether the feed granules are classes of their own (docs/pbm.md); the
    liquid classes of the two-dimensional PBM (width and open top, liquid-to-solid volume ratio)."""

    bins: int | None
    ratio: float
    min_diameter: float | None
    max_diameter: float
    liquid_step: float
    liquid_max: float
    separate_feed: bool


@dataclass(frozen=True)
class ProcessSettings(Settings):
    """Batch phases (s): dry premixing, liquid addition (the spray window), wet massing."""

    premixing_time: float
    liquid_addition_time: float
    wet_massing_time: float

    @property
    def spray_start(self) -> float:
        return self.premixing_time

    @property
    def spray_end(self) -> float:
        return self.premixing_time + self.liquid_addition_time

    @property
    def end(self) -> float:
        """End of the batch (s)."""
        return self.spray_end + self.wet_massing_time


@dataclass(frozen=True)
class InitialSettings(Settings):
    porosity: float
    liquid_content: float


@dataclass(frozen=True)
class LiquidAdditionSettings(Settings):
    rate: float
    distribution: str


@dataclass(frozen=True)
class ConsolidationSettings(Settings):
    rate: float
    min_porosity: float


@dataclass(frozen=True)
class StokesSettings(Settings):
    binder_viscosity: float
    restitution: float
    asperity_height: float
    granule_density: float


@dataclass(frozen=True)
class SuccessSettings(Settings):
    model: str
    threshold: float
    width: float
    velocity_model: str
    stokes: StokesSettings

    @property
    def velocity_resolved(self) -> bool:
        """True if the success probability needs impact velocities."""
        return self.velocity_model != "none"


@dataclass(frozen=True)
class AggregationSettings(Settings):
    scheme: str
    beta0: float
    constant_frequency: float
    constant_impact_velocity: float | None
    frequency_update_interval: float
    table_extrapolation: str
    success: SuccessSettings


@dataclass(frozen=True)
class BreakageSettings(Settings):
    """Breakage of aggregates (docs/pbm.md, "Breakage"): on or off, the fragment distribution,
    PBM-constant's selection rate (1/s per granule), and the impact criterion of PBM-DEM and
    PBM-ANN: dynamic yield strength Y (Pa, the median granule's), critical Stokes deformation
    number, the walls, whether granule-granule impacts break granules, the standard deviation
    of ln Y across granules (0: every impact above v* breaks), and how Y depends on the granule's
    size and porosity (exponents, with the diameter and porosity whose Y is ``yield_strength``)."""

    enabled: bool
    fragments: str
    constant_rate: float
    yield_strength: float
    critical_stokes: float
    walls: tuple[str, ...]
    pairs: bool
    strength_spread: float
    strength_size_exponent: float
    reference_diameter: float
    strength_porosity_exponent: float
    reference_porosity: float


@dataclass(frozen=True)
class Solver(Settings):
    """Time integration of the PBM (pbmdem.pbm.model): method, positivity safety factor, local
    error tolerances, largest step (s), refused-solid fraction, step and wall-time guards. Its
    values are checked by the model that uses them (PBMInputError)."""

    method: str
    safety: float
    rtol: float
    atol: float
    max_step: float
    max_overflow_fraction: float
    max_steps: int
    max_wall_time: float

    @classmethod
    def defaults(cls) -> Solver:
        """The schema's defaults of `pbm.solver` (the same as the config's when it sets none)."""
        from .schema import section_defaults

        return cls.from_dict(section_defaults("pbm")["solver"], "pbm.solver")


@dataclass(frozen=True)
class OutputSettings(Settings):
    interval: float


@dataclass(frozen=True)
class Pbm(Settings):
    """The `pbm:` section; ``dimensions``: 1 (lumped liquid per size class) or 2 (size x liquid
    classes, ``pbmdem.pbm.model2d``)."""

    dimensions: int
    grid: GridSettings
    process: ProcessSettings
    initial: InitialSettings
    liquid_addition: LiquidAdditionSettings
    consolidation: ConsolidationSettings
    aggregation: AggregationSettings
    breakage: BreakageSettings
    solver: Solver
    output: OutputSettings

    @classmethod
    def defaults(cls) -> Pbm:
        """The schema's defaults of the whole `pbm:` section (grid.min_diameter stays null)."""
        return cls.from_section({})

    @classmethod
    def from_section(cls, section: dict) -> Pbm:
        """Settings from a (partial) `pbm:` section, validated and completed with the schema's
        defaults (for library use without a whole configuration; grid.min_diameter stays null
        unless given)."""
        from .schema import complete_section

        return cls.from_dict(complete_section("pbm", section), "pbm")
