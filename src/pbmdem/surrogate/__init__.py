"""Encounter surrogate (MLP ensemble, Kriging, response surface) of the DEM collision and impact-velocity
tables (docs/surrogate.md)."""

from .baselines import HGBBaseline, PhysicalScaling
from .domain import OutOfDomainWarning
from .ensemble import EnsembleMLPRegressorCV, grouped_splits
from .errors import VelocityModelMissingError
from .evaluation import cross_validate_models, noise_floor_r2, select_family, summarise
from .families import KrigingRegressor, ResponseSurface
from .features import FEATURE_NAMES, TARGET_NAME, TrainingData, make_features, training_data
from .model import CollisionSurrogate
from .persistence import (
    IncompatibleVersionError,
    SurrogateLoadError,
    TamperedModelError,
    UntrustedTypesError,
    load_surrogate,
    save_surrogate,
)
from .velocity import attach_velocity_bins

__all__ = [
    "CollisionSurrogate",
    "EnsembleMLPRegressorCV",
    "KrigingRegressor",
    "ResponseSurface",
    "select_family",
    "OutOfDomainWarning",
    "HGBBaseline",
    "PhysicalScaling",
    "FEATURE_NAMES",
    "TARGET_NAME",
    "TrainingData",
    "make_features",
    "training_data",
    "grouped_splits",
    "cross_validate_models",
    "summarise",
    "save_surrogate",
    "load_surrogate",
    "SurrogateLoadError",
    "TamperedModelError",
    "IncompatibleVersionError",
    "UntrustedTypesError",
    "VelocityModelMissingError",
    "noise_floor_r2",
    "attach_velocity_bins",
]
