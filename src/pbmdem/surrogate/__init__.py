"""MLP collision-frequency surrogate trained on the DEM collision table (see docs/surrogate.md)."""

from .baselines import HGBBaseline, PhysicalScaling
from .evaluation import cross_validate_models, summarise
from .features import DEFAULT_IMPELLER_RADIUS, FEATURE_NAMES, TARGET_NAME, make_features
from .model import CollisionSurrogate, OutOfDomainWarning, grouped_splits, make_group_cv
from .persistence import (
    IncompatibleVersionError,
    SurrogateLoadError,
    TamperedModelError,
    UntrustedTypesError,
    load_surrogate,
    save_surrogate,
)

__all__ = [
    "CollisionSurrogate", "OutOfDomainWarning", "HGBBaseline", "PhysicalScaling",
    "FEATURE_NAMES", "TARGET_NAME", "DEFAULT_IMPELLER_RADIUS", "make_features",
    "grouped_splits", "make_group_cv", "cross_validate_models", "summarise",
    "save_surrogate", "load_surrogate", "SurrogateLoadError", "TamperedModelError",
    "IncompatibleVersionError", "UntrustedTypesError",
]
