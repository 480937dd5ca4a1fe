"""The settings layer: one validated, typed configuration; each setting declared once (its
model's field); each stage handed exactly the settings it uses."""

from __future__ import annotations

import copy
import json

import pytest
from conftest import config_of
from pydantic import ValidationError

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
)
from pbmdem.config.dem import DemSection
from pbmdem.config.validation import Validation


def test_a_minimal_config_is_completed_with_the_model_defaults(tiny_config):
    required = {k: v for k, v in tiny_config.to_dict().items() if k not in ("pbm", "surrogate")}
    required["dem"] = {
        k: required["dem"][k]
        for k in ("bed_height", "packing_fraction", "timestep_fraction", "settle_time", "spinup_time", "sampling_time")
    }
    required["validation"] = {"rpm": [600], "distribution": "small"}
    cfg = Config.from_mapping(required)
    dem_fields = DemSection.model_fields
    assert cfg.dem.seed == dem_fields["seed"].default
    assert cfg.dem_execution.timeout == dem_fields["timeout"].default
    assert cfg.dem_replicates == dem_fields["replicates"].default
    assert cfg.pbm == Pbm.from_dict({}, "pbm").replace(
        grid=Pbm.from_dict({}, "pbm").grid.replace(
            min_diameter=min(min(d.diameters) for d in cfg.size_distributions.values())
        )
    )
    assert cfg.validation.coupling_intervals == Validation.model_fields["coupling_intervals"].default
    # the derived defaults: the sweep spans the grid's speeds, the PBM grid starts at the smallest feed class
    assert (cfg.validation.sweep.start, cfg.validation.sweep.stop) == (
        min(cfg.grid.impeller_rpm),
        max(cfg.grid.impeller_rpm),
    )
    assert cfg.pbm.grid.min_diameter == 0.002
    # the completed mapping is what Snakemake's config holds too
    assert cfg.to_dict()["dem"]["timeout"] == dem_fields["timeout"].default


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
        with pytest.raises(ValidationError, match="frozen"):
            bundle.granulator = None if hasattr(bundle, "granulator") else bundle.pbm
    assert default_config.granulator.bed_solid_volume == pytest.approx(0.018 * 3.14159265 / 4 * 0.06**2 * 0.6)
    assert default_config.granulator.tip_speed(600) == pytest.approx(2 * 3.14159265 * 0.0265 * 10)
    assert default_config.granulator.froude_number(1200) == pytest.approx(42.67, rel=1e-3)


def test_every_setting_carries_a_description_and_its_default():
    """Each setting is declared once, as a field of its section's model with a description; the
    defaults are those fields' (`Solver()` is the model's)."""
    from pbmdem.config import ConfigFile, Settings

    seen, todo = set(), [ConfigFile]
    while todo:
        model = todo.pop()
        if model in seen:
            continue
        seen.add(model)
        for name, field in model.model_fields.items():
            assert field.description, (model.__name__, name)
            for sub in getattr(field.annotation, "__args__", ()) + (field.annotation,):
                if isinstance(sub, type) and issubclass(sub, Settings):
                    todo.append(sub)
    assert len(seen) >= 30
    assert Solver() == Pbm().solver and Solver().rtol == Solver.model_fields["rtol"].default


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


def test_the_completed_mapping_does_not_depend_on_the_order_of_keys(tiny_mapping):
    """The params of a rule holding the mapping stay the same when a file lists its keys in
    another order (yaml.safe_dump sorts them, for one)."""
    reordered = dict(reversed(list(tiny_mapping.items())))
    reordered["size_distributions"] = dict(reversed(list(tiny_mapping["size_distributions"].items())))
    a, b = config_of(tiny_mapping).to_dict(), config_of(reordered).to_dict()
    assert list(a["size_distributions"]) == list(b["size_distributions"]) and list(a) == list(b)
    assert json.dumps(a) == json.dumps(b)
