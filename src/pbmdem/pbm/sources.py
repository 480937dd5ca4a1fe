"""Collision-frequency sources besides the DEM table (:class:`ConstantFrequency`) and the checks of
what any source returns (:func:`check_frequency_matrix`, :func:`check_encounter_rates`): the
interface ``source(diameters (K,), numbers (K,), rpm) -> (K, K)`` of docs/architecture.md."""

from __future__ import annotations

import numpy as np

from pbmdem.impact import N_VELOCITY_BINS, EncounterRates, velocity_bin
from pbmdem.readers import first_index

from .errors import KernelShapeError, PBMInputError, positive

SYMMETRY_RTOL = 1e-8


def check_frequency_matrix(c, K: int, name: str) -> np.ndarray:
    """Validate what a collision-frequency source returned: (K, K), finite, >= 0, symmetric."""
    c = np.asarray(c, dtype=float)
    if c.shape == (K, K) and c.size and c.min() >= 0.0 and c.max() < 1e307 and np.array_equal(c, c.T):
        # the usual case (finite, >= 0 and symmetric to the bit): 0.5 (c + c^T) is c itself
        return c.copy()
    if c.shape != (K, K):
        raise KernelShapeError(
            f"collision-frequency source {name} returned shape {c.shape}; expected "
            f"({K}, {K}) for {K} bins (one c_ij per bin pair)"
        )
    if (at := first_index(~np.isfinite(c))) is not None:
        i, j = at
        raise KernelShapeError(
            f"collision-frequency source {name} returned a non-finite value "
            f"c[{i},{j}] = {c[i, j]}; allowed: finite values >= 0 (1/s per pair)"
        )
    if (at := first_index(c < 0)) is not None:
        i, j = at
        raise KernelShapeError(
            f"collision-frequency source {name} returned a negative value "
            f"c[{i},{j}] = {c[i, j]:.6g}; allowed: values >= 0 (1/s per pair)"
        )
    diff = np.abs(c - c.T)
    tol = SYMMETRY_RTOL * np.maximum(np.abs(c), np.abs(c.T)) + 1e-300
    if (at := first_index(diff > tol)) is not None:
        i, j = at
        raise KernelShapeError(
            f"collision-frequency source {name} returned a non-symmetric matrix: "
            f"c[{i},{j}] = {c[i, j]:.6g} but c[{j},{i}] = {c[j, i]:.6g}; c_ij must "
            f"equal c_ji within relative {SYMMETRY_RTOL:g}"
        )
    return 0.5 * (c + c.T)


def check_encounter_rates(rates, K: int, name: str):
    """Validate what ``source.encounters`` returned: an EncounterRates whose frequency passes
    :func:`check_frequency_matrix` and whose (K, K, V) velocity fractions are finite, >= 0,
    symmetric in (i, j) and sum to 1 (or to 0 for a pair without encounters) over the bins.
    Returns (frequency, fractions), both symmetrised."""
    for attr in ("frequency", "velocity_fractions"):
        if not hasattr(rates, attr):
            raise KernelShapeError(
                f"collision-frequency source {name}.encounters returned {type(rates).__name__} "
                f"without {attr!r}; expected a pbmdem.impact.EncounterRates"
            )
    c = check_frequency_matrix(rates.frequency, K, name + ".encounters")
    f = np.asarray(rates.velocity_fractions, dtype=float)
    if f.shape != (K, K, N_VELOCITY_BINS):
        raise KernelShapeError(
            f"collision-frequency source {name}.encounters returned velocity fractions of "
            f"shape {f.shape}; expected ({K}, {K}, {N_VELOCITY_BINS})"
        )
    if (at := first_index(~np.isfinite(f) | (f < 0))) is not None:
        i, j, b = at
        raise KernelShapeError(
            f"collision-frequency source {name}.encounters returned velocity fraction "
            f"[{i},{j},{b}] = {f[i, j, b]!r}; allowed: finite values >= 0"
        )
    total = f.sum(axis=2)
    off = (np.abs(total - 1.0) > 1e-8) & (total != 0.0)
    if (at := first_index(off)) is not None:
        i, j = at
        raise KernelShapeError(
            f"collision-frequency source {name}.encounters: the velocity fractions of pair "
            f"({i}, {j}) sum to {total[i, j]:.10g}; allowed: 1 (or 0 for a pair without data)"
        )
    if (at := first_index(np.abs(f - f.transpose(1, 0, 2)) > 1e-8)) is not None:
        i, j, b = at
        raise KernelShapeError(
            f"collision-frequency source {name}.encounters: velocity fractions are not "
            f"symmetric: [{i},{j},{b}] = {f[i, j, b]:.6g} but [{j},{i},{b}] = {f[j, i, b]:.6g}"
        )
    return c, 0.5 * (f + f.transpose(1, 0, 2))


class ConstantFrequency:
    """c_ij = value for every pair (1/s per pair).

    ``impact_velocity`` (m/s, optional): one impact speed for every encounter; it enables
    :meth:`encounters` (all encounters in the velocity bin of that speed), so that the constant
    baseline can run with a velocity-dependent success probability.
    """

    def __init__(self, value: float, impact_velocity: float | None = None):
        self.value = positive("constant collision frequency", value)
        self.impact_velocity = (
            None if impact_velocity is None else positive("constant impact velocity (m/s)", impact_velocity)
        )

    def __repr__(self) -> str:
        vel = "" if self.impact_velocity is None else f", impact_velocity={self.impact_velocity:g}"
        return f"ConstantFrequency({self.value:g}{vel})"

    def __call__(self, diameters, numbers, rpm) -> np.ndarray:
        K = np.atleast_1d(diameters).size
        return np.full((K, K), self.value)

    def encounters(self, diameters, numbers, rpm):
        """EncounterRates: c_ij = value, every encounter in the bin of ``impact_velocity``."""
        if self.impact_velocity is None:
            raise PBMInputError(
                "ConstantFrequency.encounters needs an impact velocity (pbm.aggregation.constant_impact_velocity, m/s)"
            )
        K = np.atleast_1d(diameters).size
        f = np.zeros((K, K, N_VELOCITY_BINS))
        f[:, :, int(velocity_bin(self.impact_velocity))] = 1.0
        return EncounterRates(self(diameters, numbers, rpm), f)
