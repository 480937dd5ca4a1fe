# The report of the study: results/report/report.html, made from the workflow's tables and figures.


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
        comparison=f"{RESULTS}/report/comparison.csv",
        runs_of_speeds=all_speed_files(),
    output:
        html=f"{RESULTS}/report/report.html",
    params:
        validation_dir=lambda wc, input: validation_dir_of(input.runs_of_speeds),
        rpms=VAL_RPMS,
        replicates=CFG.validation.dem_replicates,
    log:
        f"{RESULTS}/logs/report.log",
    conda:
        "../envs/validation.yaml"
    script:
        "../workflow/scripts/report.py"


extra_targets.append(f"{RESULTS}/report/report.html")
