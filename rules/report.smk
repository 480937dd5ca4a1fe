# The report of the study is Snakemake's report: every figure and table is registered with report()
# (captions in workflow/report/*.rst), so that `snakemake --report report.html` (or report.zip)
# holds the whole study. Rules: report_findings (the answers the report opens with), report_speed
# (figures and out-of-domain table of one validation speed), report_settings (process settings,
# impeller speeds), report_tables (comparison in display form, targets), report_provenance (config
# hashes, git commit, versions, the surrogate's kernel source).
report: "../workflow/report/workflow.rst"


# The findings the report opens with (category "1. Findings", and the text included at the top of
# workflow/report/workflow.rst): final sizes against impeller speed and against the feed, in words
# and one figure each, breakage, the factor d50 depends on most (the Sobol' indices), what lumping
# leaves out (the 1-D against the 2-D PBM: figure, table and words), then how far to trust them (the
# comparison with PBM-DEM, and what the surrogate was trained on with its accuracy on DEM runs it
# never saw); with validation.feed_check.feed set, the PBM-DEM check of the feed result
# (rules/validation.smk).
rule report_findings:
    input:
        **(
            {"feed_check": layout.validation("feed_check.csv")}
            if CFG.validation.feed_check.feed
            else {}
        ),
        speed=layout.validation("speed_study.csv"),
        feed=layout.validation("feed_study.csv"),
        breakage=layout.validation("breakage_study.csv"),
        sensitivity=layout.design("sensitivity.csv"),
        sensitivity_info=layout.design("sensitivity.json"),
        comparison=layout.report("comparison.csv"),
        # what the surrogate was trained on, and its held-out accuracy, beside the validation
        training=layout.dem("collisions.csv"),
        metadata=layout.surrogate("model.json"),
        # what lumping leaves out: the 1-D against the 2-D PBM (rules/validation.smk, rule lumping)
        lumping=layout.validation("lumping.csv"),
        lumping_liquid=layout.validation("lumping_liquid.csv"),
        lumping_info=layout.validation("lumping.json"),
    output:
        **registered_tables(("lumping",), CATEGORIES["findings"], "lumping"),
        speed_png=registered(
            layout.report("findings/speed.png"),
            "findings_speed",
            CATEGORIES["findings"],
            result="granule size against impeller speed",
        ),
        feed_png=registered(
            layout.report("findings/feed.png"),
            "findings_feed",
            CATEGORIES["findings"],
            result="granule size against the feed",
        ),
        breakage_png=registered(
            layout.report("findings/breakage.png"),
            "findings_breakage",
            CATEGORIES["findings"],
            result="granule size against impeller speed with breakage",
        ),
        lumping_png=registered(
            layout.report("findings/lumping.png"),
            "findings_lumping",
            CATEGORIES["findings"],
            result="what lumping leaves out: 1-D against 2-D PBM",
        ),
        rst=layout.report("findings/findings.rst"),
    log:
        layout.log("report/findings.log"),
    conda:
        "../envs/validation.yaml"
    params:
        speed_feed=CFG.validation.distribution,
        feed_rpm=FEED_STUDY_RPM,
        batch_s=CFG.pbm.process.end,
        confidence=CFG.sensitivity.confidence,
    script:
        "../workflow/scripts/report_findings.py"


rule report_speed:
    input:
        runs=lambda wc: speed_files(wc.rpm),
        bands=f"{SPEED}/bands.csv",
        model=MODEL,
    output:
        **{
            key: registered(
                path,
                SPEED_CAPTIONS[key][0],
                CATEGORIES["validation"],
                "{rpm} rpm",
                result=SPEED_CAPTIONS[key][1],
            )
            for key, path in speed_report_files().items()
        },
    log:
        layout.log("report/speed_rpm{rpm}.log"),
    conda:
        "../envs/validation.yaml"
    params:
        validation_dir=lambda wc, input: layout.validation_dir_of(input[0]),
        replicates=CFG.validation.dem_replicates,
        process=CFG.pbm.process.to_dict(),
    script:
        "../workflow/scripts/report_speed.py"


rule report_settings:
    output:
        **registered_tables(("settings", "speeds"), CATEGORIES["settings"]),
    log:
        layout.log("report/settings.log"),
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
            "grid_rpm": CFG.grid.speeds(),
        },
    script:
        "../workflow/scripts/report_settings.py"


rule report_tables:
    input:
        comparison=layout.report("comparison.csv"),
    output:
        **registered_tables(("targets",), CATEGORIES["validation"], "targets"),
        **registered_tables(
            (
                "comparison_d50",
                "comparison_tails",
                "comparison_accuracy",
                "comparison_cost",
                "comparison_domain",
            ),
            CATEGORIES["validation"],
            "comparison",
        ),
    log:
        layout.log("report/tables.log"),
    conda:
        "../envs/validation.yaml"
    script:
        "../workflow/scripts/report_tables.py"


# The design space and the calibration check in display form (sizes in mm, the recovery table with
# its intervals), next to their figures in "1. Findings".
rule report_design:
    input:
        design=layout.design("design_space.csv"),
        check=layout.design("calibration_check.csv"),
    output:
        **registered_tables(("design_space_table",), CATEGORIES["findings"], "design space"),
        **registered_tables(("calibration_check",), CATEGORIES["findings"], "parameter estimation"),
    log:
        layout.log("report/design.log"),
    conda:
        "../envs/validation.yaml"
    params:
        third_key=CFG.design_space.third_factor.key,
        confidence=CFG.calibration.confidence,
    script:
        "../workflow/scripts/report_design.py"


# The configuration hash is read from the job's completed config (like the execution settings of a
# DEM job); the params are the settings without the execution settings, which rerun nothing. The
# results are inputs, so that the table (git commit, versions) is rewritten whenever they are. Where
# the project and the working directory are is written into the table, never a param: a moved or
# copied project reruns nothing.
rule report_provenance:
    input:
        runs=layout.dem("runs.csv"),
        metadata=layout.surrogate("model.json"),
        results=[
            layout.report("comparison.csv"),
            layout.surrogate("metrics.csv"),
            layout.validation("rpm_sweep.csv"),
            layout.validation("proposals.csv"),
        ],
    output:
        csv=registered(
            layout.report("tables/provenance.csv"),
            "provenance",
            CATEGORIES["settings"],
            table="provenance",
            format="CSV",
        ),
        html=registered(
            layout.report("tables/provenance.html"),
            "provenance",
            CATEGORIES["settings"],
            table="provenance",
            format="HTML",
        ),
    log:
        layout.log("report/provenance.log"),
    conda:
        "../envs/validation.yaml"
    params:
        settings=settings_mapping(CFG.to_dict()),
    script:
        "../workflow/scripts/report_provenance.py"


# the report's files (what `snakemake --report` collects)
extra_targets += [layout.report("findings/findings.rst"), *table_files(*REPORT_TABLES).values()]
extra_targets += [f for rpm in VAL_RPMS for f in speed_report_files(rpm).values()]
