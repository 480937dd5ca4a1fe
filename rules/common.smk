# Shared helpers: the operating grid, the params of the rules (the settings each stage uses, from
# the typed config CFG) and the list of final targets.
import hashlib
import os

from pbmdem import layout
from pbmdem.config import rpm_text

# every path comes from pbmdem.layout, the one owner of the results folder's layout; DEM_RUN and
# SPEED are the folders of one DEM run and one validation speed with their wildcards
DEM_RUN = layout.dem_run()
SPEED = layout.speed()
# The LIGGGHTS deck template (package data, the project's liggghts_templates/) enters the DEM
# rules as a param, its SHA-256, not as an input path: an edit reruns every DEM job, while moving
# or copying the project (another absolute path) reruns nothing. Every input and output is a path
# relative to the working directory, as Snakemake expects.
from pbmdem.dem.deck import template_path

DECK_SHA256 = hashlib.sha256(template_path().read_bytes()).hexdigest()
MODEL = layout.MODEL


def dry_run_requested(argv):
    """Whether Snakemake's command line asks for a dry run (-n, --dry-run, --dryrun, -np ...)."""
    short = [a for a in argv if a.startswith("-") and not a.startswith("--")]
    return any(a in ("--dry-run", "--dryrun", "--just-print") for a in argv) or any(
        "n" in a[1:] and a[1:].isalpha() for a in short
    )


# the working directory, for the estimate printed at exit (Snakemake has left it by then)
WORKDIR = os.getcwd()


def print_runtime_estimate():
    """The DEM work of the jobs the dry run scheduled, in wall time (see pbmdem.dem.estimate)."""
    from pbmdem.dem.estimate import study_estimate

    os.chdir(WORKDIR)
    try:
        jobs = list(workflow.dag.needrun_jobs(exclude_finished=False))
    except Exception:  # no DAG was built (an error before it, --lint, ...): nothing to estimate
        return
    grid = [
        (j.wildcards_dict["rpm"], j.wildcards_dict["dist"], j.wildcards_dict["rep"])
        for j in jobs
        if j.rule.name == "dem_point"
    ]
    loops = [
        (j.wildcards_dict["rpm"], j.wildcards_dict["rep"])
        for j in jobs
        if j.rule.name == "pbm_dem_coupled"
    ]
    loops += [
        (CFG.validation.feed_check.rpm, j.wildcards_dict["rep"], feed_check_loop())
        for j in jobs
        if j.rule.name == "feed_check_dem"
    ]
    cores = workflow.resource_settings.cores or 1
    print(study_estimate(CFG, grid, loops, layout.RESULTS).text(cores), file=sys.stderr)


def grid_points():
    """(rpm text, distribution) of every operating point of the config's grid."""
    return [(rpm_text(rpm), dist) for rpm, dist in CFG.grid.points()]


def dem_outputs(name):
    """One file per operating point and replicate."""
    return [
        f"{layout.dem_run(rpm, dist, rep)}/{name}"
        for rpm, dist in grid_points()
        for rep in range(CFG.point_replicates(dist))
    ]


# --- params: what a stage uses, in plain form (a change reruns exactly the rules that use it)
def dem_point_params(wildcards):
    return CFG.dem_point(wildcards.dist).to_dict()


def pbm_batch_params(wildcards):
    return CFG.pbm_batch(wildcards.dist).to_dict()


def loop_params(wildcards=None):
    return CFG.coupled_loop().to_dict()


def feed_check_loop():
    """The coupled loop of the feed check: the validation's, from validation.feed_check.feed."""
    from pbmdem.coupling.studies import feed_case, with_feed

    feed = CFG.validation.feed_check.feed
    grid = {name: CFG.distribution(name) for name in CFG.grid.size_distributions}
    return with_feed(CFG.coupled_loop(), feed, feed_case(grid, feed))


def pbm_outputs(kernel):
    folder = layout.pbm_run(kernel)
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
# the feed study's speed: the middle impeller speed of the DEM grid (a speed the surrogate was trained at)
FEED_STUDY_RPM = CFG.grid.middle_speed()
VAL_RPMS = [rpm_text(r) for r in CFG.validation.rpm]
VAL_REPS = list(range(CFG.validation.dem_replicates))
RUN_FILES = layout.RUN_FILES


def run_outputs(folder, loop=True):
    """The files a validation run writes into `folder` (a coupled loop also intervals.csv)."""
    names = RUN_FILES + (("intervals.csv",) if loop else ())
    return {name.split(".")[0]: f"{folder}/{name}" for name in names}


