"""Aggregation kernels and collision-frequency sources.

A kernel maps the current population (a :class:`KernelInput`) to the (K, K) symmetric matrix
beta_ij (1/s per pair) used in the population balance. Provided:

* :class:`ConstantKernel` beta_ij = beta0, with Scott's (1968) analytical solution;
* :class:`SumKernel` (Golovin) beta_ij = b (v_i + v_j), with its analytical solution;
* :class:`CollisionKernel` beta_ij = beta0 c_ij psi_ij: c_ij per-pair collision frequency (1/s)
  from a pluggable source, psi_ij a success probability from the surface liquid of both granules.

Collision-frequency sources share the interface of docs/architecture.md,
``source(diameters (K,), numbers (K,), rpm) -> (K, K)``:
:class:`ConstantFrequency`, :class:`TableFrequency` (DEM collision table) and the surrogate
(``pbmdem.surrogate.CollisionSurrogate.frequency_matrix``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import analytical
from .errors import KernelShapeError, PBMInputError, positive

SYMMETRY_RTOL = 1e-8


@dataclass
class KernelInput:
    """What a kernel may depend on at time ``t``: volumes (m3) and diameters (m), numbers and
    surface-liquid volume fraction of every class, and impeller speed (rpm).

    The classes are the grid's K pivots (``feed_weights`` None), or, with feed granules kept
    apart (docs/pbm.md, "Feed granules"), the K pivots followed by P feed classes at their own
    volumes; ``feed_weights`` (P, K) is then the lever rule of the feed classes onto the pivots
    (number fractions). A kernel returns the (K + P, K + P) matrix of the classes.
    """

    t: float
    volumes: np.ndarray
    diameters: np.ndarray
    numbers: np.ndarray
    surface_fraction: np.ndarray
    rpm: float
    feed_weights: np.ndarray | None = None

    @property
    def pivots(self) -> int:
        """Number of grid pivots K."""
        return self.volumes.size if self.feed_weights is None else self.feed_weights.shape[1]

    def per_bin(self) -> tuple[np.ndarray, np.ndarray]:
        """(diameters, numbers) of the K pivots; the numbers are the bin totals (aggregates and
        the feed classes put on the pivots by the lever rule)."""
        if self.feed_weights is None:
            return self.diameters, self.numbers
        K = self.pivots
        return self.diameters[:K], self.numbers[:K] + self.numbers[K:] @ self.feed_weights


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

    def factors(self, inp: KernelInput):
        """``(S, model, threshold, width)`` if this kernel is beta_ij = S_ij p(phi_i) p(phi_j) at
        the step of ``inp`` (after ``prepare``), with S (M, M) fixed until the next ``prepare`` and
        p the success model ``model`` of ``SuccessProbability`` ("always": p = 1) of the
        surface-liquid fraction phi: the model then evaluates the kernel inside its compiled rates
        instead of calling it. None (default): the model calls the kernel."""
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

    def factors(self, inp: KernelInput):
        return self(inp), "always", 0.0, 1.0

    def analytical_solution(self, v, t, N0, mean_volume):
        """Number density n(v, t) (1/m3) for the exponential initial distribution (Scott 1968)."""
        return analytical.constant_number_density(v, t, self.beta0, N0, mean_volume)

    def analytical_moments(self, t, N0, mean_volume):
        """(M0, M1, M2) for the exponential initial distribution."""
        return analytical.constant_moments(t, self.beta0, N0, mean_volume)


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

    def factors(self, inp: KernelInput):
        return self(inp), "always", 0.0, 1.0

    def analytical_solution(self, v, t, N0, mean_volume):
        """Number density n(v, t) for the exponential initial distribution (Golovin; Scott 1968)."""
        return analytical.sum_number_density(v, t, self.b, N0, mean_volume)

    def analytical_moments(self, t, N0, mean_volume):
        return analytical.sum_moments(t, self.b, N0, mean_volume)


class SuccessProbability:
    """psi_ij = p(phi_i) p(phi_j) from the surface-liquid volume fraction phi of both granules.

    ``model``: ``"step"`` p = 1 if phi >= threshold else 0 (default); ``"logistic"``
    p = 1 / (1 + exp(-(phi - threshold) / width)); ``"always"`` p = 1 (dry or pure-aggregation
    tests). phi = surface liquid / granule volume (see ``model.surface_fraction``).

    ``velocity``: optional impact-velocity criterion (``pbmdem.pbm.success.StokesCriterion``: it
    holds an impact iff its speed is below ``critical_velocity(d, phi)``, and ``success(d, phi,
    velocities)`` gives that step per speed); with it the success of an impact at speed v is
    psi_ij(v) = p(phi_i) p(phi_j) x [criterion holds at v] (:meth:`resolved`), and
    :class:`CollisionKernel` needs velocity-resolved encounter rates from its source. Without it (default) the success is velocity-independent,
    as in the seed study.
    """

    MODELS = ("step", "logistic", "always")

    def __init__(self, model: str = "step", threshold: float = 0.02, width: float = 0.005,
                 velocity=None):
        if velocity is not None and not (hasattr(velocity, "success") and hasattr(velocity, "critical_velocity")):
            raise PBMInputError(f"success velocity criterion {velocity!r} lacks success(d, phi, velocities) or "
                                "critical_velocity(d, phi); allowed: None or a pbmdem.pbm.success.StokesCriterion")
        self.velocity = velocity
        if model not in self.MODELS:
            raise PBMInputError(f"success probability model = {model!r}; allowed: {list(self.MODELS)}")
        self.model = model
        self.threshold = positive("success threshold", threshold, allow_zero=True)
        if self.threshold >= 1:
            raise PBMInputError(f"success threshold = {threshold!r}; allowed: 0 <= threshold < 1 "
                                "(a surface-liquid volume fraction)")
        self.width = positive("success width", width)

    def __repr__(self) -> str:
        vel = "" if self.velocity is None else f", velocity={self.velocity!r}"
        return f"SuccessProbability({self.model!r}, threshold={self.threshold:g}, width={self.width:g}{vel})"

    @property
    def velocity_dependent(self) -> bool:
        """True if the success also depends on the impact velocity (``velocity`` criterion set)."""
        return self.velocity is not None

    def resolved(self, diameters, phi, velocities) -> np.ndarray:
        """(K, K, V) psi_ij(v_b): the surface-liquid condition times the velocity criterion
        (``velocity.success(diameters, phi, velocities)``) at the speeds ``velocities`` (m/s)."""
        liquid = self(phi)
        if self.velocity is None:
            return np.repeat(liquid[:, :, None], np.size(velocities), axis=2)
        return liquid[:, :, None] * self.velocity.success(diameters, phi, velocities)

    def per_particle(self, phi: np.ndarray) -> np.ndarray:
        phi = np.asarray(phi, float)
        if self.model == "always":
            return np.ones_like(phi)
        if self.model == "step":
            return (phi >= self.threshold).astype(float)
        z = np.clip((phi - self.threshold) / self.width, -700, 700)
        return 1.0 / (1.0 + np.exp(-z))

    def __call__(self, phi: np.ndarray) -> np.ndarray:
        p = self.per_particle(phi)
        return np.outer(p, p)


def check_frequency_matrix(c, K: int, name: str) -> np.ndarray:
    """Validate what a collision-frequency source returned: (K, K), finite, >= 0, symmetric."""
    c = np.asarray(c, dtype=float)
    if c.shape != (K, K):
        raise KernelShapeError(f"collision-frequency source {name} returned shape {c.shape}; expected "
                               f"({K}, {K}) for {K} bins (one c_ij per bin pair)")
    bad = ~np.isfinite(c)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise KernelShapeError(f"collision-frequency source {name} returned a non-finite value "
                               f"c[{i},{j}] = {c[i, j]}; allowed: finite values >= 0 (1/s per pair)")
    if (c < 0).any():
        i, j = np.argwhere(c < 0)[0]
        raise KernelShapeError(f"collision-frequency source {name} returned a negative value "
                               f"c[{i},{j}] = {c[i, j]:.6g}; allowed: values >= 0 (1/s per pair)")
    diff = np.abs(c - c.T)
    tol = SYMMETRY_RTOL * np.maximum(np.abs(c), np.abs(c.T)) + 1e-300
    if (diff > tol).any():
        i, j = np.argwhere(diff > tol)[0]
        raise KernelShapeError(f"collision-frequency source {name} returned a non-symmetric matrix: "
                               f"c[{i},{j}] = {c[i, j]:.6g} but c[{j},{i}] = {c[j, i]:.6g}; c_ij must "
                               f"equal c_ji within relative {SYMMETRY_RTOL:g}")
    return 0.5 * (c + c.T)


def check_encounter_rates(rates, K: int, name: str):
    """Validate what ``source.encounters`` returned: an EncounterRates whose frequency passes
    :func:`check_frequency_matrix` and whose (K, K, V) velocity fractions are finite, >= 0,
    symmetric in (i, j) and sum to 1 (or to 0 for a pair without encounters) over the bins.
    Returns (frequency, fractions), both symmetrised."""
    from pbmdem.impact import N_VELOCITY_BINS

    for attr in ("frequency", "velocity_fractions"):
        if not hasattr(rates, attr):
            raise KernelShapeError(f"collision-frequency source {name}.encounters returned {type(rates).__name__} "
                                   f"without {attr!r}; expected a pbmdem.impact.EncounterRates")
    c = check_frequency_matrix(rates.frequency, K, name + ".encounters")
    f = np.asarray(rates.velocity_fractions, dtype=float)
    if f.shape != (K, K, N_VELOCITY_BINS):
        raise KernelShapeError(f"collision-frequency source {name}.encounters returned velocity fractions of "
                               f"shape {f.shape}; expected ({K}, {K}, {N_VELOCITY_BINS})")
    bad = ~np.isfinite(f) | (f < 0)
    if bad.any():
        i, j, b = np.argwhere(bad)[0]
        raise KernelShapeError(f"collision-frequency source {name}.encounters returned velocity fraction "
                               f"[{i},{j},{b}] = {f[i, j, b]!r}; allowed: finite values >= 0")
    total = f.sum(axis=2)
    off = (np.abs(total - 1.0) > 1e-8) & (total != 0.0)
    if off.any():
        i, j = np.argwhere(off)[0]
        raise KernelShapeError(f"collision-frequency source {name}.encounters: the velocity fractions of pair "
                               f"({i}, {j}) sum to {total[i, j]:.10g}; allowed: 1 (or 0 for a pair without data)")
    asym = np.abs(f - f.transpose(1, 0, 2)) > 1e-8
    if asym.any():
        i, j, b = np.argwhere(asym)[0]
        raise KernelShapeError(f"collision-frequency source {name}.encounters: velocity fractions are not "
                               f"symmetric: [{i},{j},{b}] = {f[i, j, b]:.6g} but [{j},{i},{b}] = {f[j, i, b]:.6g}")
    return c, 0.5 * (f + f.transpose(1, 0, 2))


class CollisionKernel(Kernel):
    """beta_ij = beta0 * c_ij * psi_ij, or, with a velocity-dependent success probability,
    beta_ij = beta0 * c_ij * sum_b f_ij,b psi_ij(v_b).

    ``source(diameters, numbers, rpm) -> (K, K)`` per-pair collision frequency (1/s). It is
    evaluated at the first step of a run and then again once ``update_interval`` seconds have
    passed (0: every step); the coupled PBM-DEM loop swaps ``source`` between runs
    (``set_source``). ``beta0`` is the dimensionless fraction of successful-when-wet collisions.

    If ``success.velocity_dependent``, the source must offer ``encounters(diameters, numbers,
    rpm) -> pbmdem.impact.EncounterRates`` (docs/architecture.md): c_ij is then the encounter
    frequency per pair and f_ij,b the fraction of the pair's encounters in impact-velocity bin b,
    whose speed v_b is ``pbmdem.impact.representative_velocities()[b]``. A pair whose fractions
    are all 0 (no velocity data) gets beta_ij = 0.
    """

    def __init__(self, source, beta0: float, success: SuccessProbability | None = None,
                 update_interval: float = 0.0):
        self.beta0 = positive("aggregation beta0", beta0)
        self.success = success if success is not None else SuccessProbability()
        if self.success.velocity_dependent:
            from pbmdem.impact import representative_velocities

            self._speeds = representative_velocities()
            if not np.all(np.diff(self._speeds) > 0):  # pragma: no cover - guards pbmdem.impact
                raise PBMInputError("representative impact speeds must rise with the velocity bin")
        self._check_source(source)
        self.source = source
        self.update_interval = positive("frequency update_interval", update_interval, allow_zero=True)
        self.evaluations = 0
        self.reset()

    def __repr__(self) -> str:
        return (f"CollisionKernel(source={self.source!r}, beta0={self.beta0:g}, success={self.success!r}, "
                f"update_interval={self.update_interval:g})")

    def _check_source(self, source) -> None:
        if not callable(source):
            raise PBMInputError(f"collision-frequency source {source!r} is not callable; allowed: "
                                "source(diameters, numbers, rpm) -> (K, K)")
        if self.success.velocity_dependent and not callable(getattr(source, "encounters", None)):
            raise PBMInputError(f"the velocity-dependent success probability {self.success!r} needs impact "
                                f"velocities, but the collision-frequency source {source!r} has no "
                                "encounters(diameters, numbers, rpm) method; use a DEM table with its "
                                "impact-velocity table, or success velocity_model: none")

    def reset(self) -> None:
        self._c: np.ndarray | None = None
        self._fractions: np.ndarray | None = None
        self._classes: np.ndarray | None = None
        self._class_c = self._class_cumulative = None
        self._t_eval = -np.inf
        self._raw: np.ndarray | None = None     # the source's last matrix as returned (before the check)
        self._beta_of = None                    # the class matrix the cached products below belong to
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
        if self._c is None or self._c.shape != (K, K) or inp.t >= self._t_eval + self.update_interval:
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
            self.evaluations += 1
            if self.success.velocity_dependent or previous is None or (previous is not self._c and (
                    previous.shape != self._c.shape or not np.array_equal(previous, self._c))):
                self._classes = None                # the feed classes' c_ij must be blended again
        W = inp.feed_weights
        if W is None:
            self._class_c, self._class_cumulative = self._c, getattr(self, "_cumulative", None)
        elif self._classes is not W:
            if self._classes is None or not np.array_equal(self._classes, W):
                # a feed class between two pivots meets its partners with the lever-rule blend of
                # the pivots' c_ij (and velocity fractions): E c E^T, E = [I; W] (K + P, K)
                E = np.vstack([np.eye(W.shape[1]), W])
                c = E @ self._c @ E.T
                self._class_c = 0.5 * (c + c.T)                 # symmetric to the last digit
                if self.success.velocity_dependent:
                    cum = np.einsum("jl,ilv->ijv", E, np.einsum("ik,klv->ilv", E, self._cumulative))
                    self._class_cumulative = 0.5 * (cum + cum.transpose(1, 0, 2))
            self._classes = W                   # the model hands the same array at every step

    def _scaled_classes(self, inp: KernelInput) -> np.ndarray:
        """beta0 c_ij of the classes (kept until c_ij changes)."""
        if self._c is None or self._class_c is None or self._class_c.shape[0] != inp.volumes.size:
            self.prepare(inp)
        c = self._class_c
        if self._beta_of is not c:
            self._scaled = self.beta0 * c
            self._beta_of, self._beta_key = c, None
        return self._scaled

    def factors(self, inp: KernelInput):
        """beta0 c_ij and the success model: beta_ij = beta0 c_ij p(phi_i) p(phi_j) (None with a
        velocity-dependent success, which the model evaluates by calling the kernel)."""
        if self.success.velocity_dependent:
            return None
        s = self.success
        return self._scaled_classes(inp), s.model, s.threshold, s.width

    def __call__(self, inp: KernelInput) -> np.ndarray:
        if self._c is None or self._class_c is None or self._class_c.shape[0] != inp.volumes.size:
            self.prepare(inp)
        c = self._class_c
        if self.success.velocity_dependent:
            # the criterion holds an impact iff its speed is below the pair's critical speed w*, and
            # the representative speeds rise with the bin: sum_b f_b [v_b < w*] is the cumulative
            # fraction up to the last bin below w* (same as summing success.resolved(...) * f)
            w_star = self.success.velocity.critical_velocity(inp.diameters, inp.surface_fraction)
            n = np.searchsorted(self._speeds, w_star, side="left")
            held = np.take_along_axis(self._class_cumulative, n[:, :, None], axis=2)[:, :, 0]
            return self.beta0 * c * self.success(inp.surface_fraction) * held
        scaled = self._scaled_classes(inp)       # beta0 c_ij and the last kernel kept until c_ij changes
        if self.success.model == "always":
            return scaled
        # psi_ij = p_i p_j: with the step success p is 0 or 1 and changes only when a class crosses
        # the threshold, so the same kernel serves most evaluations (the caller must not modify it)
        p = self.success.per_particle(inp.surface_fraction)
        key = p.tobytes()
        if key != self._beta_key:
            self._beta = self._scaled * np.outer(p, p)       # = beta0 c_ij psi_ij, as before, to the bit
            self._beta_key = key
        return self._beta


class ConstantFrequency:
    """c_ij = value for every pair (1/s per pair).

    ``impact_velocity`` (m/s, optional): one impact speed for every encounter; it enables
    :meth:`encounters` (all encounters in the velocity bin of that speed), so that the constant
    baseline can run with a velocity-dependent success probability.
    """

    def __init__(self, value: float, impact_velocity: float | None = None):
        self.value = positive("constant collision frequency", value)
        self.impact_velocity = None if impact_velocity is None else \
            positive("constant impact velocity (m/s)", impact_velocity)

    def __repr__(self) -> str:
        vel = "" if self.impact_velocity is None else f", impact_velocity={self.impact_velocity:g}"
        return f"ConstantFrequency({self.value:g}{vel})"

    def __call__(self, diameters, numbers, rpm) -> np.ndarray:
        K = np.atleast_1d(diameters).size
        return np.full((K, K), self.value)

    def encounters(self, diameters, numbers, rpm):
        """EncounterRates: c_ij = value, every encounter in the bin of ``impact_velocity``."""
        from pbmdem.impact import N_VELOCITY_BINS, EncounterRates, velocity_bin

        if self.impact_velocity is None:
            raise PBMInputError("ConstantFrequency.encounters needs an impact velocity "
                                "(pbm.aggregation.constant_impact_velocity, m/s)")
        K = np.atleast_1d(diameters).size
        f = np.zeros((K, K, N_VELOCITY_BINS))
        f[:, :, int(velocity_bin(self.impact_velocity))] = 1.0
        return EncounterRates(self(diameters, numbers, rpm), f)


#: The DEM table column the PBM kernel is built on (docs/architecture.md: encounters, i.e. impacts of
#: granules that were apart, not every contact that begins).
FREQUENCY_COLUMN = "encounter_frequency_per_pair"
#: Columns of results/dem/impact_velocity.csv that TableFrequency reads.
VELOCITY_TABLE_COLUMNS = ("point_id", "class_i", "class_j", "v_lo", "v_hi", "encounters")


class TableFrequency:
    """Per-pair encounter frequency interpolated from the DEM collision table.

    ``table``: DataFrame with columns ``d_i, d_j`` and ``column`` (default
    ``encounter_frequency_per_pair``; and ``rpm``; without it one speed is assumed), one row per
    class pair as in docs/architecture.md. For each speed:

    * rows are made symmetric (the (d_j, d_i) mirror of each row is added) and rows for the same
      pair (several distributions at one speed) are averaged;
    * interpolation is bilinear in (log d_i, log d_j) of log c (a power law between table
      sizes); zero frequencies are replaced by ``zero_floor`` x the smallest positive frequency
      of the table before taking logs;
    * outside the table's size range: ``extrapolation="clamp"`` (default) uses the value at the
      nearest table size (c constant beyond the range: large aggregates of a PBM far outside the
      DEM sizes get the frequency of the largest DEM class); ``"linear"`` extends the power law.

    Over impeller speed: the table speed is selected if it matches, log c is interpolated
    linearly in rpm between the two neighbouring table speeds, and outside the table's speeds the
    nearest speed is used (clamped). ``numbers`` is ignored: the table holds the DEM
    population's own frequencies (the surrogate uses numbers).

    ``velocity_table`` (optional): the impact-velocity table (results/dem/impact_velocity.csv,
    columns ``point_id, class_i, class_j, v_lo, v_hi, encounters``), joined to ``table`` on
    (point_id, class_i, class_j) (rows of points absent from ``table`` are left out); it enables :meth:`encounters`. Per speed, the encounter counts of
    a pair (and of its mirror and of duplicate rows) are pooled and normalised to fractions per
    velocity bin; a table pair without encounters gets the pooled distribution of all pairs at
    that speed (its frequency is floored, not zero, see above). The fractions are interpolated
    bilinearly in (log d_i, log d_j), always clamped at the table's sizes (a linearly extrapolated
    distribution could turn negative), and mixed linearly in rpm with the weights of the
    frequency interpolation.
    """

    def __init__(self, table: pd.DataFrame, extrapolation: str = "clamp", zero_floor: float = 1e-3,
                 column: str = FREQUENCY_COLUMN, velocity_table: pd.DataFrame | None = None):
        import pandas as pd

        from scipy.interpolate import RegularGridInterpolator

        if extrapolation not in ("clamp", "linear"):
            raise PBMInputError(f"table extrapolation = {extrapolation!r}; allowed: 'clamp', 'linear'")
        self.extrapolation = extrapolation
        self.zero_floor = positive("table zero_floor", zero_floor)
        self.column = column
        missing = [c for c in ("d_i", "d_j", column) if c not in table.columns]
        if missing:
            raise PBMInputError(f"collision table lacks columns {missing}; required: d_i, d_j, "
                                f"{column} (and rpm); present: {list(table.columns)}")
        if len(table) == 0:
            raise PBMInputError("collision table is empty")
        t = table.copy().reset_index(drop=True)
        if "rpm" not in t.columns:
            t["rpm"] = np.nan
        for col in ("d_i", "d_j"):
            v = t[col].to_numpy(float)
            if not np.all(np.isfinite(v) & (v > 0)):
                raise PBMInputError(f"collision table column {col} has values {v[~(np.isfinite(v) & (v > 0))][:5]}; "
                                    "allowed: finite diameters > 0 (m)")
        f = t[column].to_numpy(float)
        if not np.all(np.isfinite(f) & (f >= 0)):
            raise PBMInputError(f"collision table {column} has values {f[~(np.isfinite(f) & (f >= 0))][:5]}; "
                                "allowed: finite values >= 0 (1/s per pair)")
        if not (f > 0).any():
            raise PBMInputError(f"collision table has no positive {column}; cannot interpolate in log space")
        counts = None if velocity_table is None else self._velocity_counts(t, velocity_table)
        floor = self.zero_floor * f[f > 0].min()
        self.rpms = []
        self._interp = []
        self._frac_interp = []
        self.ranges = []
        groups = [(np.nan, t)] if t["rpm"].isna().all() else sorted(t.groupby("rpm"), key=lambda kv: kv[0])
        for rpm, g in groups:
            sym = pd.concat([g[["d_i", "d_j", column]],
                             g.rename(columns={"d_i": "d_j", "d_j": "d_i"})[["d_i", "d_j", column]]])
            mean = sym.groupby(["d_i", "d_j"])[column].mean()
            u = np.unique(np.concatenate([mean.index.get_level_values(0), mean.index.get_level_values(1)]))
            F = mean.unstack().reindex(index=u, columns=u).to_numpy(float)
            if np.isnan(F).any():
                a, b = np.argwhere(np.isnan(F))[0]
                raise PBMInputError(f"collision table at rpm {rpm:g}: no row for the pair d_i = {u[a]:g}, "
                                    f"d_j = {u[b]:g}; every pair of the table's sizes is needed")
            logF = np.log(np.maximum(F, floor))
            lu = np.log(u)
            self.rpms.append(float(rpm))
            self._interp.append(self._interpolator(RegularGridInterpolator, lu, logF))
            self.ranges.append((float(u[0]), float(u[-1])))
            if counts is not None:
                fr = self._fraction_grid(g, counts[g.index.to_numpy()], u, rpm)
                self._frac_interp.append(self._interpolator(RegularGridInterpolator, lu, fr))
        self.rpms = np.array(self.rpms)

    @classmethod
    def from_matrix(cls, diameters, matrix, extrapolation: str = "clamp", zero_floor: float = 1e-3,
                    column: str = "frequency_per_pair") -> TableFrequency:
        """The source of one speed's table of K classes given as their ascending ``diameters``
        (K,) and the symmetric (K, K) per-pair frequency ``matrix``: what the constructor makes
        of the upper-triangle table (d_i, d_j, ``column``), without DataFrames (a coupling
        interval's classes). Diameters that are not strictly ascending go through the table."""
        import pandas as pd

        d = np.asarray(diameters, float)
        m = np.asarray(matrix, float)
        if d.ndim != 1 or d.size < 2 or m.shape != (d.size, d.size) or not np.all(np.diff(d) > 0):
            iu, ju = np.triu_indices(d.size) if d.ndim == 1 else (np.zeros(0, int),) * 2
            m2 = np.atleast_2d(m)
            table = pd.DataFrame({"d_i": d[iu], "d_j": d[ju], column: m2[iu, ju]})
            return cls(table, extrapolation=extrapolation, zero_floor=zero_floor, column=column)
        from scipy.interpolate import RegularGridInterpolator

        self = cls.__new__(cls)
        if extrapolation not in ("clamp", "linear"):
            raise PBMInputError(f"table extrapolation = {extrapolation!r}; allowed: 'clamp', 'linear'")
        self.extrapolation = extrapolation
        self.zero_floor = positive("table zero_floor", zero_floor)
        self.column = column
        if not np.all(np.isfinite(d) & (d > 0)):
            raise PBMInputError(f"collision table column d_i has values {d[~(np.isfinite(d) & (d > 0))][:5]}; "
                                "allowed: finite diameters > 0 (m)")
        iu, ju = np.triu_indices(d.size)
        f = m[iu, ju]
        if not np.all(np.isfinite(f) & (f >= 0)):
            raise PBMInputError(f"collision table {column} has values {f[~(np.isfinite(f) & (f >= 0))][:5]}; "
                                "allowed: finite values >= 0 (1/s per pair)")
        if not (f > 0).any():
            raise PBMInputError(f"collision table has no positive {column}; cannot interpolate in log space")
        # the table's symmetric mean: each off-diagonal pair once per order, the diagonal twice
        F = np.empty((d.size, d.size))
        F[iu, ju] = f
        F[ju, iu] = f
        floor = self.zero_floor * f[f > 0].min()
        lu = np.log(d)
        self.rpms = np.array([np.nan])
        self._interp = [self._interpolator(RegularGridInterpolator, lu, np.log(np.maximum(F, floor)))]
        self._frac_interp = []
        self.ranges = [(float(d[0]), float(d[-1]))]
        return self

    @staticmethod
    def _interpolator(rgi, lu: np.ndarray, values: np.ndarray):
        if lu.size == 1:
            return (lambda value: (lambda pts: np.repeat(value[None], pts.shape[0], axis=0)))(values[0, 0])
        return rgi((lu, lu), values, method="linear", bounds_error=False, fill_value=None)

    @staticmethod
    def _velocity_counts(t: pd.DataFrame, velocity_table: pd.DataFrame) -> np.ndarray:
        """(rows of t, V) encounter counts per velocity bin of every collision-table row."""
        import pandas as pd

        from pbmdem.impact import N_VELOCITY_BINS, VELOCITY_EDGES

        missing = [c for c in VELOCITY_TABLE_COLUMNS if c not in velocity_table.columns]
        if missing:
            raise PBMInputError(f"impact-velocity table lacks columns {missing}; required: "
                                f"{list(VELOCITY_TABLE_COLUMNS)}; present: {list(velocity_table.columns)}")
        keys = ["point_id", "class_i", "class_j"]
        missing = [c for c in keys if c not in t.columns]
        if missing:
            raise PBMInputError(f"collision table lacks columns {missing}, needed to join the impact-velocity "
                                f"table on {keys}; present: {list(t.columns)}")
        # rows of other DEM points (e.g. the grid's velocity table beside one point's collision table)
        points = set(t["point_id"].astype(str))
        vt = velocity_table[velocity_table["point_id"].astype(str).isin(points)]
        if vt.empty:
            raise PBMInputError(f"impact-velocity table has no rows for the collision table's points "
                                f"{sorted(points)[:5]}; both tables must come from the same DEM runs")
        n = vt["encounters"].to_numpy(float)
        if not np.all(np.isfinite(n) & (n >= 0)):
            raise PBMInputError(f"impact-velocity table encounters has values {n[~(np.isfinite(n) & (n >= 0))][:5]}; "
                                "allowed: finite counts >= 0")
        lo, hi = vt["v_lo"].to_numpy(float), vt["v_hi"].to_numpy(float)
        b = np.searchsorted(VELOCITY_EDGES[:-1], lo)
        b_ok = np.clip(b, 0, N_VELOCITY_BINS - 1)
        ok = (b < N_VELOCITY_BINS) & np.isclose(VELOCITY_EDGES[:-1][b_ok], lo, rtol=1e-6, atol=0.0)
        ok &= np.isclose(VELOCITY_EDGES[1:][b_ok], hi, rtol=1e-6, atol=0.0) | \
            ((b_ok == N_VELOCITY_BINS - 1) & np.isinf(hi))
        if not ok.all():
            k = int(np.argmin(ok))
            raise PBMInputError(f"impact-velocity table row {k}: bin [v_lo, v_hi) = [{lo[k]!r}, {hi[k]!r}) m/s is "
                                "not one of the project's velocity bins; allowed: consecutive edges of "
                                f"pbmdem.impact.VELOCITY_EDGES {np.round(VELOCITY_EDGES, 6).tolist()}")
        row = pd.Series(np.arange(len(t)), index=pd.MultiIndex.from_frame(
            t[keys].astype({"point_id": str, "class_i": int, "class_j": int})))
        if row.index.duplicated().any():
            dup = row.index[row.index.duplicated()][0]
            raise PBMInputError(f"collision table has several rows for (point_id, class_i, class_j) = {dup}")
        vkeys = pd.MultiIndex.from_frame(vt[keys].astype({"point_id": str, "class_i": int, "class_j": int}))
        idx = row.reindex(vkeys).to_numpy()
        if np.isnan(idx.astype(float)).any():
            k = int(np.argmax(np.isnan(idx.astype(float))))
            raise PBMInputError(f"impact-velocity table row {k}: (point_id, class_i, class_j) = {tuple(vkeys[k])} "
                                "has no row in the collision table; both tables must come from the same DEM runs")
        counts = np.zeros((len(t), N_VELOCITY_BINS))
        np.add.at(counts, (idx.astype(int), b_ok), n)
        return counts

    def _fraction_grid(self, g: pd.DataFrame, counts: np.ndarray, u: np.ndarray, rpm) -> np.ndarray:
        """(n, n, V) velocity fractions on the table sizes u of one speed's rows g."""
        has = g[self.column].to_numpy(float) > 0
        lacking = has & (counts.sum(axis=1) <= 0)
        if lacking.any():
            r = g.iloc[int(np.argmax(lacking))]
            raise PBMInputError(f"collision table at rpm {rpm:g}: pair d_i = {r['d_i']:g}, d_j = {r['d_j']:g} has "
                                f"{self.column} = {r[self.column]:g} but no encounters in the impact-velocity "
                                "table; both tables must come from the same DEM runs")
        pooled = counts.sum(axis=0)
        if not pooled.sum() > 0:
            raise PBMInputError(f"impact-velocity table: no encounters at rpm {rpm:g}")
        pos = {float(d): k for k, d in enumerate(u)}
        grid = np.zeros((u.size, u.size, counts.shape[1]))
        a = np.array([pos[float(d)] for d in g["d_i"]])
        b = np.array([pos[float(d)] for d in g["d_j"]])
        np.add.at(grid, (a, b), counts)
        np.add.at(grid, (b[a != b], a[a != b]), counts[a != b])
        total = grid.sum(axis=2, keepdims=True)
        grid = np.where(total > 0, grid / np.where(total > 0, total, 1.0), pooled / pooled.sum())
        return grid

    def __repr__(self) -> str:
        speeds = "any" if np.isnan(self.rpms).all() else ",".join(f"{r:g}" for r in self.rpms)
        vel = ", velocities" if self._frac_interp else ""
        return f"TableFrequency(rpm=[{speeds}], extrapolation={self.extrapolation!r}{vel})"

    @classmethod
    def from_csv(cls, path, distribution: str | None = None, velocity_path=None, **kwargs) -> "TableFrequency":
        """Read a collision table CSV; ``distribution`` keeps only that distribution's rows;
        ``velocity_path``: the impact-velocity table CSV (results/dem/impact_velocity.csv) that
        enables :meth:`encounters`."""
        table = cls._read(path, distribution, "collision table")
        velocity_table = None
        if velocity_path is not None:
            velocity_table = cls._read(velocity_path, distribution, "impact-velocity table")
        try:
            return cls(table, velocity_table=velocity_table, **kwargs)
        except PBMInputError as err:
            names = str(path) + ("" if velocity_path is None else f" / {velocity_path}")
            raise PBMInputError(f"{names}: {err}") from None

    @staticmethod
    def _read(path, distribution: str | None, what: str) -> pd.DataFrame:
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{what} {path} does not exist")
        from pbmdem.readers import InputFileError, read_table

        try:
            table = read_table(path, what)
        except InputFileError as exc:
            raise PBMInputError(str(exc)) from None
        if distribution is not None:
            if "distribution" not in table.columns:
                raise PBMInputError(f"{path}: no 'distribution' column to select {distribution!r}")
            names = sorted(table["distribution"].astype(str).unique())
            table = table[table["distribution"].astype(str) == distribution]
            if table.empty:
                raise PBMInputError(f"{path}: no rows for distribution {distribution!r}; present: {names}")
        return table

    def _log_d(self, k: int, d: np.ndarray, clamp: bool) -> tuple[np.ndarray, np.ndarray]:
        ld = np.log(d)
        if clamp:
            lo, hi = self.ranges[k]
            ld = np.clip(ld, np.log(lo), np.log(hi))
        A, B = np.meshgrid(ld, ld, indexing="ij")
        return A.ravel(), B.ravel()

    def _log_matrix(self, k: int, d: np.ndarray) -> np.ndarray:
        A, B = self._log_d(k, d, self.extrapolation == "clamp")
        L = self._interp[k](np.column_stack([A, B])).reshape(d.size, d.size)
        return 0.5 * (L + L.T)

    def _fractions(self, k: int, d: np.ndarray) -> np.ndarray:
        A, B = self._log_d(k, d, True)
        F = self._frac_interp[k](np.column_stack([A, B])).reshape(d.size, d.size, -1)
        F = np.maximum(0.5 * (F + F.transpose(1, 0, 2)), 0.0)
        return F / F.sum(axis=2, keepdims=True)

    def _speed_weights(self, rpm) -> list[tuple[int, float]]:
        """[(table speed index, weight)] of the interpolation in rpm."""
        if self.rpms.size == 1 or np.isnan(self.rpms).all():
            return [(0, 1.0)]
        rpm = float(rpm)
        if rpm <= self.rpms[0]:
            return [(0, 1.0)]
        if rpm >= self.rpms[-1]:
            return [(self.rpms.size - 1, 1.0)]
        k = int(np.searchsorted(self.rpms, rpm, side="right") - 1)
        if rpm == self.rpms[k]:
            return [(k, 1.0)]
        w = (rpm - self.rpms[k]) / (self.rpms[k + 1] - self.rpms[k])
        return [(k, 1.0 - w), (k + 1, w)]

    @staticmethod
    def _diameters(diameters) -> np.ndarray:
        d = np.atleast_1d(np.asarray(diameters, float))
        if not np.all(np.isfinite(d) & (d > 0)):
            raise PBMInputError(f"TableFrequency: diameters must be finite and > 0, got {d}")
        return d

    def __call__(self, diameters, numbers, rpm) -> np.ndarray:
        d = self._diameters(diameters)
        return np.exp(sum(w * self._log_matrix(k, d) for k, w in self._speed_weights(rpm)))

    def encounters(self, diameters, numbers, rpm):
        """:class:`pbmdem.impact.EncounterRates` at the bins' diameters: the frequency of
        ``__call__`` and the interpolated velocity fractions (needs ``velocity_table``)."""
        from pbmdem.impact import EncounterRates

        if not self._frac_interp:
            raise PBMInputError("TableFrequency.encounters needs the impact-velocity table "
                                "(results/dem/impact_velocity.csv: velocity_table= / from_csv(velocity_path=...), "
                                "pbmdem pbm --velocity-table)")
        d = self._diameters(diameters)
        weights = self._speed_weights(rpm)
        freq = np.exp(sum(w * self._log_matrix(k, d) for k, w in weights))
        fractions = sum(w * self._fractions(k, d) for k, w in weights)
        return EncounterRates(freq, fractions)
