"""Population balance model of a batch high-shear wet granulator (see docs/pbm.md).

Solid volume on a geometric grid, liquid and gas lumped per bin (the feed granules as classes of
their own); aggregation by the cell-average (default) or fixed pivot technique with kernel
beta0 * c_ij * psi_ij (c_ij from a pluggable collision-frequency source), binder addition during a
spray window, consolidation toward a minimum porosity, optional breakage, adaptive
positivity-preserving explicit integration.

Its modules, one concept each: docs/architecture.md ("Packages and modules").

`setup` (and with it the settings layer) is imported on first use, so `import pbmdem.pbm` stays light.
"""

from .aggregation import SCHEMES, CellAverageAggregation, FixedPivotAggregation
from .breakage import FRAGMENTS, Breakage, ConstantSelection, PowerLawSelection
from .errors import (
    GridOverflowError,
    GridRangeError,
    KernelShapeError,
    NegativePopulationError,
    PBMError,
    PBMInputError,
)
from .grid import Grid, diameter_of, volume_of
from .kernels import (
    CollisionKernel,
    ConstantFrequency,
    ConstantKernel,
    KernelFactors,
    KernelInput,
    SuccessProbability,
    SumKernel,
    TableFrequency,
)
from .liquid_grid import LiquidGrid
from .model import GranulationPBM
from .model2d import GranulationPBM2D
from .processes import Consolidation, LiquidAddition
from .results import Result, mass_quantiles
from .state import FeedGranules, State, State2D, surface_fraction
from .success import StokesCriterion

__all__ = [
    "SCHEMES",
    "CellAverageAggregation",
    "FixedPivotAggregation",
    "Grid",
    "diameter_of",
    "volume_of",
    "ConstantKernel",
    "SumKernel",
    "CollisionKernel",
    "ConstantFrequency",
    "TableFrequency",
    "SuccessProbability",
    "StokesCriterion",
    "KernelFactors",
    "KernelInput",
    "GranulationPBM",
    "GranulationPBM2D",
    "LiquidGrid",
    "Breakage",
    "ConstantSelection",
    "PowerLawSelection",
    "FRAGMENTS",
    "State",
    "State2D",
    "FeedGranules",
    "surface_fraction",
    "LiquidAddition",
    "Consolidation",
    "Result",
    "mass_quantiles",
    "build_model",
    "initial_state",
    "run_batch",
    "PBMError",
    "PBMInputError",
    "GridRangeError",
    "GridOverflowError",
    "KernelShapeError",
    "NegativePopulationError",
]


def __getattr__(name):
    # the settings-driven entry points, imported when first used
    if name in ("build_model", "initial_state", "run_batch"):
        from . import setup  # lazy: keeps `import pbmdem.pbm` free of the settings layer (docstring)

        return getattr(setup, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
