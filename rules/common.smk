# Shared helpers: the operating grid and the list of final targets.
from pbmdem.dem import point_config, point_id

RESULTS = "results"

wildcard_constraints:
    rpm=r"[0-9]+(\.[0-9]+)?",
    dist=r"[A-Za-z][A-Za-z0-9_-]*",


def grid_points():
    """(rpm, distribution) of every operating point of the config's grid."""
    return [
        (f"{float(rpm):g}", dist)
        for rpm in config["grid"]["impeller_rpm"]
        for dist in config["grid"]["size_distributions"]
    ]


def dem_outputs(name):
    return [f"{RESULTS}/dem/rpm{rpm}_{dist}/{name}" for rpm, dist in grid_points()]


def all_targets():
    targets = [
        f"{RESULTS}/dem/collisions.csv",
        f"{RESULTS}/dem/wall_collisions.csv",
        f"{RESULTS}/dem/runs.csv",
        f"{RESULTS}/surrogate/model.skops",
        f"{RESULTS}/surrogate/metrics.csv",
        f"{RESULTS}/surrogate/parity.png",
    ]
    targets += extra_targets
    return targets


# stages append their final outputs here
extra_targets = []
