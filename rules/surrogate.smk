# Reduced-order model: MLP encounter surrogate (encounter frequency and impact-velocity
# distribution per class pair, and per wall the impacts per granule and their speeds) trained on
# the DEM grid's tables. Its params are the surrogate
# settings and the granulator (the tip-speed feature): changing them retrains it.

from pbmdem.config import point_id


rule train_surrogate:
    input:
        table=layout.dem("collisions.csv"),
        velocity=layout.dem("impact_velocity.csv"),
        walls=layout.dem("wall_collisions.csv"),
        wall_velocities=layout.dem("wall_impact_velocity.csv"),
    output:
        model=MODEL,
        metadata=layout.surrogate("model.json"),
        metrics=report(
            layout.surrogate("metrics.csv"),
            caption="../workflow/report/surrogate_metrics.rst",
            category=CATEGORIES["surrogate"],
        ),
        parity=report(
            layout.surrogate("parity.png"),
            caption="../workflow/report/parity.rst",
            category=CATEGORIES["surrogate"],
        ),
    log:
        layout.log("train_surrogate.log"),
    priority: 2
    conda:
        "../envs/surrogate.yaml"
    # one thread: it runs beside a PBM-DEM loop on the other core (every fit is single-threaded)
    threads: 1
    params:
        training=lambda wildcards: CFG.surrogate_training().to_dict(),
        # the active-learning runs: samples of the PBM's own states, on which the pair frequency's family is chosen
        pbm_samples=[point_id(p.rpm, p.distribution) for p in CFG.grid.extra_points],
    script:
        "../workflow/scripts/train_surrogate.py"
