"""Snakemake rule propose_points: the next operating points (active learning) as a config fragment."""

import logging

from pbmdem.atomic import write_csv
from pbmdem.config import Granulator, OperatingGrid, SizeDistribution
from pbmdem.joblog import log_job
from pbmdem.surrogate import load_surrogate
from pbmdem.tables import INTERVALS
from pbmdem.validation import proposals

log_job(snakemake.log[0])  # noqa: F821
surrogate = load_surrogate(snakemake.input.model)  # noqa: F821
found = []
for rpm, path in zip(snakemake.params.rpms, snakemake.input.intervals):  # noqa: F821
    found += proposals.assess(surrogate, float(rpm), INTERVALS.read(path, "PBM-ANN interval record"))
grid = OperatingGrid.from_dict(snakemake.params.grid, "grid")  # noqa: F821
distributions = {name: SizeDistribution.from_dict(d, name) for name, d in snakemake.params.distributions.items()}  # noqa: F821
table = proposals.propose(
    grid,
    Granulator.from_dict(snakemake.params.granulator, "granulator"),  # noqa: F821
    distributions,
    found,
    snakemake.params.max_points,
)  # noqa: F821
write_csv(snakemake.output.table, table)  # noqa: F821
proposals.write_fragment(
    grid,
    table,
    snakemake.output.fragment,  # noqa: F821
    source=", ".join(str(p) for p in snakemake.input.intervals),
)  # noqa: F821
logging.info("proposed %d size distribution(s): %s", len(table), ", ".join(table["name"]))
