"""Breakage selection from the DEM's impacts (:class:`ImpactSelection`): a granule breaks in an
impact whose Stokes deformation number rho v^2 / (2 Y) exceeds St_def*. docs/pbm.md ("Breakage
selection from impacts") gives the selection rate, the size and porosity dependence of Y and the
references."""

from __future__ import annotations

import numpy as np

from pbmdem.config import Pbm
from pbmdem.impact import N_VELOCITY_BINS, VELOCITY_EDGES, WALLS, ImpactRates, breaking_probability

from . import _compiled_selection
from .errors import PBMInputError
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
    """Selection rate S_i (1/s per granule) of each bin's pivot from the impacts of ``source``
    (``impacts(diameters, numbers, rpm) -> pbmdem.impact.ImpactRates``); the parameters are those of
    ``pbm.breakage`` (``pbmdem.config.pbm.BreakageSettings`` describes each; docs/pbm.md, "Breakage
    selection from impacts"). :meth:`prepare` asks the source for the impacts only when the pivots, the
    speed or the source (:meth:`set_source`) changed; a call weights them with the current numbers."""

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
        self.density, self.yield_strength, self.critical_stokes = (
            float(density),
            float(yield_strength),
            float(critical_stokes),
        )
        self.walls, self.pairs = tuple(walls), bool(pairs)
        self.strength_spread, self.size_exponent = float(strength_spread), float(size_exponent)
        self.reference_diameter, self.porosity_exponent = float(reference_diameter), float(porosity_exponent)
        self.reference_porosity = float(reference_porosity)
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
