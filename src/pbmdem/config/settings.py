"""The configuration file's model (`ConfigFile`), the checked `Config` with the defaults that depend
on other sections resolved (`Config.from_mapping`), and the stage bundles whose plain form is their
rule's params (docs/architecture.md, "Settings").
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from pydantic import ValidationError

from .checks import check
from .dem import Dem, DemExecution, DemSection
from .design import Calibration, DesignSpace, Sensitivity
from .errors import ConfigError, describe_errors
from .granulator import Bed, Granulator, GranulatorSection, Material
from .pbm import Pbm
from .points import OperatingGrid, SizeDistribution, point_id
from .surrogate import Surrogate
from .typed import Name, Settings, setting
from .validation import SampleRule, Validation


class ConfigFile(Settings):
    """The configuration file: SI units throughout (m, s, kg, Pa), impeller speed in rpm."""

    granulator: GranulatorSection = setting(..., "the granulator: bowl and impeller")
    material: Material = setting(..., "the granule material of the DEM")
    size_distributions: dict[Name, SizeDistribution] = setting(..., "named feed size distributions", min_length=1)
    dem: DemSection = setting(..., "the DEM runs: bed, phases, output, execution")
    grid: OperatingGrid = setting(..., "the DEM grid of operating points")
    pbm: Pbm = setting(Pbm, "population balance model of the batch high-shear wet granulator")
    surrogate: Surrogate = setting(Surrogate, "encounter surrogate trained on the DEM tables")
    validation: Validation = setting(..., "PBM-DEM vs PBM-ANN vs PBM-constant and the PBM-ANN speed sweep")
    design_space: DesignSpace = setting(DesignSpace, "the PBM-ANN design space (docs/design.md)")
    calibration: Calibration = setting(Calibration, "parameter estimation (docs/calibration.md)")
    sensitivity: Sensitivity = setting(Sensitivity, "global sensitivity analysis (docs/design.md)")


def parse(cfg: dict) -> ConfigFile:
    """The checked configuration file `cfg` (a parsed YAML mapping) with its defaults; ConfigError
    listing every problem otherwise. Types are checked as strictly as JSON: a number is not a
    string, an integer not a fraction, a boolean not a number."""
    if not isinstance(cfg, dict):
        raise ConfigError("the top level of a configuration must be a mapping of sections")
    try:  # NaN and infinities pass through JSON as NaN, Infinity: the models refuse them
        return ConfigFile.model_validate_json(json.dumps(cfg, default=repr), strict=True)
    except ValidationError as exc:
        raise ConfigError("invalid configuration:\n  " + "\n  ".join(describe_errors(exc, ConfigFile))) from None


@dataclass(frozen=True)
class PointSpeed:
    """What the impeller speed decides for one operating point (`DemPoint.at`)."""

    rpm: float
    point_id: str
    omega: float  # impeller angular speed (rad/s)
    tip_speed: float  # m/s
    rotation_period: float  # s
    spinup_time: float  # s, the spin-up phase
    sampling_time: float  # s, the sampling window


class DemPoint(Settings):
    """What one DEM run of an operating point uses: granulator, material, DEM settings and its size
    distribution (the rpm and the replicate are the run's wildcards)."""

    granulator: Granulator
    material: Material
    dem: Dem
    distribution: str
    sizes: SizeDistribution

    def at(self, rpm: float) -> PointSpeed:
        """Everything the impeller speed `rpm` decides for this point, each from its owner (the
        granulator, the DEM settings), in one call."""
        rpm = float(rpm)
        return PointSpeed(
            rpm=rpm,
            point_id=point_id(rpm, self.distribution),
            omega=float(self.granulator.angular_speed(rpm)),
            tip_speed=float(self.granulator.tip_speed(rpm)),
            rotation_period=60.0 / rpm,
            spinup_time=self.dem.phase_time("spinup", rpm),
            sampling_time=self.dem.phase_time("sampling", rpm),
        )


class PbmBatch(Settings):
    """What one PBM batch uses: the pbm settings, the bed's solid volume (m3, owned by the
    granulator) and the initial size distribution."""

    pbm: Pbm
    bed_solid_volume: float
    distribution: str
    sizes: SizeDistribution


class SurrogateTraining(Settings):
    """What training the surrogate uses: its settings and the granulator (tip speed feature)."""

    surrogate: Surrogate
    granulator: Granulator


class CoupledLoop(Settings):
    """What one speed's coupled loop (PBM-DEM, PBM-ANN, PBM-constant) uses."""

    batch: PbmBatch
    granulator: Granulator
    material: Material
    dem: Dem
    coupling_intervals: int
    dem_sampling_time: float
    sample: SampleRule

    def dem_point(self) -> DemPoint:
        """The DEM settings of the loop's calls: the minimum sampling window is
        validation.dem_sampling_time (dem.sampling_revolutions still applies); no contact dumps kept."""
        dem = self.dem.replace(sampling_time=self.dem_sampling_time, keep_contact_dumps=False)
        return DemPoint(
            granulator=self.granulator,
            material=self.material,
            dem=dem,
            distribution=self.batch.distribution,
            sizes=self.batch.sizes,
        )


@dataclass(frozen=True)
class Config:
    """The validated configuration (`Config.from_mapping`); every field is a frozen settings object."""

    granulator: Granulator
    material: Material
    size_distributions: dict[str, SizeDistribution]
    dem: Dem
    dem_replicates: int
    dem_execution: DemExecution
    grid: OperatingGrid
    pbm: Pbm
    surrogate: Surrogate
    validation: Validation
    design_space: DesignSpace
    calibration: Calibration
    sensitivity: Sensitivity
    mapping: dict  # the completed configuration mapping (defaults filled in), for provenance

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_mapping(cls, cfg: dict, source: str | Path | None = None) -> Config:
        """Check `cfg` (a parsed config file), fill in the defaults and build the Config;
        ConfigError listing every problem (prefixed with the file, if `source` is given)."""
        try:
            config = cls._build(parse(cfg))
            check(config)
        except ConfigError as exc:
            if source is None:
                raise
            raise ConfigError(f"config file {source}: {exc}") from None
        return config

    @classmethod
    def _build(cls, f: ConfigFile) -> Config:
        dem, grid, dists = f.dem, f.grid, f.size_distributions
        bed = Bed(height=dem.bed_height, packing_fraction=dem.packing_fraction)
        granulator = Granulator(**dict(f.granulator), bed=bed)
        # defaults that depend on other sections: the PBM grid's first pivot is the smallest feed
        # class; the feed check's speed is the feed study's, the grid's middle speed; null ends of
        # the PBM-ANN sweep, the design space and the sensitivity analysis are the grid's speeds
        pbm = f.pbm
        if pbm.grid.min_diameter is None:
            pbm = pbm.replace(grid=pbm.grid.replace(min_diameter=min(min(d.diameters) for d in dists.values())))
        low, high = min(grid.impeller_rpm), max(grid.impeller_rpm)
        val = f.validation
        sweep = val.sweep.replace(start=_or(val.sweep.start, low), stop=_or(val.sweep.stop, high))
        check = val.feed_check.replace(rpm=_or(val.feed_check.rpm, grid.middle_speed()))
        speeds = f.design_space.impeller_rpm
        speeds = speeds.replace(start=_or(speeds.start, low), stop=_or(speeds.stop, high))
        sens = f.sensitivity.impeller_rpm
        sens = sens.replace(low=_or(sens.low, low), high=_or(sens.high, high))
        return cls(
            granulator=granulator,
            material=f.material,
            size_distributions=dict(dists),
            dem=Dem(**{k: getattr(dem, k) for k in Dem.model_fields}),
            dem_replicates=dem.replicates,
            dem_execution=DemExecution(**{k: getattr(dem, k) for k in DemExecution.model_fields}),
            grid=grid,
            pbm=pbm,
            surrogate=f.surrogate,
            validation=val.replace(sweep=sweep, feed_check=check),
            design_space=f.design_space.replace(impeller_rpm=speeds),
            calibration=f.calibration,
            sensitivity=f.sensitivity.replace(impeller_rpm=sens),
            mapping=f.to_dict(),
        )

    # ------------------------------------------------------------------ stage settings
    def point_replicates(self, distribution: str) -> int:
        """DEM runs (insertion seeds) per operating point of `distribution`."""
        return self.grid.replicates(distribution, self.dem_replicates)

    def distribution(self, name: str) -> SizeDistribution:
        if name not in self.size_distributions:
            raise ConfigError(
                f"size distribution {name!r} is not defined; defined names: {sorted(self.size_distributions)}"
            )
        return self.size_distributions[name]

    def dem_point(self, distribution: str) -> DemPoint:
        return DemPoint(
            granulator=self.granulator,
            material=self.material,
            dem=self.dem,
            distribution=distribution,
            sizes=self.distribution(distribution),
        )

    def pbm_batch(self, distribution: str) -> PbmBatch:
        return PbmBatch(
            pbm=self.pbm,
            bed_solid_volume=self.granulator.bed_solid_volume,
            distribution=distribution,
            sizes=self.distribution(distribution),
        )

    def surrogate_training(self) -> SurrogateTraining:
        return SurrogateTraining(surrogate=self.surrogate, granulator=self.granulator)

    def coupled_loop(self) -> CoupledLoop:
        v = self.validation
        return CoupledLoop(
            batch=self.pbm_batch(v.distribution),
            granulator=self.granulator,
            material=self.material,
            dem=self.dem,
            coupling_intervals=v.coupling_intervals,
            dem_sampling_time=v.dem_sampling_time,
            sample=SampleRule(
                max_classes=v.max_classes,
                min_particles_per_class=v.min_particles_per_class,
                max_particles=self.dem.max_particles,
            ),
        )

    # ------------------------------------------------------------------ provenance
    def to_dict(self) -> dict:
        """The completed configuration mapping (every default filled in), keys sorted at every level
        (so a rule's params do not depend on the order of the keys in the file)."""
        return json.loads(json.dumps(self.mapping, sort_keys=True))

    def sha256(self) -> str:
        """Hash of the completed configuration (:func:`sha256_of`)."""
        return sha256_of(self.to_dict())


def sha256_of(mapping: dict) -> str:
    """sha256 of a configuration mapping, key order and formatting ignored."""
    return hashlib.sha256(json.dumps(mapping, sort_keys=True).encode()).hexdigest()


def _or(value, default):
    """`value`, or `default` where the config says null."""
    return default if value is None else float(value)
