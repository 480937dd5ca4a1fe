"""Coupled PBM-DEM and PBM-ANN loops: the validation study of the seed paper (docs/validation.md).

| module | concept |
| --- | --- |
| `sample` | the representative DEM sample of a PBM size distribution |
| `class_source` | class frequencies of an interval interpolated onto the PBM bins |
| `providers` | frequencies of a sample from LIGGGHTS (PBM-DEM) or the surrogate (PBM-ANN) |
| `intervals` | finished intervals on disk (save, resume, discard when inputs change) |
| `loop` | the PBM over coupling intervals with a provider |
| `methods` | PBM-DEM, PBM-ANN and the calibrated PBM-constant |
| `sweep` | the PBM-ANN impeller-speed sweep |
| `studies` | the PBM-ANN studies of the findings (speed, feed, breakage) |
| `lumping` | PBM-ANN with the lumped (1-D) and the size x liquid (2-D) PBM side by side |
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
