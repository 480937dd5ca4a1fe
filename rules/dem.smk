# DEM stage: one LIGGGHTS run per operating point, then the grid's collision tables.


rule dem_point:
    output:
        table=f"{RESULTS}/dem/rpm{{rpm}}_{{dist}}/collisions.csv",
        walls=f"{RESULTS}/dem/rpm{{rpm}}_{{dist}}/wall_collisions.csv",
        summary=f"{RESULTS}/dem/rpm{{rpm}}_{{dist}}/summary.json",
    params:
        point=lambda wc: canonical(point_config(config, wc.dist)),
        run_dir=lambda wc, output: os.path.dirname(output.table),
    # MPI ranks of LIGGGHTS: dem.mpi_ranks (threads, for a local run), or the `tasks` resource a
    # cluster profile sets (with an `mpi` launcher such as "srun --mpi=pmix", and threads 1);
    # none of them is a param, so changing them reruns nothing that has finished
    threads: config["dem"].get("mpi_ranks", 1)
    resources:
        tasks=config["dem"].get("mpi_ranks", 1),
    log:
        f"{RESULTS}/logs/dem/rpm{{rpm}}_{{dist}}.log",
    conda:
        "../envs/dem.yaml"
    script:
        "../workflow/scripts/dem_point.py"


rule collision_tables:
    input:
        tables=dem_outputs("collisions.csv"),
        walls=dem_outputs("wall_collisions.csv"),
        summaries=dem_outputs("summary.json"),
    output:
        table=f"{RESULTS}/dem/collisions.csv",
        walls=f"{RESULTS}/dem/wall_collisions.csv",
        runs=f"{RESULTS}/dem/runs.csv",
    log:
        f"{RESULTS}/logs/dem/collision_tables.log",
    conda:
        "../envs/dem.yaml"
    script:
        "../workflow/scripts/collision_tables.py"
