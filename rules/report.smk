# The report of the study. Every figure and table is registered with report() (captions in
# workflow/report/*.rst), so that `snakemake --report report.zip` holds the whole study;
# results/report/report.html is the same content as one self-contained page, assembled from the
# same files. Rules: report_speed (figures and out-of-domain table of one validation speed),
# report_settings (process settings, impeller speeds), report_tables (comparison in display
# form, targets), report_provenance (config hashes, git commit, versions) and report (the page).
from pbmdem.report.provenance import settings_mapping


report: "../workflow/report/workflow.rst"


REPORT = f"{RESULTS}/report"


def speed_report_files(rpm="{rpm}"):
    """The report files of one validation speed: name -> path."""
    folder = f"{REPORT}/rpm{rpm}"
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
        f"{name}_{kind}": f"{REPORT}/tables/{name}.{kind}"
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


def validation_dir_of_bands(wildcards, input):
    """results/validation, from .../rpm<rpm>/bands.csv."""
    return os.path.dirname(os.path.dirname(input.bands))


rule report_speed:
    input:
        runs=lambda wc: speed_files(wc.rpm),
        bands=f"{RESULTS}/validation/rpm{{rpm}}/bands.csv",
        model=MODEL,
    output:
        **{
            key: registered(
                path,
                SPEED_CAPTIONS[key][0],
                "Validation",
                "{rpm} rpm",
                result=SPEED_CAPTIONS[key][1],
            )
            for key, path in speed_report_files().items()
        },
    log:
        f"{RESULTS}/logs/report/speed_rpm{{rpm}}.log",
    conda:
        "../envs/validation.yaml"
    params:
        validation_dir=validation_dir_of_bands,
        replicates=CFG.validation.dem_replicates,
        process=CFG.pbm.process.to_dict(),
    script:
        "../workflow/scripts/report_speed.py"


rule report_settings:
    output:
        **registered_tables(("settings", "speeds"), "Settings and provenance"),
    log:
        f"{RESULTS}/logs/report/settings.log",
    conda:
        "../envs/validation.yaml"
    params:
        settings={
            "pbm": CFG.pbm.to_dict(),
            "granulator": CFG.granulator.to_dict(),
            "feed_name": CFG.validation.distribution,
            "feed": CFG.distribution(CFG.validation.distribution).to_dict(),
            "coupling_intervals": CFG.validation.coupling_intervals,
            "dem_replicates": CFG.validation.dem_replicates,
            "dem_sampling_time": CFG.validation.dem_sampling_time,
            "validation_rpm": list(CFG.validation.rpm),
            "grid_rpm": list(CFG.grid.impeller_rpm),
        },
    script:
        "../workflow/scripts/report_settings.py"


rule report_tables:
    input:
        comparison=f"{REPORT}/comparison.csv",
    output:
        **registered_tables(("targets",), "Report"),
        **registered_tables(
            ("comparison_d50", "comparison_accuracy", "comparison_cost", "comparison_domain"),
            "Validation",
            "comparison",
        ),
    log:
        f"{RESULTS}/logs/report/tables.log",
    conda:
        "../envs/validation.yaml"
    script:
        "../workflow/scripts/report_tables.py"


# The configuration hash is read from the job's completed config (like the execution settings of a
# DEM job); the params are the settings without the execution settings, which rerun nothing. The
# results are inputs, so that the table (git commit, versions) is rewritten whenever they are.
rule report_provenance:
    input:
        runs=f"{RESULTS}/dem/runs.csv",
        metadata=f"{RESULTS}/surrogate/model.json",
        results=[
            f"{REPORT}/comparison.csv",
            f"{RESULTS}/surrogate/metrics.csv",
            f"{RESULTS}/validation/rpm_sweep.csv",
            f"{RESULTS}/validation/proposals.csv",
        ],
    output:
        csv=registered(
            f"{REPORT}/tables/provenance.csv",
            "provenance",
            "Settings and provenance",
            table="provenance",
            format="CSV",
        ),
        html=registered(
            f"{REPORT}/tables/provenance.html",
            "provenance",
            "Settings and provenance",
            table="provenance",
            format="HTML",
        ),
    log:
        f"{RESULTS}/logs/report/provenance.log",
    conda:
        "../envs/validation.yaml"
    params:
        settings=settings_mapping(CFG.to_dict()),
        basedir=workflow.basedir,
    script:
        "../workflow/scripts/report_provenance.py"


REPORT_TABLES = (
    "settings",
    "speeds",
    "provenance",
    "targets",
    "comparison_d50",
    "comparison_accuracy",
    "comparison_cost",
    "comparison_domain",
)


def report_inputs(wildcards):
    """Every file the page shows: the display tables (table_<name>), the files of each validation
    speed (speed<k>_<name>, k in the order of validation.rpm) and the workflow's own tables and
    figures."""
    files = {
        "runs": f"{RESULTS}/dem/runs.csv",
        "collisions": f"{RESULTS}/dem/collisions.csv",
        "speed_response": f"{RESULTS}/dem/speed_response.csv",
        "flow_development": f"{RESULTS}/dem/flow_development.csv",
        "speed_plot": f"{RESULTS}/dem/speed_response.png",
        "velocity_plot": f"{RESULTS}/dem/impact_velocity.png",
        "metrics": f"{RESULTS}/surrogate/metrics.csv",
        "parity": f"{RESULTS}/surrogate/parity.png",
        "metadata": f"{RESULTS}/surrogate/model.json",
        "sweep": f"{RESULTS}/validation/rpm_sweep.csv",
        "sweep_plot": f"{RESULTS}/validation/rpm_sweep.png",
        "proposals": f"{RESULTS}/validation/proposals.csv",
        "comparison": f"{REPORT}/comparison.csv",
    }
    files.update({f"table_{name}": f"{REPORT}/tables/{name}.csv" for name in REPORT_TABLES})
    for k, rpm in enumerate(VAL_RPMS):
        files.update({f"speed{k}_{name}": path for name, path in speed_report_files(rpm).items()})
    return files


rule report:
    input:
        unpack(report_inputs),
    output:
        html=registered(
            f"{REPORT}/report.html", "report", "Report", result="the whole report as one page"
        ),
    log:
        f"{RESULTS}/logs/report.log",
    conda:
        "../envs/validation.yaml"
    params:
        rpms=VAL_RPMS,
    script:
        "../workflow/scripts/report.py"


extra_targets.append(f"{REPORT}/report.html")
