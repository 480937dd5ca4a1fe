"""Snakemake rule feed_check_ann: PBM-ANN (ensemble mean and members) for the feed check's case and
its parent feeds (thin)."""

from pbmdem.atomic import write_csv
from pbmdem.config import CoupledLoop, SizeDistribution
from pbmdem.coupling.studies import feed_case_study
from pbmdem.joblog import log_job

sm = snakemake  # noqa: F821
log_job(sm.log[0])
feeds = {name: SizeDistribution.from_dict(sizes) for name, sizes in sm.params.feeds.items()}
loop = CoupledLoop.from_dict(sm.params.loop)
write_csv(sm.output.table, feed_case_study(loop, sm.input.model, float(sm.params.rpm), feeds, sm.params.feed))
