# PBM stage: the batch granulation with the constant collision-frequency kernel for every
# operating point of the grid (impeller speed x size distribution). The constant kernel does not
# depend on rpm (c_ij is the same), but each point is run so that the constant-kernel baseline
# sits beside the DEM/ANN-kernel results of the same point id. The pbm section and the parts of
# the config that fix the initial bed are params, so changing them reruns the rule.
#
# Rule pbm_table runs the same batch with the DEM grid's collision table as the frequency source
# (encounter frequency per pair, interpolated in size and rpm) and its impact-velocity table
# (needed by pbm.aggregation.success.velocity_model: stokes). It is not a default target: ask for
# results/pbm/table/rpm<rpm>_<dist>/summary.csv.


rule pbm_constant:
    output:
        summary=f"{RESULTS}/pbm/constant/rpm{{rpm}}_{{dist}}/summary.csv",
        bins=f"{RESULTS}/pbm/constant/rpm{{rpm}}_{{dist}}/bins.csv",
        info=f"{RESULTS}/pbm/constant/rpm{{rpm}}_{{dist}}/run.json",
        psd=f"{RESULTS}/pbm/constant/rpm{{rpm}}_{{dist}}/psd.png",
        d50=f"{RESULTS}/pbm/constant/rpm{{rpm}}_{{dist}}/d50.png",
    params:
        config=pbm_params,
        kernel="constant",
        rpm=lambda wc: float(wc.rpm),
        dist=lambda wc: wc.dist,
    log:
        f"{RESULTS}/logs/pbm/constant/rpm{{rpm}}_{{dist}}.log",
    conda:
        "../envs/pbm.yaml"
    script:
        "../workflow/scripts/run_pbm.py"


extra_targets += pbm_constant_outputs()


rule pbm_table:
    input:
        table=f"{RESULTS}/dem/collisions.csv",
        velocities=f"{RESULTS}/dem/impact_velocity.csv",
    output:
        summary=f"{RESULTS}/pbm/table/rpm{{rpm}}_{{dist}}/summary.csv",
        bins=f"{RESULTS}/pbm/table/rpm{{rpm}}_{{dist}}/bins.csv",
        info=f"{RESULTS}/pbm/table/rpm{{rpm}}_{{dist}}/run.json",
        psd=f"{RESULTS}/pbm/table/rpm{{rpm}}_{{dist}}/psd.png",
        d50=f"{RESULTS}/pbm/table/rpm{{rpm}}_{{dist}}/d50.png",
    params:
        config=pbm_params,
        kernel="table",
        rpm=lambda wc: float(wc.rpm),
        dist=lambda wc: wc.dist,
    log:
        f"{RESULTS}/logs/pbm/table/rpm{{rpm}}_{{dist}}.log",
    conda:
        "../envs/pbm.yaml"
    script:
        "../workflow/scripts/run_pbm.py"
