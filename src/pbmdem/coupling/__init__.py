"""Coupled PBM-DEM and PBM-ANN loops: the validation study of the seed paper (docs/validation.md).

Its modules, one concept each: docs/architecture.md ("Packages and modules").
"""

from .loop import CouplingError, run_loop
from .methods import calibrated_frequency, pbm_ann, pbm_ann_members, pbm_constant, pbm_dem, warm_batch_times
from .sample import DemSample, representative_sample

__all__ = [
    "CouplingError",
    "run_loop",
    "pbm_dem",
    "pbm_ann",
    "pbm_ann_members",
    "pbm_constant",
    "calibrated_frequency",
    "warm_batch_times",
    "DemSample",
    "representative_sample",
]
