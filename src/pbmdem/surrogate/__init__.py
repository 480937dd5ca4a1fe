"""MLP encounter surrogate trained on the DEM collision and impact-velocity tables (docs/surrogate.md)."""

from .baselines import HGBBaseline, PhysicalScaling
from .evaluation import cross_validate_models, noise_floor_r2, summarise
from .features import DEFAULT_IMPELLER_RADIUS, FEATURE_NAMES, TARGET_NAME, make_features
from .model import CollisionSurrogate, OutOfDomainWarning, VelocityModelMissingError, grouped_splits, make_group_cv
from .persistence import (
    IncompatibleVersionError,
    SurrogateLoadError,
    TamperedModelError,
    UntrustedTypesError,
    load_surrogate,
    save_surrogate,
)
from .velocity import attach_velocity_bins, fit_lognormal, lognormal_fractions

__all__ = [
    "CollisionSurrogate", "OutOfDomainWarning", "HGBBaseline", "PhysicalScaling",
    "FEATURE_NAMES", "TARGET_NAME", "DEFAULT_IMPELLER_RADIUS", "make_features",
    "grouped_splits", "make_group_cv", "cross_validate_models", "summarise",
    "save_surrogate", "load_surrogate", "SurrogateLoadError", "TamperedModelError",
    "IncompatibleVersionError", "UntrustedTypesError", "VelocityModelMissingError", "noise_floor_r2",
    "attach_velocity_bins", "fit_lognormal", "lognormal_fractions",
]
