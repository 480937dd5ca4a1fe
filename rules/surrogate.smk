# Reduced-order model: MLP encounter surrogate (encounter frequency and impact-velocity
# distribution per class pair) trained on the DEM grid's tables. Its params are the surrogate
# settings and the granulator (the tip-speed feature): changing them retrains it.


rule train_surrogate:
    input:
        table=f"{RESULTS}/dem/collisions.csv",
        velocity=f"{RESULTS}/dem/impact_velocity.csv",
    output:
        model=MODEL,
        metadata=f"{RESULTS}/surrogate/model.json",
        metrics=f"{RESULTS}/surrogate/metrics.csv",
        parity=f"{RESULTS}/surrogate/parity.png",
    params:
        training=lambda wildcards: CFG.surrogate_training().to_dict(),
    log:
        f"{RESULTS}/logs/train_surrogate.log",
    threads: 2
    conda:
        "../envs/surrogate.yaml"
    script:
        "../workflow/scripts/train_surrogate.py"
