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
    """What a kernel may depend on at time ``t``: pivot volumes (m3) and diameters (m), numbers
    per bin, surface-liquid volume fraction per bin and impeller speed (rpm)."""

    t: float
    volumes: np.ndarray
    diameters: np.ndarray
    numbers: np.ndarray
    surface_fraction: np.ndarray
    rpm: float


class Kernel:
    """Base class: ``kernel(inp) -> (K, K)``; ``prepare(inp)`` is called once at the start of every
    time step (a kernel may refresh cached data there), ``reset()`` at the start of every run."""

    def prepare(self, inp: KernelInput) -> None:
        pass

    def reset(self) -> None:
        pass

    def __call__(self, inp: KernelInput) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError


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
        if self._cache is None or self._cache[0] != v.size:
            self._cache = (v.size, self.b * (v[:, None] + v[None, :]))
        return self._cache[1]

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
    """

    MODELS = ("step", "logistic", "always")

    def __init__(self, model: str = "step", threshold: float = 0.02, width: float = 0.005):
        if model not in self.MODELS:
            raise PBMInputError(f"success probability model = {model!r}; allowed: {list(self.MODELS)}")
        self.model = model
        self.threshold = positive("success threshold", threshold, allow_zero=True)
        if self.threshold >= 1:
            raise PBMInputError(f"success threshold = {threshold!r}; allowed: 0 <= threshold < 1 "
                                "(a surface-liquid volume fraction)")
        self.width = positive("success width", width)

    def __repr__(self) -> str:
        return f"SuccessProbability({self.model!r}, threshold={self.threshold:g}, width={self.width:g})"

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


class CollisionKernel(Kernel):
    """beta_ij = beta0 * c_ij * psi_ij.

    ``source(diameters, numbers, rpm) -> (K, K)`` per-pair collision frequency (1/s). It is
    evaluated at the first step of a run and then again once ``update_interval`` seconds have
    passed (0: every step); the coupled PBM-DEM loop swaps ``source`` between runs
    (``set_source``). ``beta0`` is the dimensionless fraction of successful-when-wet collisions.
    """

    def __init__(self, source, beta0: float, success: SuccessProbability | None = None,
                 update_interval: float = 0.0):
        if not callable(source):
            raise PBMInputError(f"collision-frequency source {source!r} is not callable; allowed: "
                                "source(diameters, numbers, rpm) -> (K, K)")
        self.source = source
        self.beta0 = positive("aggregation beta0", beta0)
        self.success = success if success is not None else SuccessProbability()
        self.update_interval = positive("frequency update_interval", update_interval, allow_zero=True)
        self.evaluations = 0
        self.reset()

    def __repr__(self) -> str:
        return (f"CollisionKernel(source={self.source!r}, beta0={self.beta0:g}, success={self.success!r}, "
                f"update_interval={self.update_interval:g})")

    def reset(self) -> None:
        self._c: np.ndarray | None = None
        self._t_eval = -np.inf

    def set_source(self, source) -> None:
        self.source = source
        self.reset()

    @property
    def frequency(self) -> np.ndarray | None:
        """The c_ij matrix in use (None before the first step)."""
        return self._c

    def prepare(self, inp: KernelInput) -> None:
        K = inp.volumes.size
        if self._c is None or self._c.shape != (K, K) or inp.t >= self._t_eval + self.update_interval:
            c = self.source(inp.diameters, inp.numbers, inp.rpm)
            self._c = check_frequency_matrix(c, K, repr(self.source))
            self._t_eval = inp.t
            self.evaluations += 1

    def __call__(self, inp: KernelInput) -> np.ndarray:
        if self._c is None:
            self.prepare(inp)
        if self.success.model == "always":
            return self.beta0 * self._c
        return self.beta0 * self._c * self.success(inp.surface_fraction)


class ConstantFrequency:
    """c_ij = value for every pair (1/s per pair)."""

    def __init__(self, value: float):
        self.value = positive("constant collision frequency", value)

    def __repr__(self) -> str:
        return f"ConstantFrequency({self.value:g})"

    def __call__(self, diameters, numbers, rpm) -> np.ndarray:
        K = np.atleast_1d(diameters).size
        return np.full((K, K), self.value)


class TableFrequency:
    """Per-pair collision frequency interpolated from the DEM collision table.

    ``table``: DataFrame with columns ``d_i, d_j, frequency_per_pair`` (and ``rpm``; without it one
    speed is assumed), one row per class pair as in docs/architecture.md. For each speed:

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
    """

    def __init__(self, table: pd.DataFrame, extrapolation: str = "clamp", zero_floor: float = 1e-3):
        import pandas as pd
        from scipy.interpolate import RegularGridInterpolator

        if extrapolation not in ("clamp", "linear"):
            raise PBMInputError(f"table extrapolation = {extrapolation!r}; allowed: 'clamp', 'linear'")
        self.extrapolation = extrapolation
        self.zero_floor = positive("table zero_floor", zero_floor)
        missing = [c for c in ("d_i", "d_j", "frequency_per_pair") if c not in table.columns]
        if missing:
            raise PBMInputError(f"collision table lacks columns {missing}; required: d_i, d_j, "
                                f"frequency_per_pair (and rpm); present: {list(table.columns)}")
        if len(table) == 0:
            raise PBMInputError("collision table is empty")
        t = table.copy()
        if "rpm" not in t.columns:
            t["rpm"] = np.nan
        for col in ("d_i", "d_j"):
            v = t[col].to_numpy(float)
            if not np.all(np.isfinite(v) & (v > 0)):
                raise PBMInputError(f"collision table column {col} has values {v[~(np.isfinite(v) & (v > 0))][:5]}; "
                                    "allowed: finite diameters > 0 (m)")
        f = t["frequency_per_pair"].to_numpy(float)
        if not np.all(np.isfinite(f) & (f >= 0)):
            raise PBMInputError(f"collision table frequency_per_pair has values {f[~(np.isfinite(f) & (f >= 0))][:5]}; "
                                "allowed: finite values >= 0 (1/s per pair)")
        if not (f > 0).any():
            raise PBMInputError("collision table has no positive frequency_per_pair; cannot interpolate in log space")
        floor = self.zero_floor * f[f > 0].min()
        self.rpms = []
        self._interp = []
        self.ranges = []
        groups = [(np.nan, t)] if t["rpm"].isna().all() else sorted(t.groupby("rpm"), key=lambda kv: kv[0])
        for rpm, g in groups:
            sym = pd.concat([g[["d_i", "d_j", "frequency_per_pair"]],
                             g.rename(columns={"d_i": "d_j", "d_j": "d_i"})[["d_i", "d_j", "frequency_per_pair"]]])
            mean = sym.groupby(["d_i", "d_j"])["frequency_per_pair"].mean()
            u = np.unique(np.concatenate([mean.index.get_level_values(0), mean.index.get_level_values(1)]))
            F = mean.unstack().reindex(index=u, columns=u).to_numpy(float)
            if np.isnan(F).any():
                a, b = np.argwhere(np.isnan(F))[0]
                raise PBMInputError(f"collision table at rpm {rpm:g}: no row for the pair d_i = {u[a]:g}, "
                                    f"d_j = {u[b]:g}; every pair of the table's sizes is needed")
            logF = np.log(np.maximum(F, floor))
            lu = np.log(u)
            if u.size == 1:
                interp = (lambda value: (lambda pts: np.full(pts.shape[0], value)))(logF[0, 0])
            else:
                interp = RegularGridInterpolator((lu, lu), logF, method="linear", bounds_error=False,
                                                 fill_value=None)
            self.rpms.append(float(rpm))
            self._interp.append(interp)
            self.ranges.append((float(u[0]), float(u[-1])))
        self.rpms = np.array(self.rpms)

    def __repr__(self) -> str:
        speeds = "any" if np.isnan(self.rpms).all() else ",".join(f"{r:g}" for r in self.rpms)
        return f"TableFrequency(rpm=[{speeds}], extrapolation={self.extrapolation!r})"

    @classmethod
    def from_csv(cls, path, distribution: str | None = None, **kwargs) -> "TableFrequency":
        """Read a collision table CSV; ``distribution`` keeps only that distribution's rows."""
        import pandas as pd

        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"collision table {path} does not exist")
        table = pd.read_csv(path)
        if distribution is not None:
            if "distribution" not in table.columns:
                raise PBMInputError(f"{path}: no 'distribution' column to select {distribution!r}")
            names = sorted(table["distribution"].astype(str).unique())
            table = table[table["distribution"].astype(str) == distribution]
            if table.empty:
                raise PBMInputError(f"{path}: no rows for distribution {distribution!r}; present: {names}")
        return cls(table, **kwargs)

    def _log_matrix(self, k: int, d: np.ndarray) -> np.ndarray:
        ld = np.log(d)
        if self.extrapolation == "clamp":
            lo, hi = self.ranges[k]
            ld = np.clip(ld, np.log(lo), np.log(hi))
        A, B = np.meshgrid(ld, ld, indexing="ij")
        L = self._interp[k](np.column_stack([A.ravel(), B.ravel()])).reshape(d.size, d.size)
        return 0.5 * (L + L.T)

    def __call__(self, diameters, numbers, rpm) -> np.ndarray:
        d = np.atleast_1d(np.asarray(diameters, float))
        if not np.all(np.isfinite(d) & (d > 0)):
            raise PBMInputError(f"TableFrequency: diameters must be finite and > 0, got {d}")
        if self.rpms.size == 1 or np.isnan(self.rpms).all():
            return np.exp(self._log_matrix(0, d))
        rpm = float(rpm)
        if rpm <= self.rpms[0]:
            return np.exp(self._log_matrix(0, d))
        if rpm >= self.rpms[-1]:
            return np.exp(self._log_matrix(self.rpms.size - 1, d))
        k = int(np.searchsorted(self.rpms, rpm, side="right") - 1)
        if rpm == self.rpms[k]:
            return np.exp(self._log_matrix(k, d))
        w = (rpm - self.rpms[k]) / (self.rpms[k + 1] - self.rpms[k])
        return np.exp((1 - w) * self._log_matrix(k, d) + w * self._log_matrix(k + 1, d))
