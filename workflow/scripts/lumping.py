"""Snakemake rule lumping: PBM-ANN with the lumped (1-D) and the size x liquid (2-D) PBM side by
side on the default batch, the speed study, the design space's binder rates and the feeds (thin)."""

from pbmdem.atomic import write_csv, write_json
from pbmdem.config import CoupledLoop, SizeDistribution
from pbmdem.coupling.lumping import lumping_study
from pbmdem.joblog import log_job

sm = snakemake  # noqa: F821
# one line per case: final d50 of both models, their relative difference, CPU seconds
log_job(sm.log[0])
feeds = {name: SizeDistribution.from_dict(sizes) for name, sizes in sm.params.feeds.items()}
cases, liquid, info = lumping_study(
    CoupledLoop.from_dict(sm.params.loop),
    sm.input.model,
    sm.params.rpm,
    sm.params.speeds,
    sm.params.liquid_rates,
    feeds,
)
write_csv(sm.output.cases, cases)
write_csv(sm.output.liquid, liquid)
write_json(sm.output.info, info)
