# Validation: PBM-DEM (LIGGGHTS at every coupling interval, validation.dem_replicates loops per
# speed that differ only by their DEM insertion seeds) vs PBM-ANN (and once per ensemble member of
# the surrogate) vs PBM-constant; the replicate bands, the comparison table, the proposals of the
# active learning and the PBM-ANN impeller-speed sweep. The params of the loops are what one
# speed's loop uses (CFG.coupled_loop()): neither the list of speeds nor the number of replicates.


rule pbm_dem_coupled:
    input:
        unpack(grid_dem_of_loop),
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
        grid_dem=lambda wc: {k: os.path.dirname(v) for k, v in grid_dem_of_loop(wc).items()},
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
    # its warm batches time PBM-ANN for the comparison's speed ratio: two cores, so that on the
    # default 2-core run no other job shares the machine while they run (one did on 2026-12-06 and
    # made the same batches up to 1.8 times dearer in CPU time; docs/validation.md)
    threads: 2
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


rule pair_samples:
    input:
        model=MODEL,
        intervals=[f for rpm in VAL_RPMS for f in dem_replicate_files("intervals.csv", rpm)],
    output:
        table=report(
            layout.validation("pair_samples.csv"),
            caption="../workflow/report/pair_samples.rst",
            category=CATEGORIES["validation"],
        ),
    log:
        layout.log("validation/pair_samples.log"),
    conda:
        "../envs/validation.yaml"
    params:
        validation_dir=lambda wc, input: layout.validation_dir_of(input.intervals[0]),
        rpms=VAL_RPMS,
        replicates=CFG.validation.dem_replicates,
    script:
        "../workflow/scripts/pair_samples.py"


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
extra_targets += [layout.validation("pair_samples.csv")]


# The PBM-ANN studies the report's findings open with: final sizes against impeller speed (the
# sweep's speeds, validation feed) and against the feed (the grid's feeds and 50:50 blends between
# neighbours, at FEED_STUDY_RPM), each with the ensemble members' range and the domain status; and
# the speed study without breakage, with it and with its criterion's Y and St_def* halved and doubled.
rule pbm_ann_studies:
    input:
        model=MODEL,
    output:
        speed=layout.validation("speed_study.csv"),
        feed=layout.validation("feed_study.csv"),
        breakage=layout.validation("breakage_study.csv"),
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


# What lumping leaves out (docs/pbm.md, "What lumping leaves out"): PBM-ANN (the surrogate's
# ensemble mean) with the lumped one-dimensional PBM and with the size x liquid one (pbm.dimensions
# 2) on the same cases, whatever pbm.dimensions says: the default batch (validation feed at the feed
# study's speed), the speed study's speeds, the design space's binder rates and the feed study's
# feeds at that speed; final d10/d50/d90 of both and the liquid content per size class at the end of
# the default batch. About 15 s of CPU on the default config (36 batches; docs/measurements.md).
rule lumping:
    input:
        model=MODEL,
    output:
        cases=layout.validation("lumping.csv"),
        liquid=layout.validation("lumping_liquid.csv"),
        info=layout.validation("lumping.json"),
    log:
        layout.log("validation/lumping.log"),
    conda:
        "../envs/validation.yaml"
    params:
        loop=loop_params,
        rpm=FEED_STUDY_RPM,
        speeds=lambda wc: CFG.validation.sweep.speeds(),
        liquid_rates=lambda wc: CFG.design_space.liquid_rate.values(),
        feeds={name: CFG.distribution(name).to_dict() for name in CFG.grid.size_distributions},
    script:
        "../workflow/scripts/lumping.py"


# The feed check (validation.feed_check, docs/validation.md): PBM-DEM loops (one job per replicate,
# run in parallel like pbm_dem_coupled) and PBM-ANN (ensemble mean and members, with the case's
# parent feeds) for one case of the feed study, configured so that the DAG is known before the feed
# study runs; the table says whether PBM-DEM confirms the case's statement and whether it is still
# the feed study's most surprising case by pbmdem.validation.feed_check's rule.
FEED_CHECK = CFG.validation.feed_check
FEED_CHECK_REPS = list(range(FEED_CHECK.replicates))
GRID_FEEDS = {name: CFG.distribution(name).to_dict() for name in CFG.grid.size_distributions}


rule feed_check_dem:
    output:
        **run_outputs(layout.feed_check_run()),
    log:
        layout.log("validation/feed_check_pbm_dem_rep{rep}.log"),
    conda:
        "../envs/validation.yaml"
    threads: DEM_RANKS
    resources:
        tasks=DEM_RANKS,
    params:
        deck_sha256=DECK_SHA256,
        loop=loop_params,
        feed=FEED_CHECK.feed,
        feeds=GRID_FEEDS,
        rpm=FEED_CHECK.rpm,
        outdir=lambda wc, output: os.path.dirname(output.summary),
    script:
        "../workflow/scripts/feed_check_loop.py"


rule feed_check_ann:
    input:
        model=MODEL,
    output:
        table=layout.feed_check("pbm_ann.csv"),
    log:
        layout.log("validation/feed_check_pbm_ann.log"),
    conda:
        "../envs/validation.yaml"
    params:
        loop=loop_params,
        feed=FEED_CHECK.feed,
        feeds=GRID_FEEDS,
        rpm=FEED_CHECK.rpm,
    script:
        "../workflow/scripts/feed_check_ann.py"


rule feed_check:
    input:
        dem=[f"{layout.feed_check_run(rep)}/summary.csv" for rep in FEED_CHECK_REPS],
        ann=layout.feed_check("pbm_ann.csv"),
        study=layout.validation("feed_study.csv"),
    output:
        table=report(
            layout.validation("feed_check.csv"),
            caption="../workflow/report/feed_check.rst",
            category=CATEGORIES["validation"],
        ),
    log:
        layout.log("validation/feed_check.log"),
    conda:
        "../envs/validation.yaml"
    params:
        feed=FEED_CHECK.feed,
        rpm=FEED_CHECK.rpm,
        feed_study_rpm=FEED_STUDY_RPM,
    script:
        "../workflow/scripts/feed_check.py"


if FEED_CHECK.feed is not None:
    extra_targets.append(layout.validation("feed_check.csv"))
