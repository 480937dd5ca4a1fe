"""The ``pbm:`` config section: defaults, validation, model construction, ``run_pbm``.

Defaults equal the pbm: section of config/config.yaml (a test keeps them equal); the schema is
workflow/schemas/pbm.schema.yaml. The initial population is a named size distribution of the
config (diameters = solid-equivalent diameters, number fractions) scaled to the solid volume of
the DEM bed: bed_height x pi/4 bowl_diameter^2 x packing_fraction.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np

from .errors import PBMInputError
from .grid import Grid, volume_of
from .kernels import CollisionKernel, ConstantFrequency, SuccessProbability
from .model import GranulationPBM, SolverSettings, State
from .processes import Consolidation, LiquidAddition
from .success import StokesCriterion

_REPO = Path(__file__).resolve().parents[3]
SCHEMA_PATH = _REPO / "workflow" / "schemas" / "pbm.schema.yaml"
DEFAULTS_PATH = _REPO / "config" / "config.yaml"  # its pbm: section holds the defaults

#: Same values as the pbm: section of config/config.yaml (a test keeps them equal).
DEFAULTS: dict = {
    "grid": {"ratio": 1.2599210498948732, "min_diameter": None, "max_diameter": 0.032, "bins": None,
             "separate_feed": True},
    "process": {"premixing_time": 60.0, "liquid_addition_time": 180.0, "wet_massing_time": 240.0},
    "initial": {"porosity": 0.5, "liquid_content": 0.0},
    "liquid_addition": {"rate": 5.8e-8, "distribution": "surface_area"},
    "consolidation": {"rate": 0.02, "min_porosity": 0.2},
    "aggregation": {
        "scheme": "cell_average",
        "beta0": 2.0e-4,
        "constant_frequency": 0.12,
        "constant_impact_velocity": None,
        "frequency_update_interval": 1.0,
        "table_extrapolation": "clamp",
        "success": {"model": "step", "threshold": 0.02, "width": 0.005, "velocity_model": "none",
                    "stokes": {"binder_viscosity": 0.1, "restitution": 0.4, "asperity_height": 5.0e-6,
                               "granule_density": 1000.0}},
    },
    "solver": {"method": "ssp3", "safety": 0.5, "rtol": 1.0e-3, "atol": 1.0e-6, "max_step": 10.0,
               "max_overflow_fraction": 1.0e-6, "max_steps": 1000000, "max_wall_time": 3600.0},
    "output": {"interval": 10.0},
}


@functools.lru_cache(maxsize=1)
def _validator():
    import jsonschema
    import yaml

    return jsonschema.Draft202012Validator(yaml.safe_load(SCHEMA_PATH.read_text()))


def validate_section(section: dict) -> None:
    errors = sorted(_validator().iter_errors(section),
                    key=lambda e: list(map(str, e.absolute_path)))
    if errors:
        msgs = []
        for e in errors:
            key = "pbm." + ".".join(map(str, e.absolute_path)) if e.absolute_path else "pbm"
            msgs.append(f"{key} = {e.instance!r}: {e.message}")
        raise PBMInputError("invalid pbm configuration: " + "; ".join(msgs))


def resolve_settings(config: dict | None = None) -> dict:
    """Complete, validated ``pbm:`` settings: the config's ``pbm`` section over :data:`DEFAULTS`."""
    from pbmdem.config import merge_defaults

    section = (config or {}).get("pbm") or {}
    if not isinstance(section, dict):
        raise PBMInputError(f"pbm section must be a mapping, got {type(section).__name__}")
    merged = merge_defaults(DEFAULTS, section)
    validate_section(merged)
    g = merged["grid"]
    if g["min_diameter"] is None:
        # the first pivot is the smallest feed class of the config's size distributions
        dists = (config or {}).get("size_distributions") or {}
        smallest = [min(float(d) for d in v["diameters"]) for v in dists.values()
                    if isinstance(v, dict) and v.get("diameters")]
        if smallest:
            g["min_diameter"] = min(smallest)
    return merged


def bed_solid_volume(config: dict) -> float:
    """Solid volume of the DEM bed: bed_height x pi/4 bowl_diameter^2 x packing_fraction (m3)."""
    dem, bowl = config["dem"], config["granulator"]["bowl"]
    return float(dem["bed_height"]) * math.pi / 4 * float(bowl["diameter"]) ** 2 * float(dem["packing_fraction"])


def process_times(settings: dict) -> tuple[float, float, float]:
    """(spray start, spray end, end of process) from the phase durations."""
    p = settings["process"]
    t0 = float(p["premixing_time"])
    t1 = t0 + float(p["liquid_addition_time"])
    return t0, t1, t1 + float(p["wet_massing_time"])


def build_success(succ: dict) -> SuccessProbability:
    """SuccessProbability of a resolved ``pbm.aggregation.success`` section: the surface-liquid
    condition, times the Stokes criterion if ``velocity_model: stokes``."""
    velocity = None
    if succ["velocity_model"] == "stokes":
        st = succ["stokes"]
        velocity = StokesCriterion(st["binder_viscosity"], st["restitution"], st["asperity_height"],
                                   st["granule_density"])
    elif succ["velocity_model"] != "none":
        raise PBMInputError(f"pbm.aggregation.success.velocity_model = {succ['velocity_model']!r}; "
                            "allowed: 'none', 'stokes'")
    return SuccessProbability(succ["model"], succ["threshold"], succ["width"], velocity=velocity)


