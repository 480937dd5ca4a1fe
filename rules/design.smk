# What the fast model is for (docs/design.md, docs/calibration.md): the PBM-ANN design space over
# impeller speed x binder rate x a third pbm setting with the specification region, the check of
# the parameter estimation on data of known parameters (PBM-DEM's own output; PBM-constant's
# output with known noise), and the global sensitivity analysis. All run many in-memory PBM
# batches over the job's threads; the design-space and calibration tables reach the report in
# display form through rule report_design, the Sobol' indices as their CSV.


rule design_space:
    input:
        model=MODEL,
    output:
        table=layout.design("design_space.csv"),
        maps=registered(
            layout.design("design_space.png"),
            "design_space",
            CATEGORIES["findings"],
            "design space",
            result="design-space maps",
        ),
        info=layout.design("design_space.json"),
    log:
        layout.log("design/design_space.log"),
    conda:
        "../envs/validation.yaml"
    threads: CFG.design_space.n_jobs
    params:
        loop=loop_params,
        design=CFG.design_space.to_dict(),
    script:
        "../workflow/scripts/design_space.py"


# The global sensitivity analysis (docs/design.md, "Global sensitivity"): Sobol' indices of PBM-ANN's
# final d10/d50/d90 to speed and pbm settings over the ranges of `sensitivity:`, mean and members.
rule sensitivity:
    input:
        model=MODEL,
    output:
        table=registered(
            layout.design("sensitivity.csv"),
            "sensitivity_table",
            CATEGORIES["findings"],
            "global sensitivity",
            table="Sobol indices",
            format="CSV",
        ),
        figure=registered(
            layout.design("sensitivity.png"),
            "sensitivity",
            CATEGORIES["findings"],
            "global sensitivity",
            result="Sobol indices of the final sizes",
        ),
        info=layout.design("sensitivity.json"),
    log:
        layout.log("design/sensitivity.log"),
    conda:
        "../envs/validation.yaml"
    threads: CFG.sensitivity.n_jobs
    params:
        loop=loop_params,
        sensitivity=CFG.sensitivity.to_dict(),
    script:
        "../workflow/scripts/sensitivity.py"


rule calibration_check:
    input:
        model=MODEL,
        dem=[
            f
            for rpm in VAL_RPMS
            for name in RUN_FILES + ("intervals.csv",)
            for f in dem_replicate_files(name, rpm)
        ],
    output:
        table=layout.design("calibration_check.csv"),
        figure=registered(
            layout.design("calibration_check.png"),
            "calibration_fit",
            CATEGORIES["findings"],
            "parameter estimation",
            result="fits of the recovery check",
        ),
        measured=layout.design("measured_pbm_dem.csv"),
        summary=layout.design("calibration_check.json"),
    log:
        layout.log("design/calibration_check.log"),
    conda:
        "../envs/validation.yaml"
    threads: 2
    params:
        loop=loop_params,
        validation_dir=lambda wc, input: layout.validation_dir_of(input.dem[0]),
        rpms=VAL_RPMS,
        replicates=CFG.validation.dem_replicates,
        calibration=CFG.calibration.to_dict(),
    script:
        "../workflow/scripts/calibration_check.py"


extra_targets += [
    layout.design("design_space.png"),
    layout.design("calibration_check.png"),
    layout.design("sensitivity.png"),
]
