"""A PBM batch from the typed settings: model, initial state, run (docs/pbm.md).

`build_model(pbm, source, rpm)` builds a GranulationPBM from the `pbm:` settings
(`pbmdem.config.Pbm`), or with `pbm.dimensions: 2` the two-dimensional GranulationPBM2D;
`initial_state(batch, model)` puts the batch's feed on the grid, scaled to the bed's solid volume
(owned by `pbmdem.config.Granulator.bed_solid_volume`: the PBM models the DEM bed);
`run_batch(batch, source, rpm)` runs the whole batch.
"""

from __future__ import annotations

import numpy as np

from pbmdem.config import Pbm, PbmBatch

from .breakage import Breakage, ConstantSelection
from .errors import PBMInputError
from .grid import Grid, volume_of
from .kernels import CollisionKernel, ConstantFrequency
from .liquid_grid import LiquidGrid
from .model import GranulationPBM
from .model2d import GranulationPBM2D
from .processes import Consolidation, LiquidAddition
from .state import State
from .success import StokesCriterion, SuccessProbability


def build_success(pbm: Pbm) -> SuccessProbability:
    """The success probability of `pbm.aggregation.success`: the surface-liquid condition, times
    the Stokes criterion if `velocity_model: stokes`."""
    succ = pbm.aggregation.success
    velocity = None
    if succ.velocity_model == "stokes":
        st = succ.stokes
        velocity = StokesCriterion(st.binder_viscosity, st.restitution, st.asperity_height, st.granule_density)
    return SuccessProbability(succ.model, succ.threshold, succ.width, velocity=velocity)


def build_grid(pbm: Pbm) -> Grid:
    g = pbm.grid
    if g.min_diameter is None:
        raise PBMInputError(
            "pbm.grid.min_diameter = null (the smallest class of size_distributions) but no "
            "configuration resolved it; allowed: a diameter (m), or settings from "
            "pbmdem.config.load_config"
        )
    if g.bins is not None:
        return Grid(g.bins, g.ratio, min_diameter=g.min_diameter)
    return Grid.spanning(g.min_diameter, g.max_diameter, g.ratio)


def constant_source(pbm: Pbm) -> ConstantFrequency:
    """The constant collision-frequency source of `pbm.aggregation` (constant_frequency, and
    constant_impact_velocity for a velocity-dependent success)."""
    agg = pbm.aggregation
    if agg.success.velocity_resolved and agg.constant_impact_velocity is None:
        raise PBMInputError(
            "pbm.aggregation.success.velocity_model = "
            f"{agg.success.velocity_model!r} needs impact velocities; the constant "
            "collision-frequency kernel has them only with pbm.aggregation."
            "constant_impact_velocity = a speed in m/s (now null)"
        )
    return ConstantFrequency(agg.constant_frequency, agg.constant_impact_velocity)


def build_breakage(pbm: Pbm, selection=None) -> Breakage | None:
    """The breakage of `pbm.breakage`: None if not enabled; else the fragment distribution with
    the selection rate `selection` (a SelectionRate, e.g. from impact statistics), by default
    PBM-constant's ConstantSelection(constant_rate)."""
    brk = pbm.breakage
    if not brk.enabled:
        return None
    return Breakage(ConstantSelection(brk.constant_rate) if selection is None else selection, brk.fragments)


