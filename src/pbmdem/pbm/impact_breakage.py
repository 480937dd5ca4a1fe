"""Breakage selection from the DEM's impacts: :class:`ImpactSelection`.

A granule breaks in an impact that deforms it beyond what its binder can hold. The Stokes
deformation number of an impact at normal speed v,

    St_def = rho v^2 / (2 Y),

is the impact's kinetic energy per granule volume over the granule's dynamic yield strength Y
(Tardos, Khan & Mort 1997, Powder Technol. 94, 245-258; Iveson, Litster, Hapgood & Ennis 2001,
Powder Technol. 117, 3-39); granules break when St_def exceeds a critical St_def*, i.e. when v
exceeds the critical speed v* = sqrt(2 Y St_def* / rho). The selection rate of a granule of
class i (1/s) sums, over the kinds of impact k it suffers, its impact rate of that kind times
the fraction of those impacts faster than v*:

    S_i = sum_j c_ij (N_j - delta_ij) P_ij  +  sum_w f_wi P_wi,

with c_ij the encounter frequency per pair, N_j the granules of class j, f_wi the impacts per
granule on wall w (impeller, bowl) and P the fraction of the impact-velocity distribution above v*
(:func:`pbmdem.impact.fraction_above`: impacts spread evenly in log v inside a bin). The impact
statistics come from the frequency source's ``impacts(diameters, numbers, rpm)`` (DEM tables,
a coupling interval's DEM run or the surrogate), evaluated at the bins' pivots.

Y may depend on the granule's size d and porosity eps (both factors are 1 at d_ref and eps_ref):

    Y(d, eps) = Y (d / d_ref)^(-e) [((1 - eps) / eps) / ((1 - eps_ref) / eps_ref)]^n,

so v* scales with the square root of both factors. The porosity factor is the strengthening of a
wet granule as it consolidates: Rumpf's (1962) tensile strength of a capillary-bound aggregate
grows as (1 - eps) / eps (n = 1), the viscous dynamic yield strength of wet granules as
((1 - eps) / eps)^2 (n = 2; Iveson, Litster, Hapgood & Ennis 2001). eps is each pivot's
aggregate porosity G / (S + G) (``KernelInput.porosity``), eps_ref where a pivot is empty.
"""

from __future__ import annotations

import numpy as np

from pbmdem.config import Pbm
from pbmdem.impact import N_VELOCITY_BINS, VELOCITY_EDGES, WALLS, ImpactRates, breaking_probability

from . import _compiled_selection
from .errors import PBMInputError, positive
from .kernels import KernelInput

#: porosities are kept in [POROSITY_LIMIT, 1 - POROSITY_LIMIT] by the porosity-dependent strength
POROSITY_LIMIT = 1e-6


def critical_speed(density: float, yield_strength: float, critical_stokes: float) -> float:
    """v* = sqrt(2 Y St_def* / rho) (m/s): the slowest impact with St_def above St_def*."""
    return float(np.sqrt(2.0 * yield_strength * critical_stokes / density))


def selection_rates(
    rates: ImpactRates, numbers, speed: float, walls=WALLS, pairs: bool = True, spread: float = 0.0
) -> dict[str, np.ndarray]:
    """(K,) breaking impacts per granule and second of each class, per kind of impact: ``pairs``
    (summed over the partner classes) and each wall of ``walls``; ``speed`` is v* (m/s) of the
    median granule (or (K,), one per class), ``spread`` the standard deviation of ln Y across granules (0: the sharp
    criterion; :func:`pbmdem.impact.breaking_probability`)."""
    n = np.asarray(numbers, float)
    K = n.size
    # (K, V): the probability of each class's granule breaking in an impact of each bin
    above = np.broadcast_to(breaking_probability(speed, spread), (K, N_VELOCITY_BINS))
    out: dict[str, np.ndarray] = {}
    if pairs:
        # (K, K) fraction of each pair's impacts that break granule i
        breaking = np.einsum("ijb,ib->ij", rates.pairs.velocity_fractions, above)
        partners = np.maximum(n[None, :] - np.eye(K), 0.0)  # a granule does not meet itself
        out["pairs"] = (rates.pairs.frequency * breaking * partners).sum(axis=1)
    for wall in walls:
        frequency, fractions = rates.walls.of(wall)
        out[wall] = frequency * (fractions * above).sum(axis=1)
    return out


