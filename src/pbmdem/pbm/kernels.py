"""Aggregation kernels: a kernel maps the population (:class:`KernelInput`) to the (K, K) symmetric
matrix beta_ij (1/s per pair): :class:`ConstantKernel`, :class:`SumKernel` (the closed forms of
tests/pbm_analytical.py) and :class:`CollisionKernel` beta0 c_ij psi_ij with c_ij from a
collision-frequency source (docs/architecture.md: ``sources``, ``table``, the surrogate)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from pbmdem.impact import representative_velocities

from .errors import PBMInputError, positive
from .sources import SYMMETRY_RTOL, ConstantFrequency, check_encounter_rates, check_frequency_matrix
from .success import SuccessProbability
from .table import FREQUENCY_COLUMN, TableFrequency

__all__ = [
    "FREQUENCY_COLUMN",
    "SYMMETRY_RTOL",
    "CollisionKernel",
    "ConstantFrequency",
    "ConstantKernel",
    "Kernel",
    "KernelFactors",
    "KernelInput",
    "SuccessProbability",
    "SumKernel",
    "TableFrequency",
    "check_encounter_rates",
    "check_frequency_matrix",
]


@dataclass
class KernelInput:
    """What a kernel may depend on at time ``t``: volumes (m3) and diameters (m), numbers and
    surface-liquid volume fraction of every class, and impeller speed (rpm).

    The classes are the grid's K pivots (``feed_weights`` None), or, with feed granules kept
    apart (docs/pbm.md, "Feed granules"), the K pivots followed by P feed classes at their own
    volumes; ``feed_weights`` (P, K) is then the lever rule of the feed classes onto the pivots
    (number fractions). A kernel returns the (K + P, K + P) matrix of the classes.

    ``porosity`` is the intra-granular porosity eps = G / (S + G) of every class (NaN where a class
    holds no solid; None: not given). Only a selection rate whose strength depends on porosity reads it
    (``pbm.impact_breakage.ImpactSelection``).
    """

    t: float
    volumes: np.ndarray
    diameters: np.ndarray
    numbers: np.ndarray
    surface_fraction: np.ndarray
    rpm: float
    feed_weights: np.ndarray | None = None
    porosity: np.ndarray | None = None

    @property
    def pivots(self) -> int:
        """Number of grid pivots K."""
        return self.volumes.size if self.feed_weights is None else self.feed_weights.shape[1]

    def per_bin(self) -> tuple[np.ndarray, np.ndarray]:
        """(diameters, numbers) of the K pivots; the numbers are the bin totals (aggregates and
        the feed classes put on the pivots by the lever rule). Computed once per input (the
        kernel and the breakage selection of a step read the same)."""
        cached = self.__dict__.get("_per_bin")
        if cached is None:
            if self.feed_weights is None:
                cached = (self.diameters, self.numbers)
            else:
                K = self.pivots
                cached = (self.diameters[:K], self.numbers[:K] + self.numbers[K:] @ self.feed_weights)
            self.__dict__["_per_bin"] = cached
        return cached


class KernelFactors(NamedTuple):
    """A kernel beta_ij = scaled_ij p(phi_i) p(phi_j) for the compiled rates (``Kernel.factors``):
    ``scaled`` (M, M) fixed until the kernel's next ``prepare``, and p the success ``model`` of
    :class:`SuccessProbability` ("always": p = 1) with its ``threshold`` and ``width``."""

    scaled: np.ndarray
    model: str = "always"
    threshold: float = 0.0
    width: float = 1.0


class Kernel:
    """Base class: ``kernel(inp) -> (K, K)``; ``prepare(inp)`` is called once at the start of every
    time step (a kernel may refresh cached data there), ``reset()`` at the start of every run.
    A kernel may return the same (cached) array from several calls: callers read it, never write it."""

    def prepare(self, inp: KernelInput) -> None:
        pass

    def reset(self) -> None:
        pass

    def __call__(self, inp: KernelInput) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def factors(self, inp: KernelInput) -> KernelFactors | None:
        """The :class:`KernelFactors` of this kernel at the step of ``inp`` (after ``prepare``):
        the model then evaluates the kernel inside its compiled rates instead of calling it. None
        (default): the model calls the kernel and passes its matrix to the same compiled rates."""
        return None


class ConstantKernel(Kernel):
    """beta_ij = beta0 (1/s per pair)."""

    def __init__(self, beta0: float):
        self.beta0 = positive("constant kernel beta0", beta0)
        self._cache: tuple[int, np.ndarray] | None = None

    def __repr__(self) -> str:
        return f"ConstantKernel(beta0={self.beta0:g})"

    def __call__(self, inp: KernelInput) -> np.ndarray:
        K = inp.volumes.size
        if self._cache is None or self._cache[0] != K:
            self._cache = (K, np.full((K, K), self.beta0))
        return self._cache[1]

    def factors(self, inp: KernelInput) -> KernelFactors:
        return KernelFactors(self(inp))


class SumKernel(Kernel):
    """Golovin's sum kernel beta_ij = b (v_i + v_j), b in 1/(m3 s)."""

    def __init__(self, b: float):
        self.b = positive("sum kernel b", b)
        self._cache: tuple[int, np.ndarray] | None = None

    def __repr__(self) -> str:
        return f"SumKernel(b={self.b:g})"

    def __call__(self, inp: KernelInput) -> np.ndarray:
        v = inp.volumes
        if self._cache is None or not np.array_equal(self._cache[0], v):
            self._cache = (v.copy(), self.b * (v[:, None] + v[None, :]))
        return self._cache[1]

    def factors(self, inp: KernelInput) -> KernelFactors:
        return KernelFactors(self(inp))


