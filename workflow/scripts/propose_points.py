"""Snakemake rule propose_points: the next operating points (active learning) as a config fragment."""

import logging

from pbmdem.atomic import write_csv
from pbmdem.config import Granulator, OperatingGrid, SizeDistribution
from pbmdem.joblog import rule_job
from pbmdem.surrogate import load_surrogate
from pbmdem.tables import INTERVALS
from pbmdem.validation import proposals

sm = snakemake  # noqa: F821
with rule_job(sm.log[0]):
    surrogate = load_surrogate(sm.input.model)
    found = []
    for rpm, path in zip(sm.params.rpms, sm.input.intervals):
        found += proposals.assess(surrogate, float(rpm), INTERVALS.read(path, "PBM-ANN interval record"))
    grid = OperatingGrid.from_dict(sm.params.grid, "grid")
    distributions = {name: SizeDistribution.from_dict(d, name) for name, d in sm.params.distributions.items()}
    table = proposals.propose(
        grid,
        Granulator.from_dict(sm.params.granulator, "granulator"),
        distributions,
        found,
        sm.params.max_points,
    )
    write_csv(sm.output.table, table)
    proposals.write_fragment(
        grid,
        table,
        sm.output.fragment,
        source=", ".join(str(p) for p in sm.input.intervals),
    )
    logging.info("proposed %d size distribution(s): %s", len(table), ", ".join(table["name"]))
