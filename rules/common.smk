# Shared helpers: the operating grid, the params of the rules (the settings each stage uses, from
# the typed config CFG) and the list of final targets.
import os

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

# --- validation speeds
VAL_RPMS = [rpm_text(r) for r in CFG.validation.rpm]
VALIDATION_METHODS = ["pbm_dem", "pbm_ann", "pbm_constant"]


def method_outputs(method):
    return {
        "summary": f"{RESULTS}/validation/rpm{{rpm}}/{method}/summary.csv",
        "bins": f"{RESULTS}/validation/rpm{{rpm}}/{method}/final_bins.csv",
        "timing": f"{RESULTS}/validation/rpm{{rpm}}/{method}/timing.json",
    }


def validation_files(name, methods=VALIDATION_METHODS):
    return expand(
        f"{RESULTS}/validation/rpm{{rpm}}/{{method}}/{name}", rpm=VAL_RPMS, method=methods
    )


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
