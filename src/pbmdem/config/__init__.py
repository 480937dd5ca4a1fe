"""The settings layer: one checked, typed, frozen configuration for every path (docs/architecture.md,
"Settings"); `load_config(path)` reads a file, `pbmdem config` lists, prints or checks the settings.
"""

from pathlib import Path

import yaml

from .dem import DemExecution
from .design import Calibration, DesignSpace, Sensitivity, SobolFactor, Specification
from .errors import ConfigError
from .granulator import Bowl, Granulator, Impeller
from .pbm import Pbm, Solver
from .points import BLEND_JOIN, OperatingGrid, SizeDistribution, feed_case_names, feed_case_parents, point_id, rpm_text
from .settings import Config, ConfigFile, CoupledLoop, DemPoint, PbmBatch, SurrogateTraining
from .surrogate import Surrogate
from .typed import RPM_MAX, Settings, check_rpm
from .validation import SampleRule, Sweep


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
    return Config.from_mapping(load_yaml(path, "config file"), source=path)


__all__ = [
    "Config",
    "ConfigError",
    "load_config",
    "load_yaml",
    "check_rpm",
    "RPM_MAX",
    "ConfigFile",
    "Settings",
    "Granulator",
    "Bowl",
    "Impeller",
    "SizeDistribution",
    "OperatingGrid",
    "point_id",
    "feed_case_names",
    "feed_case_parents",
    "BLEND_JOIN",
    "rpm_text",
    "DemExecution",
    "Pbm",
    "Solver",
    "Surrogate",
    "Sweep",
    "SampleRule",
    "DemPoint",
    "PbmBatch",
    "SurrogateTraining",
    "CoupledLoop",
    "DesignSpace",
    "Calibration",
    "Specification",
    "Sensitivity",
    "SobolFactor",
]