class ImpactSelection:
    """Selection rate S_i (1/s per granule) of each bin's pivot from the impacts of ``source``.

    ``source`` offers ``impacts(diameters, numbers, rpm) -> pbmdem.impact.ImpactRates``;
    ``density`` (kg/m3) the granule density, ``yield_strength`` Y (Pa) the granule's dynamic yield
    strength, ``critical_stokes`` St_def*; ``walls`` the walls whose impacts can break a granule
    (of "impeller", "bowl"); ``pairs`` whether granule-granule encounters can; ``strength_spread``
    the standard deviation of ln Y across granules (log-normal strengths: an impact at v breaks
    with probability Phi(2 ln(v / v*) / spread), v* that of the median granule; 0: every impact
    above v* breaks, none below); ``size_exponent`` e: Y of a granule of diameter d is
    Y (d / reference_diameter)^(-e) (0: the same for every size); ``porosity_exponent`` n: Y of a
    granule of porosity eps is Y [((1 - eps) / eps) / ((1 - eps_ref) / eps_ref)]^n with eps_ref =
    ``reference_porosity`` (0: the same at every porosity; 1: Rumpf's capillary strength, 2: the
    viscous strength of Iveson et al. 2001). :meth:`prepare`
    (at every step) asks the source for the impacts only when the pivots, the speed or the source
    (:meth:`set_source`, a coupling interval's) changed; a call weights them with the current
    numbers (the pair term)."""

    #: its impacts are fixed for the pivots and the speed and its rates are those of
    #: ``_compiled_selection.selection_of_impacts``: the compiled step loop evaluates it (``pbm.fast_steps``)
    compiled_steps = True

    def __init__(
        self,
        source,
        density: float,
        yield_strength: float,
        critical_stokes: float,
        walls=("impeller", "bowl"),
        pairs: bool = True,
        strength_spread: float = 0.0,
        size_exponent: float = 0.0,
        reference_diameter: float = 0.002,
        porosity_exponent: float = 0.0,
        reference_porosity: float = 0.5,
    ):
        self.density = positive("granule density (kg/m3)", density)
        self.yield_strength = positive("granule dynamic yield strength Y (Pa)", yield_strength)
        self.critical_stokes = positive("critical Stokes deformation number St_def*", critical_stokes)
        unknown = [w for w in walls if w not in WALLS]
        if unknown:
            raise PBMInputError(f"breakage walls {list(walls)}: {unknown} unknown; allowed: {list(WALLS)}")
        self.walls = tuple(walls)
        self.pairs = bool(pairs)
        self.strength_spread = positive("spread of ln Y across granules", strength_spread, allow_zero=True)
        self.size_exponent = positive("strength size exponent", size_exponent, allow_zero=True)
        self.reference_diameter = positive("reference diameter of Y (m)", reference_diameter)
        self.porosity_exponent = positive("strength porosity exponent", porosity_exponent, allow_zero=True)
        eps_ref = float(reference_porosity)
        if not 0.0 < eps_ref < 1.0:
            raise PBMInputError(f"reference porosity of Y = {reference_porosity!r}; allowed: 0 < porosity < 1")
        self.reference_porosity = eps_ref
        self.speed = critical_speed(self.density, self.yield_strength, self.critical_stokes)
        # the compiled selection's strength parameters (_compiled_selection.STRENGTH_FIELDS) and "no porosity"
        strength = dict(vars(self), limit=POROSITY_LIMIT)
        self._strength = np.array([float(strength[k]) for k in _compiled_selection.STRENGTH_FIELDS])
        self._no_porosity = np.zeros(0)
        self.set_source(source)

    def __repr__(self) -> str:
        porosity = ""
        if self.porosity_exponent != 0.0:
            porosity = f", porosity exponent={self.porosity_exponent:g} (eps_ref={self.reference_porosity:g})"
        return (
            f"ImpactSelection(Y={self.yield_strength:g} Pa, St_def*={self.critical_stokes:g}, "
            f"v*={self.speed:.3g} m/s, spread of ln Y={self.strength_spread:g}, walls={list(self.walls)}, "
            f"pairs={self.pairs}, source={self.source!r}{porosity})"
        )

    def set_source(self, source) -> None:
        """Use ``source`` from the next :meth:`prepare` on (a coupling interval's impacts; None:
        none yet, the loop sets it before the first step)."""
        if source is not None and not callable(getattr(source, "impacts", None)):
            raise PBMInputError(
                f"breakage from impacts needs a source with impacts(diameters, numbers, rpm); {source!r} has none"
            )
        self.source = source
        self._rates = None
        self._key = None

    def prepare(self, inp: KernelInput) -> None:
        """Fetch the impacts of the bins' pivots from the source, unless it gave them already."""
        if self.source is None:
            raise PBMInputError("ImpactSelection has no source of impacts yet (set_source)")
        d, n = inp.per_bin()
        key = (np.asarray(d, float).tobytes(), float(inp.rpm))
        if self._rates is not None and key == self._key:
            return
        rates = self.source.impacts(d, n, inp.rpm)
        if not isinstance(rates, ImpactRates) or rates.pairs.frequency.shape[0] != d.size:
            raise PBMInputError(
                f"{self.source!r}.impacts gave {type(rates).__name__}, not ImpactRates of {d.size} bins"
            )
        self._rates, self._key = rates, key
        # the compiled selection's arguments: contiguous arrays, the walls that can break a granule
        walls = rates.walls
        rows = [walls.walls.index(w) for w in self.walls]
        shape = (len(rows), d.size)
        self._arrays = (
            np.ascontiguousarray(rates.pairs.frequency, dtype=float),
            np.ascontiguousarray(rates.pairs.velocity_fractions, dtype=float),
            np.ascontiguousarray(walls.frequency[rows], dtype=float).reshape(shape),
            np.ascontiguousarray(walls.velocity_fractions[rows], dtype=float).reshape(*shape, N_VELOCITY_BINS),
        )
        self._columns = _compiled_selection.fraction_columns(self._arrays[1])
        self._work = (np.empty(d.size), np.empty((d.size, N_VELOCITY_BINS)))

    def _porosity(self, inp: KernelInput) -> np.ndarray | None:
        """The porosity of each pivot's aggregates (feed granules do not break), or None when the
        strength does not depend on porosity."""
        if self.porosity_exponent == 0.0:
            return None
        if inp.porosity is None:
            raise PBMInputError(
                "a strength that depends on porosity (porosity_exponent > 0) needs the classes' porosity "
                "in the KernelInput; it has none"
            )
        return inp.porosity[: inp.pivots]

    def __call__(self, inp: KernelInput) -> np.ndarray:
        """S_i of every pivot: the sum over the kinds of impact of :func:`selection_rates`, in one compiled call
        (``_compiled_selection.selection_of_impacts``: v*, the breaking probability per velocity bin, the sum
        over the impacts)."""
        if self._rates is None:
            self.prepare(inp)
        d, n = inp.per_bin()
        eps = self._porosity(inp)
        eps = self._no_porosity if eps is None else np.ascontiguousarray(eps, dtype=float)
        out = np.empty(d.size)
        _compiled_selection.selection_of_impacts(
            np.ascontiguousarray(d, dtype=float),
            eps,
            self._strength,
            self.strength_spread,
            VELOCITY_EDGES,
            self._arrays[0],
            self._arrays[1],
            self._columns,
            *self._arrays[2:],
            np.ascontiguousarray(n, dtype=float),
            self.pairs,
            *self._work,
            out,
        )
        return out


def impact_selection(pbm: Pbm, source=None) -> ImpactSelection | None:
    """The ImpactSelection of the ``pbm.breakage`` settings (Y, St_def*, walls, pairs, strength_spread, its
    size and porosity dependence) on
    ``source`` (None: set later), with the granule density of the Stokes success model
    (``pbm.aggregation.success.stokes.granule_density``, the DEM particle density); None when breakage
    is off."""
    brk = pbm.breakage
    if not brk.enabled:
        return None
    density = pbm.aggregation.success.stokes.granule_density
    return ImpactSelection(
        source,
        density,
        brk.yield_strength,
        brk.critical_stokes,
        brk.walls,
        brk.pairs,
        brk.strength_spread,
        brk.strength_size_exponent,
        brk.reference_diameter,
        brk.strength_porosity_exponent,
        brk.reference_porosity,
    )
