"""The whole configuration as one frozen, typed object, and the settings each stage uses.

`Config.from_mapping(cfg)` validates a configuration against the schema once, fills in the
schema's defaults, resolves the defaults that depend on other sections (the PBM grid's first
pivot, the sweep's speed range), makes the checks a schema cannot express, and returns a
`Config`. Every path goes through it: the Snakefile, the `pbmdem` command line, the library's
entry points and the tests.

A stage is handed only the settings it uses, as one of the bundles below (`DemPoint`,
`PbmBatch`, `SurrogateTraining`, `CoupledLoop`). A bundle's plain form (`to_dict()`) is also the
params of the stage's Snakemake rule, so a rule reruns exactly when something its stage uses
changes, and the rule script rebuilds the bundle from its params (`from_dict`).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from .dem import BED_KEYS, EXECUTION_KEYS, REPLICATES_KEY, Dem, DemExecution
from .design import Calibration, DesignSpace, Sensitivity
from .errors import ConfigError
from .granulator import Bed, Bowl, Granulator, Impeller, Material
from .pbm import Pbm
from .points import OperatingGrid, SizeDistribution
from .surrogate import Surrogate
from .typed import Settings, plain
from .validation import SampleRule, Validation


@dataclass(frozen=True)
class DemPoint(Settings):
    """What one DEM run of an operating point uses: granulator, material, DEM settings and its size
    distribution (the rpm and the replicate are the run's wildcards)."""

    granulator: Granulator
    material: Material
    dem: Dem
    distribution: str
    sizes: SizeDistribution


@dataclass(frozen=True)
class PbmBatch(Settings):
    """What one PBM batch uses: the pbm settings, the bed's solid volume (m3, owned by the
    granulator) and the initial size distribution."""

    pbm: Pbm
    bed_solid_volume: float
    distribution: str
    sizes: SizeDistribution


@dataclass(frozen=True)
class SurrogateTraining(Settings):
    """What training the surrogate uses: its settings and the granulator (tip speed feature)."""

    surrogate: Surrogate
    granulator: Granulator


@dataclass(frozen=True)
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
        return DemPoint(self.granulator, self.material, dem, self.batch.distribution, self.batch.sizes)


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
        """Validate `cfg` (a parsed config file), fill in the defaults and build the Config;
        ConfigError listing every problem (prefixed with the file, if `source` is given)."""
        from .checks import check
        from .schema import complete

        try:
            full = complete(cfg)
            config = cls._build(full)
            check(config)
        except ConfigError as exc:
            if source is None:
                raise
            raise ConfigError(f"config file {source}: {exc}") from None
        return config

    @classmethod
    def _build(cls, full: dict) -> Config:
        dists = {
            name: SizeDistribution.from_dict(d, f"size_distributions.{name}")
            for name, d in full["size_distributions"].items()
        }
        dem_section = full["dem"]
        bed = Bed(height=float(dem_section["bed_height"]), packing_fraction=float(dem_section["packing_fraction"]))
        g = full["granulator"]
        granulator = Granulator(
            Bowl.from_dict(g["bowl"], "granulator.bowl"), Impeller.from_dict(g["impeller"], "granulator.impeller"), bed
        )
        run_keys = {k: v for k, v in dem_section.items() if k not in (*BED_KEYS, *EXECUTION_KEYS, REPLICATES_KEY)}
        grid = OperatingGrid.from_dict(full["grid"], "grid")
        # defaults that depend on other sections
        pbm_section = json.loads(json.dumps(full["pbm"]))
        if pbm_section["grid"]["min_diameter"] is None:
            pbm_section["grid"]["min_diameter"] = min(min(d.diameters) for d in dists.values())
        val_section = json.loads(json.dumps(full["validation"]))
        design = json.loads(json.dumps(full["design_space"]))
        # the feed check's speed: null is the feed study's, the grid's middle speed
        if val_section["feed_check"]["rpm"] is None:
            val_section["feed_check"]["rpm"] = grid.middle_speed()
        sensitivity = json.loads(json.dumps(full["sensitivity"]))
        # the speed ranges of the PBM-ANN sweep, the design space and the sensitivity analysis:
        # null ends are the grid's
        for span, (low, high) in (
            (val_section["sweep"], ("start", "stop")),
            (design["impeller_rpm"], ("start", "stop")),
            (sensitivity["impeller_rpm"], ("low", "high")),
        ):
            if span[low] is None:
                span[low] = min(grid.impeller_rpm)
            if span[high] is None:
                span[high] = max(grid.impeller_rpm)
        return cls(
            granulator=granulator,
            material=Material.from_dict(full["material"], "material"),
            size_distributions=dists,
            dem=Dem.from_dict(run_keys, "dem"),
            dem_replicates=int(dem_section[REPLICATES_KEY]),
            dem_execution=DemExecution.from_dict({k: dem_section[k] for k in EXECUTION_KEYS}, "dem"),
            grid=grid,
            pbm=Pbm.from_dict(pbm_section, "pbm"),
            surrogate=Surrogate.from_dict(full["surrogate"], "surrogate"),
            validation=Validation.from_dict(val_section, "validation"),
            design_space=DesignSpace.from_dict(design, "design_space"),
            calibration=Calibration.from_dict(full["calibration"], "calibration"),
            sensitivity=Sensitivity.from_dict(sensitivity, "sensitivity"),
            mapping=full,
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
        return DemPoint(self.granulator, self.material, self.dem, distribution, self.distribution(distribution))

    def pbm_batch(self, distribution: str) -> PbmBatch:
        return PbmBatch(self.pbm, self.granulator.bed_solid_volume, distribution, self.distribution(distribution))

    def surrogate_training(self) -> SurrogateTraining:
        return SurrogateTraining(self.surrogate, self.granulator)

    def sample_rule(self) -> SampleRule:
        return SampleRule(self.validation.max_classes, self.validation.min_particles_per_class, self.dem.max_particles)

    def coupled_loop(self) -> CoupledLoop:
        v = self.validation
        return CoupledLoop(
            self.pbm_batch(v.distribution),
            self.granulator,
            self.material,
            self.dem,
            v.coupling_intervals,
            v.dem_sampling_time,
            self.sample_rule(),
        )

    # ------------------------------------------------------------------ provenance
    def to_dict(self) -> dict:
        """The completed configuration mapping (every default filled in)."""
        return plain(self.mapping)

    def sha256(self) -> str:
        """Hash of the completed configuration (key order and formatting do not matter)."""
        return hashlib.sha256(json.dumps(self.to_dict(), sort_keys=True).encode()).hexdigest()
