"""Population balance model of a batch high-shear wet granulator (see docs/pbm.md).

Solid volume on a geometric grid, liquid and gas lumped per bin; aggregation by the cell-average
(default) or fixed pivot technique with kernel beta0 * c_ij * psi_ij (c_ij from a pluggable collision-frequency source),
binder addition during a spray window, consolidation toward a minimum porosity, adaptive
positivity-preserving explicit integration.
"""

from .aggregation import SCHEMES, CellAverageAggregation, FixedPivotAggregation
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
    KernelInput,
    SuccessProbability,
    SumKernel,
    TableFrequency,
)
from .model import GranulationPBM, SolverSettings, State, surface_fraction
from .processes import Consolidation, LiquidAddition
from .results import Result, mass_quantiles
from .success import StokesCriterion
from .setup import build_model, initial_state, run_batch

__all__ = [
    "SCHEMES", "CellAverageAggregation", "FixedPivotAggregation", "Grid", "diameter_of", "volume_of",
    "ConstantKernel", "SumKernel", "CollisionKernel", "ConstantFrequency", "TableFrequency",
    "SuccessProbability", "StokesCriterion", "KernelInput", "GranulationPBM", "SolverSettings", "State", "surface_fraction",
    "LiquidAddition", "Consolidation", "Result", "mass_quantiles",
    "build_model", "initial_state", "run_batch",
    "PBMError", "PBMInputError", "GridRangeError", "GridOverflowError", "KernelShapeError",
    "NegativePopulationError",
]
