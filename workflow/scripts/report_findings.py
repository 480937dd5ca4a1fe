"""Snakemake rule report_findings: the figures and words the report opens with (thin)."""

from pbmdem.joblog import log_job
from pbmdem.report.findings import write_findings

sm = snakemake  # noqa: F821
log_job(sm.log[0])
write_findings(
    speed=sm.input.speed,
    feed=sm.input.feed,
    comparison=sm.input.comparison,
    speed_feed=sm.params.speed_feed,
    feed_rpm=sm.params.feed_rpm,
    batch_s=sm.params.batch_s,
    breakage=sm.input.breakage,
    training=sm.input.training,
    metadata=sm.input.metadata,
    feed_check=sm.input.get("feed_check"),
    sensitivity=sm.input.sensitivity,
    sensitivity_info=sm.input.sensitivity_info,
    confidence=sm.params.confidence,
    lumping=sm.input.lumping,
    lumping_liquid=sm.input.lumping_liquid,
    lumping_info=sm.input.lumping_info,
    out={
        "speed_png": sm.output.speed_png,
        "feed_png": sm.output.feed_png,
        "breakage_png": sm.output.breakage_png,
        "lumping_png": sm.output.lumping_png,
        "lumping_csv": sm.output.lumping_csv,
        "lumping_html": sm.output.lumping_html,
        "rst": sm.output.rst,
    },
)
