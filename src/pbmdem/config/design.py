"""Settings of what the fast model is for: the design space (`design_space:`), the parameter
estimation (`calibration:`) and the global sensitivity analysis (`sensitivity:`)."""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import Field

from .errors import ConfigError
from .typed import PbmKey, Rpm, Settings, Unique, setting

Positive = Annotated[float, Field(gt=0)]


class LiquidSpan(Settings):
    """`num` binder addition rates (m3/s) evenly from `start` to `stop`."""

    start: Positive = setting(..., "lowest binder rate", "m3/s")
    stop: Positive = setting(..., "highest binder rate", "m3/s")
    num: int = setting(7, "rates of the span", ge=2, le=200)

    def values(self) -> list[float]:
        if self.stop == self.start:
            return [float(self.start)]
        return [float(v) for v in np.linspace(self.start, self.stop, self.num)]


class Span(LiquidSpan):
    """`num` impeller speeds evenly from `start` to `stop` (null ends are resolved from the DEM
    grid); one value if start = stop (a grid of one speed)."""

    start: Rpm | None = setting(None, "lowest speed; null: the DEM grid's lowest", "rpm")
    stop: Rpm | None = setting(None, "highest speed; null: the DEM grid's highest", "rpm")


class Factor(Settings):
    """A numeric pbm setting (its config key) and the values it takes."""

    key: PbmKey = setting("pbm.process.wet_massing_time", "a numeric pbm setting (its config key)")
    values: Unique[Positive] = setting(
        (120.0, 240.0, 360.0), "its values; one map per value", min_length=1, max_length=20
    )


class Specification(Settings):
    """The product specification (m): d50 within [d50_min, d50_max], d90 at most d90_max (None: no bound)."""

    d50_min: float | None = setting(0.008, "lowest d50; null: no bound", "m", gt=0, le=1)
    d50_max: float | None = setting(0.0105, "highest d50; null: no bound", "m", gt=0, le=1)
    d90_max: float | None = setting(0.014, "highest d90; null: no bound", "m", gt=0, le=1)


class DesignSpace(Settings):
    """The PBM-ANN design space (docs/design.md): final d10/d50/d90 with the surrogate's
    uncertainty over impeller speed x binder rate x a third factor, and the region that meets a
    specification."""

    impeller_rpm: Span = setting(Span, "speeds: num evenly from start to stop")
    liquid_rate: LiquidSpan = setting(
        LiquidSpan(start=5.6e-8, stop=8.0e-8, num=7), "binder addition rates (the values of pbm.liquid_addition.rate)"
    )
    third_factor: Factor = setting(Factor, "the third factor: a numeric pbm setting and its values")
    specification: Specification = setting(Specification, "the product specification")
    n_jobs: int = setting(2, "processes running the batches (the results do not depend on it)", ge=1, le=256)


class Proof(Settings):
    """The check of the calibration on data of known parameters (rule calibration_check)."""

    time_step: float = setting(60.0, "time between the measured times taken from PBM-DEM and PBM-constant", "s", gt=0)
    start_factor: float = setting(1.5, "the fit starts from the true values times this factor", gt=0)
    noise: float = setting(0.03, "relative sd of the noise added to PBM-constant's output", gt=0, le=0.5)
    seed: int = setting(2026, "seed of the noise", ge=0)


class Calibration(Settings):
    """Parameter estimation with PBM-ANN from measured d10/d50/d90 over time (docs/calibration.md)."""

    parameters: Unique[PbmKey] = setting(
        ("pbm.aggregation.beta0", "pbm.aggregation.success.threshold"),
        "the PBM settings to estimate, config keys of positive numbers (estimated in ln)",
        min_length=1,
        max_length=10,
    )
    statistics: Unique[Literal["d10", "d50", "d90"]] = setting(
        ("d10", "d50", "d90"), "the size statistics of the measured table that enter the fit", min_length=1
    )
    relative_error_floor: float = setting(0.01, "the smallest measurement sd, a fraction of the value", gt=0, le=1)
    max_factor: float = setting(
        10.0, "each parameter is searched within [start / max_factor, start x max_factor]", gt=1, le=1000
    )
    confidence: float = setting(0.95, "confidence level of the intervals", gt=0, lt=1)
    identifiability_correlation: float = setting(
        0.95, "|correlation| of two estimates above which the data do not separate them (flagged)", gt=0, le=1
    )
    proof: Proof = setting(Proof, "the check on data of known parameters")


