"""Settings of what the fast model is for: the design space (`design_space:`), the parameter
estimation (`calibration:`) and the global sensitivity analysis (`sensitivity:`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .errors import ConfigError
from .typed import Settings


@dataclass(frozen=True)
class Span(Settings):
    """`num` values evenly from `start` to `stop` (null ends are resolved from the DEM grid); one
    value if start = stop (a grid of one speed)."""

    start: float | None
    stop: float | None
    num: int

    def values(self) -> list[float]:
        import numpy as np

        if self.stop == self.start:
            return [float(self.start)]
        return [float(v) for v in np.linspace(self.start, self.stop, self.num)]


@dataclass(frozen=True)
class Factor(Settings):
    """A numeric pbm setting (its config key) and the values it takes."""

    key: str
    values: tuple[float, ...]


@dataclass(frozen=True)
class Specification(Settings):
    """The product specification (m): d50 within [d50_min, d50_max], d90 at most d90_max (None: no bound)."""

    d50_min: float | None
    d50_max: float | None
    d90_max: float | None


@dataclass(frozen=True)
class DesignSpace(Settings):
    """Impeller speed x binder rate x a third factor, the specification, and the processes."""

    impeller_rpm: Span
    liquid_rate: Span
    third_factor: Factor
    specification: Specification
    n_jobs: int


@dataclass(frozen=True)
class Proof(Settings):
    """The check of the calibration on data of known parameters."""

    time_step: float
    start_factor: float
    noise: float
    seed: int


@dataclass(frozen=True)
class Calibration(Settings):
    """Which pbm settings to estimate, from which statistics, and how to judge the estimates."""

    parameters: tuple[str, ...]
    statistics: tuple[str, ...]
    relative_error_floor: float
    max_factor: float
    confidence: float
    identifiability_correlation: float
    proof: Proof


#: the name of the impeller speed among the factors of the sensitivity analysis
SPEED = "impeller_rpm"


@dataclass(frozen=True)
class SpeedRange(Settings):
    """The impeller speed range (rpm) of the sensitivity analysis (null ends are resolved from the
    DEM grid); low = high: a fixed speed, not a factor."""

    low: float | None
    high: float | None


@dataclass(frozen=True)
class SobolFactor(Settings):
    """A factor of the sensitivity analysis: `key` (a pbm config key, or `SPEED`) varied over
    [low, high], uniformly (`scale` linear) or uniformly in ln (log)."""

    key: str
    low: float
    high: float
    scale: str


@dataclass(frozen=True)
class Sensitivity(Settings):
    """The global sensitivity analysis: the factors and their ranges, Saltelli's base sample N,
    the seed, the confidence level and bootstrap resamples of the intervals, the processes."""

    impeller_rpm: SpeedRange
    parameters: tuple[SobolFactor, ...]
    base_samples: int
    seed: int
    confidence: float
    resamples: int
    n_jobs: int

    def factors(self) -> tuple[SobolFactor, ...]:
        """The factors in their order: the speed first (unless fixed), then `parameters`."""
        speed = self.impeller_rpm
        if speed.low == speed.high:
            return self.parameters
        return (SobolFactor(SPEED, float(speed.low), float(speed.high), "linear"), *self.parameters)


def _sensitivity_problems(s: Sensitivity, pbm) -> list[str]:
    out = []
    if s.impeller_rpm.high < s.impeller_rpm.low:
        out.append(
            f"sensitivity.impeller_rpm: high = {s.impeller_rpm.high:g} must not be below low = "
            f"{s.impeller_rpm.low:g} (equal: a fixed speed)"
        )
    seen = set()
    for k, p in enumerate(s.parameters):
        where = f"sensitivity.parameters[{k}]"
        if not p.high > p.low:
            out.append(f"{where} ({p.key}): high = {p.high:g} must exceed low = {p.low:g}")
        if p.key in seen:
            out.append(f"{where}.key = {p.key!r}: named twice; allowed: each pbm setting once")
        seen.add(p.key)
        try:
            pbm_value(pbm, p.key)
        except ConfigError as exc:
            out.append(f"{where}.key: {exc}")
    n = s.base_samples
    if n & (n - 1):
        out.append(
            f"sensitivity.base_samples = {n}: allowed: a power of 2 (2, 4, ..., 65536), the sizes at which the "
            "Sobol' sequence is balanced"
        )
    return out


def problems(cfg) -> list[str]:
    """What the schema cannot check of `design_space`, `calibration` and `sensitivity`: ascending
    ranges, parameter keys that name positive pbm numbers, a specification that can be met, a
    base sample that is a power of 2."""
    out: list[str] = []
    ds = cfg.design_space
    for name, span in (("impeller_rpm", ds.impeller_rpm), ("liquid_rate", ds.liquid_rate)):
        if span.stop < span.start:
            out.append(f"design_space.{name}: stop = {span.stop:g} must not be below start = {span.start:g}")
    keys = [("design_space.third_factor.key", ds.third_factor.key)]
    keys += [(f"calibration.parameters[{k}]", key) for k, key in enumerate(cfg.calibration.parameters)]
    for where, key in keys:
        try:
            pbm_value(cfg.pbm, key)
        except ConfigError as exc:
            out.append(f"{where}: {exc}")
    if ds.third_factor.key in ("pbm.liquid_addition.rate",):
        out.append("design_space.third_factor.key = 'pbm.liquid_addition.rate' is already the second factor")
    spec = ds.specification
    if spec.d50_min is not None and spec.d50_max is not None and not spec.d50_max > spec.d50_min:
        out.append(f"design_space.specification: d50_max = {spec.d50_max:g} must exceed d50_min = {spec.d50_min:g}")
    return out + _sensitivity_problems(cfg.sensitivity, cfg.pbm)


def _path(key: str) -> list[str]:
    parts = key.split(".")
    if len(parts) < 2 or parts[0] != "pbm":
        raise ConfigError(f"config key {key!r}: allowed: a key of the pbm section, e.g. pbm.aggregation.beta0")
    return parts[1:]


def pbm_value(pbm, key: str) -> float:
    """The value of the numeric pbm setting `key` (a config key such as pbm.aggregation.beta0) in
    the settings `pbm`; ConfigError naming the key if it is not a positive number there."""
    obj = pbm
    for name in _path(key):
        if not dataclasses.is_dataclass(obj) or name not in {f.name for f in dataclasses.fields(obj)}:
            raise ConfigError(f"config key {key!r}: {name!r} is not a pbm setting; allowed: a numeric key of pbm")
        obj = getattr(obj, name)
    if isinstance(obj, bool) or not isinstance(obj, (int, float)) or not obj > 0:
        raise ConfigError(f"config key {key!r} = {obj!r}: allowed: a key of a positive number (it is estimated in ln)")
    return float(obj)


def with_pbm_values(pbm, values: dict[str, float]):
    """`pbm` with the numeric settings of `values` (config key -> value) replaced."""
    for key, value in values.items():
        pbm_value(pbm, key)  # the key names a positive number
        pbm = _replaced(pbm, _path(key), value)
    return pbm


def _replaced(obj, names: list[str], value):
    head, *rest = names
    current = getattr(obj, head)
    new = _replaced(current, rest, value) if rest else type(current)(value)
    return dataclasses.replace(obj, **{head: new})
