"""Settings of the population balance model (the `pbm:` section; meaning of every key: docs/pbm.md)."""

from __future__ import annotations

from typing import Literal

from .typed import Settings, Unique, setting


class GridSettings(Settings):
    """Geometric solid-volume grid v_k = v_0 ratio^k (docs/pbm.md)."""

    bins: int | None = setting(None, "number of bins K; null: as many as reach max_diameter", ge=3, le=400)
    ratio: float = setting(1.2599210498948732, "volume ratio of neighbouring pivots (2^(1/3))", gt=1, le=4)
    min_diameter: float | None = setting(
        None, "diameter of the first pivot; null: the smallest class of the size_distributions", "m", gt=0, le=0.1
    )
    max_diameter: float = setting(
        0.032,
        "largest diameter the grid reaches (the last pivot is the first at or above it; bins null)",
        "m",
        gt=0,
        le=10,
    )
    liquid_step: float = setting(0.02, "dimensions 2: width of the liquid classes (liquid/solid volume)", gt=0, le=1)
    liquid_max: float = setting(
        1.0, "dimensions 2: lower bound of the last, open liquid class (liquid/solid volume)", gt=0, le=100
    )
    separate_feed: bool = setting(
        True, "feed granules keep their own size, liquid and gas until they aggregate (false: share their bins')"
    )


class ProcessSettings(Settings):
    """Batch phases (s): dry premixing, liquid addition (the spray window), wet massing."""

    premixing_time: float = setting(60.0, "dry mixing before spraying", "s", ge=0, le=36000)
    liquid_addition_time: float = setting(180.0, "spray window length", "s", gt=0, le=36000)
    wet_massing_time: float = setting(240.0, "mixing after spraying", "s", ge=0, le=36000)

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


class InitialSettings(Settings):
    porosity: float = setting(
        0.5, "initial intra-granular porosity G/(S+G); must be >= consolidation.min_porosity", ge=0, lt=1
    )
    liquid_content: float = setting(0.0, "initial liquid volume per solid volume", ge=0, le=10)


class LiquidAdditionSettings(Settings):
    rate: float = setting(6.4e-8, "binder spray rate", "m3/s", gt=0, le=1.0e-3)
    distribution: Literal["surface_area", "solid_volume"] = setting(
        "surface_area", "share of the spray per bin, proportional to N_k d_k^2 or to N_k v_k"
    )


class ConsolidationSettings(Settings):
    rate: float = setting(0.02, "c in dG/dt = -c (G - eps_min/(1-eps_min) S)", "1/s", gt=0, le=100)
    min_porosity: float = setting(0.2, "minimum porosity eps_min", ge=0, lt=1)


class StokesSettings(Settings):
    """Parameters of the viscous Stokes criterion (velocity_model stokes)."""

    binder_viscosity: float = setting(
        0.1, "binder viscosity (water 1e-3, binder solutions 1e-2..1)", "Pa s", ge=1.0e-4, le=1000
    )
    restitution: float = setting(0.4, "coefficient of restitution e of the solid contact", gt=0, le=1)
    asperity_height: float = setting(5.0e-6, "surface asperity height h_a", "m", gt=0, le=1.0e-3)
    granule_density: float = setting(1000.0, "granule density for the granule mass", "kg/m3", ge=10, le=20000)


class SuccessSettings(Settings):
    """Success probability psi_ij from the surface-liquid volume fraction of both granules."""

    model: Literal["step", "logistic", "always"] = setting("step", "shape of the success switch")
    threshold: float = setting(0.02, "surface-liquid volume fraction of the switch", ge=0, lt=1)
    width: float = setting(0.005, "width of the logistic switch", gt=0, le=1)
    velocity_model: Literal["none", "stokes"] = setting(
        "none", "none: velocity-independent success (seed study); stokes: also St_v < St* (Ennis et al. 1991)"
    )
    stokes: StokesSettings = setting(StokesSettings, "the viscous Stokes criterion")

    @property
    def velocity_resolved(self) -> bool:
        """True if the success probability needs impact velocities."""
        return self.velocity_model != "none"


class AggregationSettings(Settings):
    scheme: Literal["cell_average", "fixed_pivot"] = setting(
        "cell_average", "discretisation on the pivots (Kumar et al. 2006 / Kumar & Ramkrishna 1996)"
    )
    beta0: float = setting(2.0e-4, "rate constant in beta_ij = beta0 c_ij psi_ij (successful fraction)", gt=0, le=1000)
    constant_frequency: float = setting(
        0.12, "per-pair collision frequency c_ij of the constant kernel", "1/s", gt=0, le=1.0e6
    )
    constant_impact_velocity: float | None = setting(
        None, "impact speed of every encounter of the constant kernel; null: none", "m/s", gt=0, le=100
    )
    frequency_update_interval: float = setting(
        1.0, "re-evaluate c_ij after this time; 0: every step", "s", ge=0, le=36000
    )
    table_extrapolation: Literal["clamp", "linear"] = setting(
        "clamp", "DEM-table frequencies outside the table's sizes: nearest size, or a power law"
    )
    success: SuccessSettings = setting(SuccessSettings, "success probability psi_ij")


