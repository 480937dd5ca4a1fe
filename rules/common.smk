# Shared helpers: the operating grid, the params of the rules (the settings each stage uses, from
# the typed config CFG) and the list of final targets.
import os
from pathlib import Path

from pbmdem.config import rpm_text

RESULTS = "results"
TEMPLATE = os.path.join(workflow.basedir, "liggghts_templates", "granulator.in")
MODEL = f"{RESULTS}/surrogate/model.skops"


def grid_points():
    """(rpm text, distribution) of every operating point of the config's grid."""
    return [(rpm_text(rpm), dist) for rpm, dist in CFG.grid.points()]


def dem_outputs(name):
    """One file per operating point and replicate."""
    return [
        f"{RESULTS}/dem/rpm{rpm}_{dist}/rep{rep}/{name}"
        for rpm, dist in grid_points()
        for rep in range(CFG.dem_replicates)
    ]


# --- params: what a stage uses, in plain form (a change reruns exactly the rules that use it)
def dem_point_params(wildcards):
    return CFG.dem_point(wildcards.dist).to_dict()


def pbm_batch_params(wildcards):
    return CFG.pbm_batch(wildcards.dist).to_dict()


def loop_params(wildcards=None):
    return CFG.coupled_loop().to_dict()


def pbm_outputs(kernel):
    folder = f"{RESULTS}/pbm/{kernel}/rpm{{rpm}}_{{dist}}"
    return {
        "summary": f"{folder}/summary.csv",
        "bins": f"{folder}/bins.csv",
        "info": f"{folder}/run.json",
        "psd": f"{folder}/psd.png",
        "d50": f"{folder}/d50.png",
    }


# --- job resources: how DEM runs execute (not params: changing them reruns nothing)
DEM_RANKS = CFG.dem_execution.mpi_ranks

# --- validation speeds and runs
VAL_RPMS = [rpm_text(r) for r in CFG.validation.rpm]
VAL_REPS = list(range(CFG.validation.dem_replicates))
RUN_FILES = ("summary.csv", "bins.csv", "final_bins.csv", "timing.json")


def run_outputs(folder, loop=True):
    """The files a validation run writes into `folder` (a coupled loop also intervals.csv)."""
    names = RUN_FILES + (("intervals.csv",) if loop else ())
    return {name.split(".")[0]: f"{folder}/{name}" for name in names}


def dem_replicate_files(name, rpm="{rpm}"):
    """One file of every PBM-DEM replicate of a validation speed."""
    return [f"{RESULTS}/validation/rpm{rpm}/pbm_dem/rep{rep}/{name}" for rep in VAL_REPS]


def speed_files(rpm="{rpm}"):
    """Every run file of one validation speed (all replicates, PBM-ANN with its members, PBM-constant)."""
    folder = f"{RESULTS}/validation/rpm{rpm}"
    files = [f for name in RUN_FILES + ("intervals.csv",) for f in dem_replicate_files(name, rpm)]
    files += list(run_outputs(f"{folder}/pbm_ann").values()) + [f"{folder}/pbm_ann/members.csv"]
    files += list(run_outputs(f"{folder}/pbm_constant", loop=False).values())
    return files


def all_speed_files():
    return [f for rpm in VAL_RPMS for f in speed_files(rpm)]


def validation_dir_of(files):
    """results/validation, from the first file of speed_files() (.../rpm<rpm>/pbm_dem/rep0/summary.csv)."""
    return str(Path(files[0]).parents[3])


def all_targets():
    targets = [
        f"{RESULTS}/dem/collisions.csv",
        f"{RESULTS}/dem/wall_collisions.csv",
        f"{RESULTS}/dem/impact_velocity.csv",
        f"{RESULTS}/dem/runs.csv",
        f"{RESULTS}/dem/speed_response.csv",
        f"{RESULTS}/dem/flow_development.csv",
        MODEL,
        f"{RESULTS}/surrogate/metrics.csv",
        f"{RESULTS}/surrogate/parity.png",
    ]
    targets += extra_targets
    return targets


# stages append their final outputs here
extra_targets = []
