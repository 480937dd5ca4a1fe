"""The settings layer of pbmdem: one validated, typed configuration for every path.

    from pbmdem.config import load_config
    cfg = load_config("config/config.yaml")        # a Config: frozen, typed, defaults filled
    cfg.granulator.tip_speed(600)                   # m/s
    cfg.dem_point("fine")                           # what one DEM run of feed 'fine' uses

The schema (`workflow/schemas/*.schema.yaml`, shipped as package data) is the only place
defaults live; `Config.from_mapping` validates once, fills them in, and builds the typed objects.
"""

from .dem import Dem, DemExecution
from .design import Calibration, DesignSpace, Factor, Sensitivity, SobolFactor, Specification
from .errors import RPM_MAX, ConfigError, check_rpm
from .granulator import Bed, Bowl, Granulator, Impeller, Material
from .pbm import Pbm, Solver
from .points import (
    BLEND_JOIN,
    ExtraPoint,
    OperatingGrid,
    SizeDistribution,
    feed_case_names,
    feed_case_parents,
    point_id,
    rpm_text,
)
from .schema import complete, non_finite_values, schema_dir, section_defaults
from .settings import Config, CoupledLoop, DemPoint, PbmBatch, SurrogateTraining
from .surrogate import Surrogate
from .validation import FeedCheck, SampleRule, Sweep, Validation
from .yamlfile import load_yaml


def load_config(path) -> Config:
    """Read, validate and complete a config file; ConfigError naming the file otherwise."""
    data = load_yaml(path, "config file")
    if not isinstance(data, dict):
        raise ConfigError(f"config file {path}: the top level must be a mapping of sections")
    return Config.from_mapping(data, source=path)


__all__ = [
    "Config",
    "ConfigError",
    "load_config",
    "load_yaml",
    "check_rpm",
    "RPM_MAX",
    "complete",
    "non_finite_values",
    "schema_dir",
    "section_defaults",
    "Granulator",
    "Bowl",
    "Impeller",
    "Bed",
    "Material",
    "SizeDistribution",
    "ExtraPoint",
    "OperatingGrid",
    "point_id",
    "feed_case_names",
    "feed_case_parents",
    "BLEND_JOIN",
    "rpm_text",
    "Dem",
    "DemExecution",
    "Pbm",
    "Solver",
    "Surrogate",
    "Validation",
    "Sweep",
    "FeedCheck",
    "SampleRule",
    "DemPoint",
    "PbmBatch",
    "SurrogateTraining",
    "CoupledLoop",
    "DesignSpace",
    "Calibration",
    "Factor",
    "Specification",
    "Sensitivity",
    "SobolFactor",
]