def build_model(pbm: Pbm, source=None, rpm: float = 0.0, selection=None) -> GranulationPBM:
    """GranulationPBM of the `pbm:` settings (`pbm.dimensions` 2: a GranulationPBM2D with the
    liquid classes of `pbm.grid`); `source` (collision-frequency source) defaults to
    the constant one of `pbm.aggregation`. With `pbm.breakage.enabled`, the breakage's selection
    rate is `selection`; None: PBM-constant's constant rate, allowed only with the constant
    source (a DEM or surrogate source needs the selection from its impact statistics)."""
    if pbm.dimensions == 2 and pbm.aggregation.success.velocity_resolved:
        raise PBMInputError(
            f"pbm.dimensions = 2 with pbm.aggregation.success.velocity_model = "
            f"{pbm.aggregation.success.velocity_model!r}: the two-dimensional PBM evaluates the success "
            "of every (size, liquid) class inside its compiled rates, which the Stokes criterion's "
            "kernel does not offer; allowed: velocity_model none, or dimensions 1"
        )
    grid = build_grid(pbm)
    agg = pbm.aggregation
    if source is None:
        source = constant_source(pbm)
    elif selection is None and pbm.breakage.enabled:
        raise PBMInputError(
            f"pbm.breakage.enabled = true with the collision-frequency source {source!r} needs the "
            "selection rate from that source's impact statistics (build_model(..., selection=...)); "
            "allowed: pbm.breakage.enabled = false, or a selection"
        )
    kernel = CollisionKernel(source, agg.beta0, build_success(pbm), update_interval=agg.frequency_update_interval)
    process = pbm.process
    liquid = LiquidAddition(
        pbm.liquid_addition.rate, process.spray_start, process.spray_end, pbm.liquid_addition.distribution
    )
    cons = Consolidation(pbm.consolidation.rate, pbm.consolidation.min_porosity)
    kwargs = {"rpm": rpm, "scheme": agg.scheme, "separate_feed": pbm.grid.separate_feed}
    kwargs["breakage"] = build_breakage(pbm, selection)
    if pbm.dimensions == 2:
        lg = LiquidGrid.uniform(pbm.grid.liquid_step, pbm.grid.liquid_max)
        return GranulationPBM2D(grid, kernel, liquid, cons, pbm.solver, liquid_grid=lg, **kwargs)
    return GranulationPBM(grid, kernel, liquid, cons, pbm.solver, **kwargs)


def initial_state(batch: PbmBatch, model: GranulationPBM) -> State:
    """The feed of `batch` on the model's grid: number fractions scaled so that the population
    holds the bed's solid volume, with the initial liquid content and porosity."""
    d = np.asarray(batch.sizes.diameters, float)
    f = np.asarray(batch.sizes.number_fractions, float)
    u = volume_of(d)
    f = f / f.sum()
    numbers = batch.bed_solid_volume / float(np.sum(f * u)) * f
    ini = batch.pbm.initial
    return model.initial_state(
        u,
        numbers,
        liquid_content=ini.liquid_content,
        porosity=ini.porosity,
        what=f"size distribution {batch.distribution!r}",
    )


def output_times(pbm: Pbm, t_start: float, t_end: float) -> np.ndarray:
    """The recorded times of a run from t_start to t_end: every pbm.output.interval."""
    step = pbm.output.interval
    times = np.arange(t_start, t_end + 0.5 * step, step)
    return times[(times >= t_start) & (times <= t_end)]


def run_batch(
    batch: PbmBatch, source=None, rpm: float = 0.0, *, t_end: float | None = None, times=None, selection=None
):
    """Run the batch granulation of `batch` at impeller speed `rpm` (the source's input) with the
    collision-frequency source `source` (default: the constant one) until `t_end` (default: the
    end of the batch), recording at `times` (default: every pbm.output.interval), with the breakage
    selection rate `selection` (build_model). Returns a Result."""
    model = build_model(batch.pbm, source, rpm, selection)
    state = initial_state(batch, model)
    t_end = batch.pbm.process.end if t_end is None else float(t_end)
    times = output_times(batch.pbm, 0.0, t_end) if times is None else times
    res = model.run(0.0, t_end, state, output_times=times)
    res.info.update(
        {
            "distribution": batch.distribution,
            "source": repr(model.kernel.source),
            "frequency_evaluations": model.kernel.evaluations,
            "bed_solid_volume": batch.bed_solid_volume,
            "settings": batch.pbm.to_dict(),
            "spray_window": [batch.pbm.process.spray_start, batch.pbm.process.spray_end],
        }
    )
    return res