def grid_dem_of_loop(wc):
    """The DEM grid's files that a PBM-DEM loop of the validation feed borrows (docs/validation.md,
    "Borrowed grid runs"): the settled bed of the feed and replicate, and at a grid speed the run
    of the feed (its summary); none where the grid has no such replicate."""
    feed = CFG.validation.distribution
    points = CFG.grid.points()
    if all(dist != feed for _, dist in points) or int(wc.rep) >= CFG.point_replicates(feed):
        return {}
    files = {"bed": f"{layout.dem_bed(feed, wc.rep)}/bed.json"}
    if (float(wc.rpm), feed) in points:
        files["grid_run"] = f"{layout.dem_run(wc.rpm, feed, wc.rep)}/summary.json"
    return files


def dem_replicate_files(name, rpm="{rpm}"):
    """One file of every PBM-DEM replicate of a validation speed."""
    return [f"{layout.validation_run('pbm_dem', rpm, rep)}/{name}" for rep in VAL_REPS]


def speed_files(rpm="{rpm}"):
    """Every run file of one validation speed (all replicates, PBM-ANN with its members, PBM-constant)."""
    ann = layout.validation_run("pbm_ann", rpm)
    files = [f for name in RUN_FILES + ("intervals.csv",) for f in dem_replicate_files(name, rpm)]
    files += list(run_outputs(ann).values()) + [f"{ann}/members.csv"]
    files += list(run_outputs(layout.validation_run("pbm_constant", rpm), loop=False).values())
    return files


def all_speed_files():
    return [f for rpm in VAL_RPMS for f in speed_files(rpm)]


def all_targets():
    targets = [
        layout.dem("collisions.csv"),
        layout.dem("wall_collisions.csv"),
        layout.dem("impact_velocity.csv"),
        layout.dem("runs.csv"),
        layout.dem("speed_response.csv"),
        layout.dem("flow_development.csv"),
        MODEL,
        layout.surrogate("metrics.csv"),
        layout.surrogate("parity.png"),
    ]
    targets += extra_targets
    return targets


# stages append their final outputs here
extra_targets = []


# --- the report (rules/report.smk): its files, and registering them with Snakemake's report()
from pbmdem.report.provenance import settings_mapping

# the report's categories, in the order a reader needs them (Snakemake's report sorts them by name):
# the answers first, then how far to trust them, then the details
CATEGORIES = {
    "findings": "1. Findings",
    "validation": "2. Validation: how far to trust them",
    "surrogate": "3. Surrogate",
    "dem": "4. DEM",
    "settings": "5. Settings and provenance",
}


def speed_report_files(rpm="{rpm}"):
    """The report files of one validation speed: name -> path."""
    folder = layout.report(f"rpm{rpm}")
    return {
        "sizes": f"{folder}/size_statistics.png",
        "psd": f"{folder}/psd_evolution.png",
        "liquid": f"{folder}/liquid_porosity.png",
        "frequency": f"{folder}/collision_frequency.png",
        "domain_csv": f"{folder}/out_of_domain.csv",
        "domain_html": f"{folder}/out_of_domain.html",
    }


def table_files(*names):
    """<name>_csv and <name>_html of display tables in results/report/tables/."""
    return {
        f"{name}_{kind}": layout.report(f"tables/{name}.{kind}")
        for name in names
        for kind in ("csv", "html")
    }


def registered(path, caption, category, subcategory=None, **labels):
    """`path` registered with Snakemake's report (caption workflow/report/<caption>.rst)."""
    return report(
        path,
        caption=f"../workflow/report/{caption}.rst",
        category=category,
        subcategory=subcategory,
        labels=labels or None,
    )


def registered_tables(names, category, subcategory=None):
    """table_files(*names), each CSV and HTML registered (caption <name>.rst)."""
    return {
        key: registered(
            path,
            key.rsplit("_", 1)[0],
            category,
            subcategory,
            table=key.rsplit("_", 1)[0].replace("_", " "),
            format=key.rsplit("_", 1)[1].upper(),
        )
        for key, path in table_files(*names).items()
    }


SPEED_CAPTIONS = {
    "sizes": ("size_statistics", "d10, d50, d90 vs time"),
    "psd": ("psd_evolution", "mass size distribution over the batch"),
    "liquid": ("liquid_porosity", "liquid content and porosity vs time"),
    "frequency": ("collision_frequency", "collision frequency per interval"),
    "domain_csv": ("out_of_domain", "surrogate domain, interval by interval (CSV)"),
    "domain_html": ("out_of_domain", "surrogate domain, interval by interval"),
}


REPORT_TABLES = (
    "settings",
    "speeds",
    "provenance",
    "targets",
    "comparison_d50",
    "comparison_tails",
    "comparison_accuracy",
    "comparison_cost",
    "comparison_domain",
    "design_space_table",
    "calibration_check",
    "lumping",
)
