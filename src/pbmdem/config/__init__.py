"""The settings layer of pbmdem: one validated, typed configuration for every path.

    from pbmdem.config import load_config
    cfg = load_config("config/config.yaml")        # a Config: frozen, typed, defaults filled
    cfg.granulator.tip_speed(600)                   # m/s
    cfg.dem_point("fine")                           # what one DEM run of feed 'fine' uses

Every setting is declared once, in the pydantic models of this package (type, default, bounds,
unit, description); `Config.from_mapping` checks a file once, fills in the defaults and builds the
typed objects. `pbmdem config --show-defaults` lists every setting, `--schema` prints the JSON
schema generated from the models, `--check FILE` checks a file. YAML files are read with duplicate
keys refused (`load_yaml`).
"""

from pathlib import Path

import yaml

from .dem import Dem, DemExecution
from .design import Calibration, DesignSpace, Factor, Sensitivity, SobolFactor, Specification
from .errors import ConfigError
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
from .settings import Config, ConfigFile, CoupledLoop, DemPoint, PbmBatch, SurrogateTraining, non_finite_values
from .surrogate import Surrogate
from .typed import RPM_MAX, Settings, check_rpm, setting
from .validation import FeedCheck, SampleRule, Sweep, Validation


class UniqueKeyLoader(yaml.SafeLoader):
    """YAML SafeLoader that rejects a key given twice in one mapping (PyYAML silently keeps the
    last one), naming the key and both lines."""

    def construct_mapping(self, node, deep=False):
        seen: dict = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                first = seen.get(key)
            except TypeError:  # unhashable key: let PyYAML report it
                continue
            line = key_node.start_mark.line + 1
            if first is not None:
                raise yaml.constructor.ConstructorError(
                    None,
                    None,
                    f"duplicate key {key!r} on line {line} (first given on line {first}); "
                    "each key may appear only once in a mapping",
                    key_node.start_mark,
                )
            seen[key] = line
        return super().construct_mapping(node, deep=deep)


def load_yaml(path: str | Path, what: str = "YAML file"):
    """Parse a YAML file with duplicate keys rejected; errors name the file (ConfigError)."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ConfigError(f"{what} {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{what} {path} cannot be read: {exc}") from None
    try:
        return yaml.load(text, Loader=UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        raise ConfigError(f"{what} {path} is not valid YAML: {exc}") from None


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
    "ConfigFile",
    "Settings",
    "setting",
    "non_finite_values",
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