def velocity_resolved(settings: dict) -> bool:
    """True if the resolved settings' success probability needs impact velocities."""
    return settings["aggregation"]["success"]["velocity_model"] != "none"


def build_model(settings: dict, source=None, rpm: float = 0.0) -> GranulationPBM:
    """GranulationPBM from resolved settings; ``source`` defaults to ConstantFrequency."""
    g = settings["grid"]
    if g["min_diameter"] is None:
        raise PBMInputError("pbm.grid.min_diameter = null (the smallest class of size_distributions) but the "
                            "config defines no size_distributions; allowed: a diameter (m) or size_distributions")
    if g.get("bins") is not None:
        grid = Grid(g["bins"], g["ratio"], min_diameter=g["min_diameter"])
    else:
        grid = Grid.spanning(g["min_diameter"], g["max_diameter"], g["ratio"])
    agg = settings["aggregation"]
    if source is None:
        if velocity_resolved(settings) and agg["constant_impact_velocity"] is None:
            raise PBMInputError("pbm.aggregation.success.velocity_model = "
                                f"{agg['success']['velocity_model']!r} needs impact velocities; the constant "
                                "collision-frequency kernel has them only with pbm.aggregation."
                                "constant_impact_velocity = a speed in m/s (now null)")
        source = ConstantFrequency(agg["constant_frequency"], agg["constant_impact_velocity"])
    kernel = CollisionKernel(source, agg["beta0"], build_success(agg["success"]),
                             update_interval=agg["frequency_update_interval"])
    t0, t1, _ = process_times(settings)
    liquid = LiquidAddition(settings["liquid_addition"]["rate"], t0, t1,
                            settings["liquid_addition"]["distribution"])
    cons = Consolidation(settings["consolidation"]["rate"], settings["consolidation"]["min_porosity"])
    s = settings["solver"]
    solver = SolverSettings(method=s["method"], safety=s["safety"], max_step=s["max_step"], rtol=s["rtol"],
                            atol=s["atol"], max_overflow_fraction=s["max_overflow_fraction"],
                            max_steps=s["max_steps"], max_wall_time=s["max_wall_time"])
    return GranulationPBM(grid, kernel, liquid, cons, solver, rpm=rpm, scheme=agg["scheme"],
                          separate_feed=g["separate_feed"])


def initial_state_from_config(config: dict, model: GranulationPBM, distribution: str,
                              settings: dict | None = None) -> State:
    dists = config.get("size_distributions", {})
    if distribution not in dists:
        raise PBMInputError(f"size distribution {distribution!r} is not in the config; defined: {sorted(dists)}")
    dist = dists[distribution]
    d = np.asarray(dist["diameters"], float)
    f = np.asarray(dist["number_fractions"], float)
    if d.shape != f.shape or f.sum() <= 0:
        raise PBMInputError(f"size_distributions.{distribution}: {d.size} diameters, {f.size} fractions "
                            f"summing to {f.sum():g}; need one fraction per diameter and a positive sum")
    u = volume_of(d)
    f = f / f.sum()
    total = bed_solid_volume(config)
    numbers = total / float(np.sum(f * u)) * f
    settings = settings or resolve_settings(config)
    ini = settings["initial"]
    return model.initial_state(u, numbers, liquid_content=ini["liquid_content"], porosity=ini["porosity"],
                               what=f"size distribution {distribution!r}")


def run_pbm(config: dict, source=None, rpm: float = 0.0, distribution_name: str | None = None, *,
            t_end: float | None = None, output_times=None):
    """Run the batch granulation of the config's ``pbm:`` section for one operating point.

    ``source``: collision-frequency source ``(diameters, numbers, rpm) -> (K, K)`` (default
    ConstantFrequency(pbm.aggregation.constant_frequency)); ``distribution_name``: a key of
    ``size_distributions`` (default: the first of ``grid.size_distributions``). Returns a Result.
    """
    settings = resolve_settings(config)
    if distribution_name is None:
        names = config.get("grid", {}).get("size_distributions") or list(config.get("size_distributions", {}))
        if not names:
            raise PBMInputError("no size distribution given and none in the config")
        distribution_name = names[0]
    model = build_model(settings, source, rpm)
    state = initial_state_from_config(config, model, distribution_name, settings)
    _, _, t_final = process_times(settings)
    t_end = t_final if t_end is None else float(t_end)
    if output_times is None:
        step = float(settings["output"]["interval"])
        output_times = np.arange(0.0, t_end + 0.5 * step, step)
    res = model.run(0.0, t_end, state, output_times=output_times)
    res.info.update({"distribution": distribution_name, "source": repr(model.kernel.source),
                     "frequency_evaluations": model.kernel.evaluations,
                     "bed_solid_volume": bed_solid_volume(config), "settings": settings,
                     "spray_window": list(process_times(settings)[:2])})
    return res
