"""Snakemake rule pbm_ann_studies: PBM-ANN's final sizes against impeller speed (with and without
breakage) and against the feed (thin)."""

from pbmdem.atomic import write_csv
from pbmdem.config import CoupledLoop, SizeDistribution
from pbmdem.coupling.studies import breakage_study, feed_study, speed_study
from pbmdem.joblog import log_job

sm = snakemake  # noqa: F821
# one line per case (speed or feed): final d50, the members' range, domain status, wall time
log_job(sm.log[0])
loop = CoupledLoop.from_dict(sm.params.loop)
write_csv(sm.output.speed, speed_study(loop, sm.input.model, sm.params.speeds, sm.params.grid_speeds))
feeds = {name: SizeDistribution.from_dict(sizes) for name, sizes in sm.params.feeds.items()}
write_csv(sm.output.feed, feed_study(loop, sm.input.model, sm.params.feed_rpm, feeds))
# final sizes against speed without breakage, with it, and with Y and St_def* halved and doubled
write_csv(sm.output.breakage, breakage_study(loop, sm.input.model, sm.params.speeds, sm.params.grid_speeds))
