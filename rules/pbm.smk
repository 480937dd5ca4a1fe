# PBM stage: the batch granulation with the constant collision-frequency kernel for every
# operating point of the grid (impeller speed x size distribution). The constant kernel does not
# depend on rpm (c_ij is the same), but each point is run so that the constant-kernel baseline
# sits beside the DEM/ANN-kernel results of the same point id. The params are what a batch uses
# (pbm settings, the bed's solid volume, the feed), so changing them reruns the rule.
#
# Rule pbm_table runs the same batch with the DEM grid's collision table as the frequency source
# (encounter frequency per pair, interpolated in size and rpm) and its impact-velocity table
# (needed by pbm.aggregation.success.velocity_model: stokes). It is not a default target: ask for
# results/pbm/table/rpm<rpm>_<dist>/summary.csv.


rule pbm_constant:
    output:
        **pbm_outputs("constant"),
    log:
        layout.log("pbm/constant/rpm{rpm}_{dist}.log"),
    conda:
        "../envs/pbm.yaml"
    params:
        batch=pbm_batch_params,
        kernel="constant",
    script:
        "../workflow/scripts/run_pbm.py"


extra_targets += [
    f"{layout.pbm_run('constant', rpm, dist)}/summary.csv" for rpm, dist in grid_points()
]


rule pbm_table:
    input:
        table=layout.dem("collisions.csv"),
        velocities=layout.dem("impact_velocity.csv"),
    output:
        **pbm_outputs("table"),
    log:
        layout.log("pbm/table/rpm{rpm}_{dist}.log"),
    conda:
        "../envs/pbm.yaml"
    params:
        batch=pbm_batch_params,
        kernel="table",
    script:
        "../workflow/scripts/run_pbm.py"
