# Validation: PBM-DEM (LIGGGHTS at every coupling interval) vs PBM-ANN vs PBM-constant, the
# PBM-ANN impeller-speed sweep, and the self-contained HTML report.
rule pbm_dem_coupled:
    output:
        **method_outputs("pbm_dem"),
        intervals=f"{RESULTS}/validation/rpm{{rpm}}/pbm_dem/intervals.csv",
    params:
        config=lambda wc: loop_config(),
        method="dem",
        outdir=lambda wc, output: os.path.dirname(output.summary),
    threads: config["dem"].get("mpi_ranks", 1)
    resources:
        tasks=config["dem"].get("mpi_ranks", 1),
    log:
        f"{RESULTS}/logs/validation/pbm_dem_rpm{{rpm}}.log",
    conda:
        "../envs/validation.yaml"
    script:
        "../workflow/scripts/validation_loop.py"


rule pbm_ann_coupled:
    input:
        model=MODEL,
    output:
        **method_outputs("pbm_ann"),
        intervals=f"{RESULTS}/validation/rpm{{rpm}}/pbm_ann/intervals.csv",
    params:
        config=lambda wc: loop_config(),
        method="ann",
        outdir=lambda wc, output: os.path.dirname(output.summary),
    log:
        f"{RESULTS}/logs/validation/pbm_ann_rpm{{rpm}}.log",
    conda:
        "../envs/validation.yaml"
    script:
        "../workflow/scripts/validation_loop.py"


rule pbm_constant_calibrated:
    input:
        model=MODEL,
    output:
        **method_outputs("pbm_constant"),
    params:
        config=lambda wc: loop_config(),
        method="constant",
        outdir=lambda wc, output: os.path.dirname(output.summary),
    log:
        f"{RESULTS}/logs/validation/pbm_constant_rpm{{rpm}}.log",
    conda:
        "../envs/validation.yaml"
    script:
        "../workflow/scripts/validation_loop.py"


rule rpm_sweep:
    input:
        model=MODEL,
    output:
        table=f"{RESULTS}/validation/rpm_sweep.csv",
        plot=f"{RESULTS}/validation/rpm_sweep.png",
    params:
        config=lambda wc: {**loop_config(), "validation": canonical(VALIDATION)},
    log:
        f"{RESULTS}/logs/validation/rpm_sweep.log",
    conda:
        "../envs/validation.yaml"
    script:
        "../workflow/scripts/rpm_sweep.py"


rule report:
    input:
        runs=f"{RESULTS}/dem/runs.csv",
        collisions=f"{RESULTS}/dem/collisions.csv",
        speed_response=f"{RESULTS}/dem/speed_response.csv",
        flow_development=f"{RESULTS}/dem/flow_development.csv",
        speed_plot=f"{RESULTS}/dem/speed_response.png",
        velocity_plot=f"{RESULTS}/dem/impact_velocity.png",
        metrics=f"{RESULTS}/surrogate/metrics.csv",
        parity=f"{RESULTS}/surrogate/parity.png",
        metadata=f"{RESULTS}/surrogate/model.json",
        model=MODEL,
        sweep=f"{RESULTS}/validation/rpm_sweep.csv",
        sweep_plot=f"{RESULTS}/validation/rpm_sweep.png",
        loops=expand(f"{RESULTS}/validation/rpm{{rpm}}/{{method}}/summary.csv", rpm=VAL_RPMS,
                     method=["pbm_dem", "pbm_ann", "pbm_constant"]),
        intervals=expand(f"{RESULTS}/validation/rpm{{rpm}}/{{method}}/intervals.csv", rpm=VAL_RPMS,
                         method=["pbm_dem", "pbm_ann"]),
    output:
        html=f"{RESULTS}/report/report.html",
        comparison=f"{RESULTS}/report/comparison.csv",
    params:
        validation_dir=lambda wc, input: os.path.dirname(input.sweep),
        rpms=VAL_RPMS,
        grid_rpm=config["grid"]["impeller_rpm"],
    log:
        f"{RESULTS}/logs/report.log",
    conda:
        "../envs/validation.yaml"
    script:
        "../workflow/scripts/report.py"


extra_targets.append(f"{RESULTS}/report/report.html")
