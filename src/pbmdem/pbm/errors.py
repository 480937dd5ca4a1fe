"""Exceptions of the population balance model. All are ``ValueError`` subclasses, so the
``pbmdem`` command line reports them as ordinary input errors. Each message names the offending
value and what is allowed."""

from __future__ import annotations


class PBMError(ValueError):
    """Base class of every PBM error."""


class PBMInputError(PBMError):
    """A parameter is out of its allowed range (e.g. a zero or negative rate)."""


class GridRangeError(PBMError):
    """Particles (e.g. the initial distribution) lie outside the pivot range of the grid."""


class GridOverflowError(PBMError):
    """Aggregates beyond the last bin carried more solid than the allowed fraction."""


class KernelShapeError(PBMError):
    """A kernel or collision-frequency source returned a matrix of the wrong shape, a
    non-symmetric, negative or non-finite matrix."""


class NegativePopulationError(PBMError):
    """A number, liquid or gas entry became negative or NaN during the integration."""


def positive(name: str, value, allow_zero: bool = False) -> float:
    """``float(value)`` if it is finite and > 0 (>= 0 with ``allow_zero``), else PBMInputError."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise PBMInputError(
            f"{name} = {value!r} is not a number; allowed: a finite number {'>= 0' if allow_zero else '> 0'}"
        ) from None
    ok = v >= 0 if allow_zero else v > 0
    if not (ok and v == v and v != float("inf")):
        raise PBMInputError(
            f"{name} = {value!r} is not allowed; allowed: a finite number {'>= 0' if allow_zero else '> 0'}"
        )
    return v


class SolverLimitError(PBMError):
    """A run exceeded its step or wall-time guard (``solver.max_steps`` / ``solver.max_wall_time``)."""
