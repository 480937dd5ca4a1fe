"""Single-threaded BLAS/OpenMP for the surrogate's tiny matrices.

Fitting MLPs on tens of rows is dominated by thread synchronisation: with multi-threaded OpenBLAS
on a two-core machine whose cores are busy with DEM runs, the surrogate tests ran 15x slower
(106 s instead of 7 s) than with one thread. Parallelism is instead at the job level
(``n_jobs`` of the grid search, Snakemake jobs).
"""

from __future__ import annotations

from threadpoolctl import ThreadpoolController

_controller = None


def single_threaded():
    """Context manager limiting BLAS and OpenMP pools to one thread (cheap after the first call)."""
    global _controller
    if _controller is None:
        _controller = ThreadpoolController()
    return _controller.limit(limits=1)
