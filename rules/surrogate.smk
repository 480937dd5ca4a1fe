# Reduced-order model: MLP encounter surrogate (encounter frequency and impact-velocity
# distribution per class pair) trained on the DEM grid. Depends on the aggregated collision and
# impact-velocity tables only: adding operating points changes those tables and retrains the surrogate. The surrogate settings and the impeller radius are params, so
# changing them in the config also triggers a retrain (Snakemake's params rerun trigger).

rule train_surrogate:
    input:
        table="results/dem/collisions.csv",
        velocity="results/dem/impact_velocity.csv",
    output:
        model="results/surrogate/model.skops",
        metadata="results/surrogate/model.json",
        metrics="results/surrogate/metrics.csv",
        parity="results/surrogate/parity.png",
    params:
        settings=lambda wildcards: canonical(config.get("surrogate", {})),
        impeller_radius=lambda wildcards: config["granulator"]["impeller"]["blade_length"],
    log:
        "results/logs/train_surrogate.log",
    threads: 2
    conda:
        "../envs/surrogate.yaml"
    script:
        "../workflow/scripts/train_surrogate.py"
