"""The settings layer: one validated, typed configuration; defaults only in the schema; each
stage handed exactly the settings it uses."""

from __future__ import annotations

import copy
import dataclasses

import pytest
import yaml
from conftest import config_of

from pbmdem.config import (
    Config,
    ConfigError,
    CoupledLoop,
    DemPoint,
    Pbm,
    PbmBatch,
    Solver,
    SurrogateTraining,
    load_config,
    schema_dir,
    section_defaults,
)


def test_a_minimal_config_is_completed_with_the_schema_defaults(tiny_config):
    required = {k: v for k, v in tiny_config.to_dict().items() if k not in ("pbm", "surrogate")}
    required["dem"] = {
        k: required["dem"][k]
        for k in ("bed_height", "packing_fraction", "timestep_fraction", "settle_time", "spinup_time", "sampling_time")
    }
    required["validation"] = {"rpm": [600], "distribution": "small"}
    cfg = Config.from_mapping(required)
    schema = yaml.safe_load((schema_dir() / "config.schema.yaml").read_text())
    dem_schema = schema["properties"]["dem"]["properties"]
    assert cfg.dem.seed == dem_schema["seed"]["default"]
    assert cfg.dem_execution.timeout == dem_schema["timeout"]["default"]
    assert cfg.dem_replicates == dem_schema["replicates"]["default"]
    assert cfg.pbm == Pbm.from_section({}).replace(
        grid=Pbm.from_section({}).grid.replace(
            min_diameter=min(min(d.diameters) for d in cfg.size_distributions.values())
        )
    )
    validation_schema = yaml.safe_load((schema_dir() / "validation.schema.yaml").read_text())
    assert cfg.validation.coupling_intervals == validation_schema["properties"]["coupling_intervals"]["default"]
    # the derived defaults: the sweep spans the grid's speeds, the PBM grid starts at the smallest feed class
    assert (cfg.validation.sweep.start, cfg.validation.sweep.stop) == (
        min(cfg.grid.impeller_rpm),
        max(cfg.grid.impeller_rpm),
    )
    assert cfg.pbm.grid.min_diameter == 0.002
    # the completed mapping is what Snakemake's config holds too
    assert cfg.to_dict()["dem"]["timeout"] == dem_schema["timeout"]["default"]


def test_the_cli_and_the_workflow_see_the_same_execution_settings(root):
    """The same completed values on every path (they differed when only Snakemake filled defaults)."""
    cfg = load_config(root / "config" / "test.yaml")
    from pbmdem.config import DemExecution

    assert DemExecution.of_job(cfg.to_dict()) == cfg.dem_execution
    assert DemExecution.of_job(cfg.to_dict(), {"tasks": 4}).mpi_ranks == 4


def test_settings_objects_are_frozen_and_round_trip(default_config):
    for bundle, cls in (
        (default_config.dem_point("fine"), DemPoint),
        (default_config.pbm_batch("coarse"), PbmBatch),
        (default_config.surrogate_training(), SurrogateTraining),
        (default_config.coupled_loop(), CoupledLoop),
    ):
        assert cls.from_dict(bundle.to_dict()) == bundle
        with pytest.raises(dataclasses.FrozenInstanceError):
            bundle.granulator = None if hasattr(bundle, "granulator") else bundle.pbm
    assert default_config.granulator.bed_solid_volume == pytest.approx(0.018 * 3.14159265 / 4 * 0.06**2 * 0.6)
    assert default_config.granulator.tip_speed(600) == pytest.approx(2 * 3.14159265 * 0.0265 * 10)
    assert default_config.granulator.froude_number(1200) == pytest.approx(42.67, rel=1e-3)


def test_no_settings_class_has_defaults():
    """Defaults live in the schema only (`Solver.defaults()` reads them from there)."""
    from pbmdem.config import dem, granulator, pbm, points, settings, surrogate, validation

    for module in (dem, granulator, pbm, points, settings, surrogate, validation):
        for obj in vars(module).values():
            if dataclasses.is_dataclass(obj) and obj.__module__ == module.__name__:
                for f in dataclasses.fields(obj):
                    assert f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING, (
                        obj.__name__,
                        f.name,
                    )
    assert Solver.defaults().to_dict() == section_defaults("pbm")["solver"]


def test_each_stage_fingerprint_holds_only_what_it_uses(tiny_config, tiny_mapping):
    base = {
        "point": tiny_config.dem_point("small").to_dict(),
        "batch": tiny_config.pbm_batch("small").to_dict(),
        "loop": tiny_config.coupled_loop().to_dict(),
        "training": tiny_config.surrogate_training().to_dict(),
    }

    def changed(edit) -> set[str]:
        mapping = copy.deepcopy(tiny_mapping)
        edit(mapping)
        cfg = config_of(mapping)
        now = {
            "point": cfg.dem_point("small").to_dict(),
            "batch": cfg.pbm_batch("small").to_dict(),
            "loop": cfg.coupled_loop().to_dict(),
            "training": cfg.surrogate_training().to_dict(),
        }
        return {k for k in base if base[k] != now[k]}

    assert changed(lambda m: m["dem"].update(timeout=5.0, mpi_ranks=3)) == set()
    assert changed(lambda m: m["dem"].update(replicates=7)) == set()
    assert changed(lambda m: m["validation"].update(rpm=[700])) == set()
    assert changed(lambda m: m["validation"]["sweep"].update(num=9)) == set()
    assert changed(lambda m: m["dem"].update(seed=30011)) == {"point", "loop"}
    assert changed(lambda m: m["pbm"]["aggregation"].update(beta0=1e-3)) == {"batch", "loop"}
    assert changed(lambda m: m["surrogate"].update(max_iter=50)) == {"training"}
    assert changed(lambda m: m["dem"].update(bed_height=0.009)) == {"point", "batch", "loop", "training"}
    assert changed(lambda m: m["validation"].update(coupling_intervals=3)) == {"loop"}


def test_errors_name_the_key_the_value_and_what_is_allowed(tiny_mapping):
    tiny_mapping["pbm"]["solver"]["rtol"] = 2.0
    tiny_mapping["surrogate"]["seeds"] = [1]
    tiny_mapping["validation"]["distribution"] = "huge"
    with pytest.raises(ConfigError) as info:
        config_of(tiny_mapping)
    msg = str(info.value)
    assert "pbm.solver.rtol = 2.0" in msg and "<= 1" in msg
    with pytest.raises(ConfigError) as info:
        tiny_mapping["pbm"]["solver"]["rtol"] = 1e-3
        config_of(tiny_mapping)
    msg = str(info.value)
    assert "surrogate.seeds = [1]" in msg and "validation.distribution: 'huge' is not defined" in msg
