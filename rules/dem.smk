# DEM stage: one LIGGGHTS run per operating point and replicate (insertion seed), then the
# grid's collision tables (replicate means and standard errors).


rule dem_point:
    output:
        table=f"{RESULTS}/dem/rpm{{rpm}}_{{dist}}/rep{{rep}}/collisions.csv",
        walls=f"{RESULTS}/dem/rpm{{rpm}}_{{dist}}/rep{{rep}}/wall_collisions.csv",
        velocities=f"{RESULTS}/dem/rpm{{rpm}}_{{dist}}/rep{{rep}}/impact_velocity.csv",
        wall_velocities=f"{RESULTS}/dem/rpm{{rpm}}_{{dist}}/rep{{rep}}/wall_impact_velocity.csv",
        summary=f"{RESULTS}/dem/rpm{{rpm}}_{{dist}}/rep{{rep}}/summary.json",
    log:
        f"{RESULTS}/logs/dem/rpm{{rpm}}_{{dist}}_rep{{rep}}.log",
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
        wall_velocities=dem_outputs("wall_impact_velocity.csv"),
        summaries=dem_outputs("summary.json"),
    output:
        table=f"{RESULTS}/dem/collisions.csv",
        walls=f"{RESULTS}/dem/wall_collisions.csv",
        velocities=f"{RESULTS}/dem/impact_velocity.csv",
        wall_velocities=f"{RESULTS}/dem/wall_impact_velocity.csv",
        replicates=f"{RESULTS}/dem/collisions_replicates.csv",
        runs=report(
            f"{RESULTS}/dem/runs.csv",
            caption="../workflow/report/runs.rst",
            category=CATEGORIES["dem"],
        ),
    log:
        f"{RESULTS}/logs/dem/collision_tables.log",
    priority: 2
    conda:
        "../envs/dem.yaml"
    script:
        "../workflow/scripts/collision_tables.py"


rule speed_response:
    input:
        replicates=f"{RESULTS}/dem/collisions_replicates.csv",
        runs=f"{RESULTS}/dem/runs.csv",
        velocities=f"{RESULTS}/dem/impact_velocity.csv",
    output:
        table=f"{RESULTS}/dem/speed_response.csv",
        flow=f"{RESULTS}/dem/flow_development.csv",
        plot=report(
            f"{RESULTS}/dem/speed_response.png",
            caption="../workflow/report/speed_response.rst",
            category=CATEGORIES["dem"],
        ),
        velocity_plot=report(
            f"{RESULTS}/dem/impact_velocity.png",
            caption="../workflow/report/impact_velocity.rst",
            category=CATEGORIES["dem"],
        ),
    log:
        f"{RESULTS}/logs/dem/speed_response.log",
    conda:
        "../envs/dem.yaml"
    script:
        "../workflow/scripts/speed_response.py"
