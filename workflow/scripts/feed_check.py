"""Snakemake rule feed_check: PBM-DEM against PBM-ANN for the feed check's case, and whether it is
still the feed study's most surprising case (thin)."""

import logging
from pathlib import Path

from pbmdem.atomic import write_csv
from pbmdem.joblog import log_job
from pbmdem.readers import read_table
from pbmdem.validation.feed_check import STUDY_COLUMNS, check_table, dem_finals

sm = snakemake  # noqa: F821
log_job(sm.log[0])
ann = read_table(sm.input.ann, "PBM-ANN feed-check table", columns=STUDY_COLUMNS)
study = read_table(sm.input.study, "PBM-ANN feed study", columns=STUDY_COLUMNS)
dem = dem_finals(Path(f).parent for f in sm.input.dem)
table = check_table(sm.params.feed, sm.params.rpm, ann, dem, study, sm.params.feed_study_rpm)
write_csv(sm.output.table, table)
row = table.iloc[0]
log = logging.getLogger("pbmdem.validation.feed_check")
log.info(
    "feed check at %g rpm: %s; PBM-DEM confirms it: %s (%d of %d replicates)",
    row.rpm,
    row.statement,
    row.dem_confirms,
    row.dem_replicates_confirming,
    row.dem_replicates,
)
if not row.is_most_surprising:
    log.warning(
        "validation.feed_check.feed = %r is no longer the feed study's most surprising case: by the rule it is %r (%s)",
        row.feed,
        row.most_surprising,
        row.most_surprising_statement,
    )
