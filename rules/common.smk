# Shared helpers: the operating grid, parameters of the rules and the list of final targets.
import os

from pbmdem.dem import point_config, point_id, result_settings, rpm_text

RESULTS = "results"


def canonical(obj):
    """The same dict with keys sorted at every level: Snakemake compares params by their text,
    so a config re-saved with another key order must not look like a change."""
    if isinstance(obj, dict):
        return {k: canonical(obj[k]) for k in sorted(obj)}
    if isinstance(obj, list):
        return [canonical(v) for v in obj]
    return obj


def grid_points():
    """(rpm, distribution) of every operating point of the config's grid."""
    return [
        (rpm_text(rpm), dist)
        for rpm in config["grid"]["impeller_rpm"]
        for dist in config["grid"]["size_distributions"]
    ]


def dem_outputs(name):
    """One file per operating point and replicate."""
    return [
        f"{RESULTS}/dem/rpm{rpm}_{dist}/rep{rep}/{name}"
        for rpm, dist in grid_points()
        for rep in range(config["dem"].get("replicates", 3))
    ]


def all_targets():
    targets = [
        f"{RESULTS}/dem/collisions.csv",
        f"{RESULTS}/dem/wall_collisions.csv",
        f"{RESULTS}/dem/impact_velocity.csv",
        f"{RESULTS}/dem/runs.csv",
        f"{RESULTS}/dem/speed_response.csv",
        f"{RESULTS}/dem/flow_development.csv",
        f"{RESULTS}/surrogate/model.skops",
        f"{RESULTS}/surrogate/metrics.csv",
        f"{RESULTS}/surrogate/parity.png",
    ]
    targets += extra_targets
    return targets


# stages append their final outputs here
extra_targets = []


# --- PBM stage
def pbm_params(wildcards):
    return canonical({
        "pbm": config.get("pbm", {}),
        "size_distributions": {wildcards.dist: config["size_distributions"][wildcards.dist]},
        "dem": result_settings(config["dem"]),
        "granulator": config["granulator"],
    })


def pbm_constant_outputs():
    return [f"{RESULTS}/pbm/constant/rpm{rpm}_{dist}/summary.csv" for rpm, dist in grid_points()]


# --- validation stage
from pbmdem.coupling import settings_from_config

VALIDATION = settings_from_config(config)
VAL_RPMS = [rpm_text(r) for r in VALIDATION["rpm"]]
MODEL = f"{RESULTS}/surrogate/model.skops"


def loop_config():
    """The config parts a validation loop depends on (as params, so that other edits do not re-run it)."""
    keys = ("granulator", "material", "dem", "pbm", "validation")
    out = {k: config[k] for k in keys if k in config}
    out["dem"] = result_settings(config["dem"])  # ranks and timeouts do not change a result
    # the list of speeds and the sweep do not change one speed's loop
    out["validation"] = {k: v for k, v in VALIDATION.items() if k not in ("rpm", "sweep")}
    dist = VALIDATION["distribution"]
    out["size_distributions"] = {dist: config["size_distributions"][dist]}
    return canonical(out)


def method_outputs(method):
    return {
        "summary": f"{RESULTS}/validation/rpm{{rpm}}/{method}/summary.csv",
        "bins": f"{RESULTS}/validation/rpm{{rpm}}/{method}/final_bins.csv",
        "timing": f"{RESULTS}/validation/rpm{{rpm}}/{method}/timing.json",
    }