class CollisionKernel(Kernel):
    """beta_ij = beta0 c_ij psi_ij, or with a velocity-dependent success beta0 c_ij sum_b f_ij,b psi_ij(v_b)
    (docs/pbm.md, "Rate processes").

    ``source(diameters, numbers, rpm) -> (K, K)`` gives c_ij (1/s per pair) at the first step of a run
    and again every ``update_interval`` s (0: every step); a coupled loop swaps it (``set_source``).
    A velocity-dependent success needs ``source.encounters(...) -> pbmdem.impact.EncounterRates``
    (docs/architecture.md); a pair without velocity data gets beta_ij = 0."""

    def __init__(self, source, beta0: float, success: SuccessProbability | None = None, update_interval: float = 0.0):
        self.beta0 = float(beta0)
        self.success = success if success is not None else SuccessProbability()
        if self.success.velocity_dependent:
            self._speeds = representative_velocities()
        self._check_source(source)
        self.source = source
        self.update_interval = float(update_interval)
        self.evaluations = 0
        self.reset()

    def __repr__(self) -> str:
        return (
            f"CollisionKernel(source={self.source!r}, beta0={self.beta0:g}, success={self.success!r}, "
            f"update_interval={self.update_interval:g})"
        )

    def _check_source(self, source) -> None:
        if not callable(source):
            raise PBMInputError(
                f"collision-frequency source {source!r} is not callable; allowed: "
                "source(diameters, numbers, rpm) -> (K, K)"
            )
        if self.success.velocity_dependent and not callable(getattr(source, "encounters", None)):
            raise PBMInputError(
                f"the velocity-dependent success probability {self.success!r} needs impact "
                f"velocities, but the collision-frequency source {source!r} has no "
                "encounters(diameters, numbers, rpm) method; use a DEM table with its "
                "impact-velocity table, or success velocity_model: none"
            )

    def reset(self) -> None:
        self._c: np.ndarray | None = None
        self._fractions: np.ndarray | None = None
        self._classes: np.ndarray | None = None
        self._class_c = self._class_cumulative = None
        self._t_eval = -np.inf
        self._raw: np.ndarray | None = None  # the source's last matrix as returned (before the check)
        self._diameters: np.ndarray | None = None  # the pivots the source was last asked about
        self._beta_of = None  # the class matrix the cached products below belong to
        self._scaled = self._beta = self._beta_key = None

    def set_source(self, source) -> None:
        self._check_source(source)
        self.source = source
        self.reset()

    @property
    def velocity_fractions(self) -> np.ndarray | None:
        """The (K, K, V) velocity fractions in use (None before the first step or without a
        velocity-dependent success probability)."""
        return self._fractions

    @property
    def frequency(self) -> np.ndarray | None:
        """The c_ij matrix in use (None before the first step)."""
        return self._c

    def prepare(self, inp: KernelInput) -> None:
        # the source sees the grid's pivots and the bins' total numbers, with or without feed classes
        K = inp.pivots
        due = self._c is None or self._c.shape != (K, K) or inp.t >= self._t_eval + self.update_interval
        if due and self._c is not None and getattr(self.source, "fixed_for_diameters", False):
            # a source whose frequencies depend on the diameters alone (a coupling interval's
            # classes, ClassFrequencySource) gives the same matrix on the same pivots: not asked again
            d = inp.per_bin()[0]
            due = self._diameters is None or not np.array_equal(d, self._diameters)
            if not due:
                self._t_eval = inp.t
        if due:
            previous = self._c
            d, n = inp.per_bin()
            if self.success.velocity_dependent:
                rates = self.source.encounters(d, n, inp.rpm)
                self._c, self._fractions = check_encounter_rates(rates, K, repr(self.source))
                self._cumulative = np.concatenate([np.zeros((K, K, 1)), np.cumsum(self._fractions, axis=2)], axis=2)
            else:
                c = self.source(d, n, inp.rpm)
                raw = self._raw
                # a source that returns what it returned last time (the usual case between two
                # refreshes: a table or a coupling interval's classes on fixed bins) was checked then
                if raw is None or previous is None or not (np.shape(c) == raw.shape and np.array_equal(c, raw)):
                    self._c = check_frequency_matrix(c, K, repr(self.source))
                    self._raw = np.array(c, dtype=float)
            self._t_eval = inp.t
            self._diameters = np.array(d, dtype=float)
            self.evaluations += 1
            if (
                self.success.velocity_dependent
                or previous is None
                or (
                    previous is not self._c
                    and (previous.shape != self._c.shape or not np.array_equal(previous, self._c))
                )
            ):
                self._classes = None  # the feed classes' c_ij must be blended again
        W = inp.feed_weights
        if W is None:
            self._class_c, self._class_cumulative = self._c, getattr(self, "_cumulative", None)
        elif self._classes is not W:
            if self._classes is None or not np.array_equal(self._classes, W):
                # a feed class between two pivots meets its partners with the lever-rule blend of
                # the pivots' c_ij (and velocity fractions): E c E^T, E = [I; W] (K + P, K)
                E = np.vstack([np.eye(W.shape[1]), W])
                c = E @ self._c @ E.T
                self._class_c = 0.5 * (c + c.T)  # symmetric to the last digit
                if self.success.velocity_dependent:
                    cum = np.einsum("jl,ilv->ijv", E, np.einsum("ik,klv->ilv", E, self._cumulative))
                    self._class_cumulative = 0.5 * (cum + cum.transpose(1, 0, 2))
            self._classes = W  # the model hands the same array at every step

    def _scaled_classes(self, inp: KernelInput) -> np.ndarray:
        """beta0 c_ij of the classes (kept until c_ij changes)."""
        if self._c is None or self._class_c is None or self._class_c.shape[0] != inp.volumes.size:
            self.prepare(inp)
        c = self._class_c
        if self._beta_of is not c:
            self._scaled = self.beta0 * c
            self._beta_of, self._beta_key = c, None
        return self._scaled

    def factors(self, inp: KernelInput) -> KernelFactors | None:
        """beta0 c_ij and the success model: beta_ij = beta0 c_ij p(phi_i) p(phi_j) (None with a
        velocity-dependent success, which the model evaluates by calling the kernel)."""
        if self.success.velocity_dependent:
            return None
        s = self.success
        return KernelFactors(self._scaled_classes(inp), s.model, s.threshold, s.width)

    def __call__(self, inp: KernelInput) -> np.ndarray:
        if self._c is None or self._class_c is None or self._class_c.shape[0] != inp.volumes.size:
            self.prepare(inp)
        c = self._class_c
        if self.success.velocity_dependent:
            # the criterion holds an impact iff its speed is below the pair's critical speed w*, and
            # the representative speeds rise with the bin: sum_b f_b [v_b < w*] is the cumulative
            # fraction up to the last bin below w* (the same as summing [v_b < w*] f_b over the bins)
            w_star = self.success.velocity.critical_velocity(inp.diameters, inp.surface_fraction)
            n = np.searchsorted(self._speeds, w_star, side="left")
            held = np.take_along_axis(self._class_cumulative, n[:, :, None], axis=2)[:, :, 0]
            return self.beta0 * c * self.success(inp.surface_fraction) * held
        scaled = self._scaled_classes(inp)  # beta0 c_ij and the last kernel kept until c_ij changes
        if self.success.model == "always":
            return scaled
        # psi_ij = p_i p_j: with the step success p is 0 or 1 and changes only when a class crosses
        # the threshold, so the same kernel serves most evaluations (the caller must not modify it)
        p = self.success.per_particle(inp.surface_fraction)
        key = p.tobytes()
        if key != self._beta_key:
            self._beta = self._scaled * np.outer(p, p)  # = beta0 c_ij psi_ij, as before, to the bit
            self._beta_key = key
        return self._beta
