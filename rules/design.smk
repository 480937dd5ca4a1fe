# What the fast model is for (docs/design.md, docs/calibration.md): the PBM-ANN design space over
# impeller speed x binder rate x a third pbm setting with the specification region, and the check
# of the parameter estimation on data of known parameters (PBM-DEM's own output; PBM-constant's
# output with known noise). Both run many in-memory PBM batches over the job's threads.


rule design_space:
    input:
        model=MODEL,
    output:
        table=registered(
            f"{RESULTS}/design/design_space.csv",
            "design_space_table",
            CATEGORIES["findings"],
            "design space",
            result="design-space table",
        ),
        maps=registered(
            f"{RESULTS}/design/design_space.png",
            "design_space",
            CATEGORIES["findings"],
            "design space",
            result="design-space maps",
        ),
        info=f"{RESULTS}/design/design_space.json",
    log:
        f"{RESULTS}/logs/design/design_space.log",
    conda:
        "../envs/validation.yaml"
    threads: CFG.design_space.n_jobs
    params:
        loop=loop_params,
        design=CFG.design_space.to_dict(),
    script:
        "../workflow/scripts/design_space.py"


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
        table=registered(
            f"{RESULTS}/design/calibration_check.csv",
            "calibration_check",
            CATEGORIES["findings"],
            "parameter estimation",
            result="recovery of known parameters",
        ),
        figure=registered(
            f"{RESULTS}/design/calibration_check.png",
            "calibration_fit",
            CATEGORIES["findings"],
            "parameter estimation",
            result="fits of the recovery check",
        ),
        measured=f"{RESULTS}/design/measured_pbm_dem.csv",
        summary=f"{RESULTS}/design/calibration_check.json",
    log:
        f"{RESULTS}/logs/design/calibration_check.log",
    conda:
        "../envs/validation.yaml"
    threads: 2
    params:
        loop=loop_params,
        validation_dir=lambda wc, input: validation_dir_of(input.dem),
        rpms=VAL_RPMS,
        replicates=CFG.validation.dem_replicates,
        calibration=CFG.calibration.to_dict(),
    script:
        "../workflow/scripts/calibration_check.py"


extra_targets += [f"{RESULTS}/design/design_space.png", f"{RESULTS}/design/calibration_check.csv"]
