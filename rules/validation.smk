# Validation: PBM-DEM (LIGGGHTS at every coupling interval, validation.dem_replicates loops per
# speed that differ only by their DEM insertion seeds) vs PBM-ANN (and once per ensemble member of
# the surrogate) vs PBM-constant; the replicate bands, the comparison table, the proposals of the
# active learning and the PBM-ANN impeller-speed sweep. The params of the loops are what one
# speed's loop uses (CFG.coupled_loop()): neither the list of speeds nor the number of replicates.


rule pbm_dem_coupled:
    output:
        **run_outputs(layout.validation_run("pbm_dem", rep="{rep}")),
    log:
        layout.log("validation/pbm_dem_rpm{rpm}_rep{rep}.log"),
    conda:
        "../envs/validation.yaml"
    threads: DEM_RANKS
    resources:
        tasks=DEM_RANKS,
    params:
        deck_sha256=DECK_SHA256,
        loop=loop_params,
        method="dem",
        outdir=lambda wc, output: os.path.dirname(output.summary),
    script:
        "../workflow/scripts/validation_loop.py"


rule pbm_ann_coupled:
    input:
        model=MODEL,
    output:
        **run_outputs(layout.validation_run("pbm_ann")),
        members=f"{SPEED}/pbm_ann/members.csv",
    log:
        layout.log("validation/pbm_ann_rpm{rpm}.log"),
    conda:
        "../envs/validation.yaml"
    params:
        loop=loop_params,
        method="ann",
        outdir=lambda wc, output: os.path.dirname(output.summary),
    script:
        "../workflow/scripts/validation_loop.py"


rule pbm_constant_calibrated:
    input:
        model=MODEL,
    output:
        **run_outputs(layout.validation_run("pbm_constant"), loop=False),
    log:
        layout.log("validation/pbm_constant_rpm{rpm}.log"),
    conda:
        "../envs/validation.yaml"
    params:
        loop=loop_params,
        method="constant",
        outdir=lambda wc, output: os.path.dirname(output.summary),
    script:
        "../workflow/scripts/validation_loop.py"


rule validation_bands:
    input:
        lambda wc: speed_files(wc.rpm),
    output:
        bands=f"{SPEED}/bands.csv",
    log:
        layout.log("validation/bands_rpm{rpm}.log"),
    conda:
        "../envs/validation.yaml"
    params:
        validation_dir=lambda wc, input: layout.validation_dir_of(input[0]),
        replicates=CFG.validation.dem_replicates,
    script:
        "../workflow/scripts/validation_bands.py"


rule comparison:
    input:
        all_speed_files(),
    output:
        table=report(
            layout.report("comparison.csv"),
            caption="../workflow/report/comparison.rst",
            category=CATEGORIES["validation"],
        ),
    log:
        layout.log("validation/comparison.log"),
    conda:
        "../envs/validation.yaml"
    params:
        validation_dir=lambda wc, input: layout.validation_dir_of(input[0]),
        rpms=VAL_RPMS,
        grid_rpm=list(CFG.grid.impeller_rpm),
        replicates=CFG.validation.dem_replicates,
    script:
        "../workflow/scripts/comparison.py"


rule propose_points:
    input:
        model=MODEL,
        intervals=expand(f"{SPEED}/pbm_ann/intervals.csv", rpm=VAL_RPMS),
    output:
        fragment=layout.validation("proposals.yaml"),
        table=report(
            layout.validation("proposals.csv"),
            caption="../workflow/report/proposals.rst",
            category=CATEGORIES["validation"],
        ),
    log:
        layout.log("validation/propose_points.log"),
    conda:
        "../envs/validation.yaml"
    params:
        grid=CFG.grid.to_dict(),
        distributions={n: CFG.size_distributions[n].to_dict() for n in CFG.grid.distributions()},
        granulator=CFG.granulator.to_dict(),
        max_points=CFG.validation.proposals.max_points,
        rpms=VAL_RPMS,
    script:
        "../workflow/scripts/propose_points.py"


rule rpm_sweep:
    input:
        model=MODEL,
    output:
        table=layout.validation("rpm_sweep.csv"),
        plot=report(
            layout.validation("rpm_sweep.png"),
            caption="../workflow/report/rpm_sweep.rst",
            category=CATEGORIES["validation"],
        ),
    log:
        layout.log("validation/rpm_sweep.log"),
    conda:
        "../envs/validation.yaml"
    params:
        loop=loop_params,
        sweep=lambda wc: CFG.validation.sweep.to_dict(),
    script:
        "../workflow/scripts/rpm_sweep.py"


extra_targets += [f"{layout.speed(rpm)}/bands.csv" for rpm in VAL_RPMS]
extra_targets += [layout.report("comparison.csv"), layout.validation("proposals.yaml")]


# The PBM-ANN studies the report's findings open with: final sizes against impeller speed (the
# sweep's speeds, validation feed) and against the feed (the grid's feeds and 50:50 blends between
# neighbours, at FEED_STUDY_RPM), each with the ensemble members' range and the domain status.
rule pbm_ann_studies:
    input:
        model=MODEL,
    output:
        speed=layout.validation("speed_study.csv"),
        feed=layout.validation("feed_study.csv"),
    log:
        layout.log("validation/pbm_ann_studies.log"),
    conda:
        "../envs/validation.yaml"
    params:
        loop=loop_params,
        speeds=lambda wc: CFG.validation.sweep.speeds(),
        grid_speeds=CFG.grid.speeds(),
        feed_rpm=FEED_STUDY_RPM,
        feeds={name: CFG.distribution(name).to_dict() for name in CFG.grid.size_distributions},
    script:
        "../workflow/scripts/pbm_ann_studies.py"
