"""Snakemake rule report: the self-contained HTML report (thin)."""

from pbmdem import report

report.build_report(
    validation_dir=snakemake.params.validation_dir,  # noqa: F821
    rpms=snakemake.params.rpms,  # noqa: F821
    replicates=snakemake.params.replicates,  # noqa: F821
    runs=snakemake.input.runs,  # noqa: F821
    collisions=snakemake.input.collisions,  # noqa: F821
    metrics=snakemake.input.metrics,  # noqa: F821
    parity=snakemake.input.parity,  # noqa: F821
    metadata=snakemake.input.metadata,  # noqa: F821
    model=snakemake.input.model,  # noqa: F821
    sweep=snakemake.input.sweep,  # noqa: F821
    sweep_plot=snakemake.input.sweep_plot,  # noqa: F821
    comparison=snakemake.input.comparison,  # noqa: F821
    html=snakemake.output.html,  # noqa: F821
    speed_study={
        "table": snakemake.input.speed_response,  # noqa: F821
        "flow": snakemake.input.flow_development,  # noqa: F821
        "plot": snakemake.input.speed_plot,  # noqa: F821
        "velocity_plot": snakemake.input.velocity_plot,  # noqa: F821
    },
)