class BreakageSettings(Settings):
    """Breakage of aggregates (docs/pbm.md, "Breakage"): selection rate and fragment distribution."""

    enabled: bool = setting(
        False,
        "aggregates break (PBM-constant at constant_rate, PBM-DEM and PBM-ANN from "
        "impact statistics); false: aggregation only",
    )
    fragments: Literal["binary", "uniform"] = setting(
        "binary", "binary: two equal fragments; uniform: any split equally likely, b(v|u) = 2/u"
    )
    constant_rate: float = setting(0.002, "selection rate of PBM-constant, per granule", "1/s", ge=0, le=1.0e3)
    yield_strength: float = setting(1.0e4, "median granule dynamic yield strength Y", "Pa", gt=0, le=1.0e9)
    critical_stokes: float = setting(0.2, "critical Stokes deformation number St_def*", gt=0, le=1.0e3)
    walls: Unique[Literal["impeller", "bowl"]] = setting(("impeller", "bowl"), "wall impacts that can break a granule")
    pairs: bool = setting(True, "granule-granule impacts can break a granule too")
    strength_spread: float = setting(
        0.5, "standard deviation of ln Y across granules; 0: every impact above v* breaks", ge=0, le=5
    )
    strength_size_exponent: float = setting(
        0.0, "e in Y(d) = Y (d / reference_diameter)^(-e); 0: one Y for every size", ge=0, le=3
    )
    reference_diameter: float = setting(
        0.002, "diameter whose dynamic yield strength is yield_strength", "m", gt=0, le=1
    )
    strength_porosity_exponent: float = setting(
        0.0, "n in Y(eps) = Y [((1-eps)/eps) / ((1-eps_ref)/eps_ref)]^n; 0: one Y at every porosity", ge=0, le=4
    )
    reference_porosity: float = setting(
        0.5, "porosity eps_ref whose dynamic yield strength is yield_strength", gt=0, lt=1
    )


class Solver(Settings):
    """Time integration of the PBM (pbmdem.pbm.model)."""

    method: Literal["ssp3", "heun", "euler"] = setting(
        "ssp3", "SSP-RK3 with embedded Heun error estimate, SSP-RK2 (Heun) with embedded Euler, or forward Euler"
    )
    safety: float = setting(0.5, "fraction of the fastest depletion time per step", gt=0, le=1)
    rtol: float = setting(1.0e-3, "relative local error per step (ssp3, heun)", gt=0, le=1)
    atol: float = setting(1.0e-6, "error floor as a fraction of the total solid volume", gt=0, le=1)
    max_step: float = setting(10.0, "largest time step", "s", gt=0, le=36000)
    max_overflow_fraction: float = setting(
        1.0e-6, "solid volume refused beyond the last bin, as a fraction of the total, that stops the run", ge=0, le=1
    )
    max_steps: int = setting(1000000, "guard: a run stops with an error after this many steps", ge=1)
    max_wall_time: float = setting(3600.0, "guard: a run stops with an error after this much wall time", "s", gt=0)


class OutputSettings(Settings):
    interval: float = setting(10.0, "time between recorded states", "s", gt=0, le=36000)


class Pbm(Settings):
    """The `pbm:` section; ``dimensions``: 1 (lumped liquid per size class) or 2 (size x liquid
    classes, ``pbmdem.pbm.model2d``)."""

    dimensions: Literal[1, 2] = setting(
        1, "1: classed by solid volume; 2: by solid volume and liquid-to-solid ratio (docs/pbm.md)"
    )
    grid: GridSettings = setting(GridSettings, "geometric solid-volume grid v_k = v_0 ratio^k")
    process: ProcessSettings = setting(ProcessSettings, "batch phases: premixing, liquid addition, wet massing")
    initial: InitialSettings = setting(InitialSettings, "the initial granules")
    liquid_addition: LiquidAdditionSettings = setting(LiquidAdditionSettings, "the binder spray")
    consolidation: ConsolidationSettings = setting(ConsolidationSettings, "consolidation of the granules")
    aggregation: AggregationSettings = setting(AggregationSettings, "aggregation kernel")
    breakage: BreakageSettings = setting(BreakageSettings, "breakage of aggregates")
    solver: Solver = setting(Solver, "time integration")
    output: OutputSettings = setting(OutputSettings, "recorded states")