#: the name of the impeller speed among the factors of the sensitivity analysis
SPEED = "impeller_rpm"


class SpeedRange(Settings):
    """The impeller speed range (rpm) of the sensitivity analysis (null ends are resolved from the
    DEM grid); low = high: a fixed speed, not a factor."""

    low: Rpm | None = setting(None, "lowest speed; null: the DEM grid's lowest", "rpm")
    high: Rpm | None = setting(None, "highest speed; null: the DEM grid's highest", "rpm")


class SobolFactor(Settings):
    """A factor of the sensitivity analysis: `key` (a pbm config key, or `SPEED`) varied over
    [low, high], uniformly (`scale` linear) or uniformly in ln (log)."""

    key: str
    low: float
    high: float
    scale: Literal["linear", "log"] = "linear"


class SobolParameter(SobolFactor):
    """A pbm setting varied by the sensitivity analysis (an item of `sensitivity.parameters`)."""

    key: PbmKey = setting(..., "a pbm setting (its config key)")
    low: Positive = setting(..., "lowest value")
    high: Positive = setting(..., "highest value")
    scale: Literal["linear", "log"] = setting("linear", "sampled uniformly (linear) or uniformly in ln (log)")


class Sensitivity(Settings):
    """The global sensitivity analysis (docs/design.md, "Global sensitivity"): Sobol' indices of
    PBM-ANN's final d10/d50/d90 to impeller speed and to pbm settings."""

    impeller_rpm: SpeedRange = setting(SpeedRange, "the speed range, sampled uniformly; low = high: fixed")
    parameters: tuple[SobolParameter, ...] = setting(
        (
            SobolParameter(key="pbm.liquid_addition.rate", low=5.6e-8, high=8.0e-8, scale="linear"),
            SobolParameter(key="pbm.process.wet_massing_time", low=120.0, high=360.0, scale="linear"),
            SobolParameter(key="pbm.breakage.yield_strength", low=5.0e3, high=1.0e5, scale="log"),
            SobolParameter(key="pbm.aggregation.beta0", low=1.0e-4, high=4.0e-4, scale="log"),
        ),
        "the pbm settings varied, each over [low, high]",
        min_length=1,
        max_length=20,
    )
    base_samples: int = setting(
        128, "N of Saltelli's scheme (a power of 2): N (D + 2) batches for D factors", ge=2, le=65536
    )
    seed: int = setting(1, "seed of the scrambled Sobol' sequence and of the bootstrap", ge=1, le=1000000000)
    confidence: float = setting(0.95, "level of the confidence intervals of the indices", gt=0, lt=1)
    resamples: int = setting(1000, "bootstrap resamples of the confidence intervals", ge=10, le=100000)
    n_jobs: int = setting(2, "processes running the batches (the results do not depend on it)", ge=1, le=256)

    def factors(self) -> tuple[SobolFactor, ...]:
        """The factors in their order: the speed first (unless fixed), then `parameters`."""
        speed = self.impeller_rpm
        if speed.low == speed.high:
            return self.parameters
        return (SobolFactor(key=SPEED, low=float(speed.low), high=float(speed.high), scale="linear"), *self.parameters)


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
    keys += [(f"sensitivity.parameters[{k}].key", p.key) for k, p in enumerate(cfg.sensitivity.parameters)]
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
    s = cfg.sensitivity
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
    n = s.base_samples
    if n & (n - 1):
        out.append(
            f"sensitivity.base_samples = {n}: allowed: a power of 2 (2, 4, ..., 65536), the sizes at which the "
            "Sobol' sequence is balanced"
        )
    return out


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
        if not isinstance(obj, Settings) or name not in type(obj).model_fields:
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
    return obj.replace(**{head: new})
