# Validation: PBM-DEM (LIGGGHTS at every coupling interval) vs PBM-ANN vs PBM-constant, the
# PBM-ANN impeller-speed sweep, and the report. The params of the loops are what one speed's loop
# uses (CFG.coupled_loop()): neither the list of validation speeds nor the sweep.


rule pbm_dem_coupled:
    input:
        template=TEMPLATE,
    output:
        **method_outputs("pbm_dem"),
        intervals=f"{RESULTS}/validation/rpm{{rpm}}/pbm_dem/intervals.csv",
    params:
        loop=loop_params,
        method="dem",
        outdir=lambda wc, output: os.path.dirname(output.summary),
    threads: DEM_RANKS
    resources:
        tasks=DEM_RANKS,
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
        loop=loop_params,
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
        loop=loop_params,
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
        loop=loop_params,
        sweep=lambda wc: CFG.validation.sweep.to_dict(),
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
        summaries=validation_files("summary.csv"),
        bins=validation_files("final_bins.csv"),
        timings=validation_files("timing.json"),
        intervals=validation_files("intervals.csv", ["pbm_dem", "pbm_ann"]),
    output:
        html=f"{RESULTS}/report/report.html",
        comparison=f"{RESULTS}/report/comparison.csv",
    params:
        validation_dir=lambda wc, input: os.path.dirname(input.sweep),
        rpms=VAL_RPMS,
        grid_rpm=list(CFG.grid.impeller_rpm),
    log:
        f"{RESULTS}/logs/report.log",
    conda:
        "../envs/validation.yaml"
    script:
        "../workflow/scripts/report.py"


extra_targets.append(f"{RESULTS}/report/report.html")
