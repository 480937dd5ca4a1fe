# DEM stage: one LIGGGHTS run per operating point and replicate (insertion seed), then the
# grid's collision tables (replicate means and standard errors).


rule dem_point:
    output:
        table=f"{DEM_RUN}/collisions.csv",
        walls=f"{DEM_RUN}/wall_collisions.csv",
        velocities=f"{DEM_RUN}/impact_velocity.csv",
        summary=f"{DEM_RUN}/summary.json",
    log:
        layout.log("dem/rpm{rpm}_{dist}_rep{rep}.log"),
    # the grid's runs before the validation's PBM-DEM loops: the surrogate (which needs the whole
    # grid) then trains while the loops still run, instead of after them
    priority: 2
    conda:
        "../envs/dem.yaml"
    # MPI ranks of LIGGGHTS: dem.mpi_ranks (threads, for a local run), or the `tasks` resource a
    # cluster profile sets (with an `mpi` launcher such as "srun --mpi=pmix", and threads 1);
    # none of them is a param, so changing them reruns nothing that has finished
    threads: DEM_RANKS
    resources:
        tasks=DEM_RANKS,
    params:
        deck_sha256=DECK_SHA256,
        point=dem_point_params,
        run_dir=lambda wc, output: os.path.dirname(output.table),
    script:
        "../workflow/scripts/dem_point.py"


rule collision_tables:
    input:
        tables=dem_outputs("collisions.csv"),
        walls=dem_outputs("wall_collisions.csv"),
        velocities=dem_outputs("impact_velocity.csv"),
        summaries=dem_outputs("summary.json"),
    output:
        table=layout.dem("collisions.csv"),
        walls=layout.dem("wall_collisions.csv"),
        velocities=layout.dem("impact_velocity.csv"),
        replicates=layout.dem("collisions_replicates.csv"),
        runs=report(
            layout.dem("runs.csv"),
            caption="../workflow/report/runs.rst",
            category=CATEGORIES["dem"],
        ),
    log:
        layout.log("dem/collision_tables.log"),
    priority: 2
    conda:
        "../envs/dem.yaml"
    script:
        "../workflow/scripts/collision_tables.py"


rule speed_response:
    input:
        replicates=layout.dem("collisions_replicates.csv"),
        runs=layout.dem("runs.csv"),
        velocities=layout.dem("impact_velocity.csv"),
    output:
        table=layout.dem("speed_response.csv"),
        flow=layout.dem("flow_development.csv"),
        plot=report(
            layout.dem("speed_response.png"),
            caption="../workflow/report/speed_response.rst",
            category=CATEGORIES["dem"],
        ),
        velocity_plot=report(
            layout.dem("impact_velocity.png"),
            caption="../workflow/report/impact_velocity.rst",
            category=CATEGORIES["dem"],
        ),
    log:
        layout.log("dem/speed_response.log"),
    conda:
        "../envs/dem.yaml"
    script:
        "../workflow/scripts/speed_response.py"
