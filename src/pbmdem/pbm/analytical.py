"""Closed-form solutions of pure aggregation from an exponential initial distribution.

Initial number density n(v, 0) = (N0 / m) exp(-v / m) (mean volume m, total volume N0 m).

Constant kernel beta (Scott 1968, J. Atmos. Sci. 25:54; Smoluchowski), with T = beta N0 t:
    n(v, t) = N0 / m * 4 / (T + 2)^2 * exp(-2 v / (m (T + 2)))
    M0 = 2 N0 / (T + 2),  M1 = N0 m,  M2 = 2 N0 m^2 + beta M1^2 t.

Sum (Golovin) kernel beta(u, v) = b (u + v) (Golovin 1963; Scott 1968), tau = 1 - exp(-b N0 m t):
    n(v, t) = N0 (1 - tau) / (v sqrt(tau)) exp(-(1 + tau) v / m) I1(2 v sqrt(tau) / m)
    M0 = N0 (1 - tau),  M1 = N0 m,  M2 = 2 N0 m^2 / (1 - tau)^2.
"""

from __future__ import annotations

import numpy as np


def constant_number_density(v, t, beta, N0, m):
    T = beta * N0 * t
    return N0 / m * 4.0 / (T + 2.0) ** 2 * np.exp(-2.0 * np.asarray(v, float) / (m * (T + 2.0)))


def constant_moments(t, beta, N0, m):
    T = beta * N0 * t
    M1 = N0 * m
    return 2.0 * N0 / (T + 2.0), M1, 2.0 * N0 * m * m + beta * M1 * M1 * t


def constant_cumulative_mass(v, t, beta, N0, m):
    """Fraction of the solid volume in particles smaller than v (the density stays exponential)."""
    z = np.asarray(v, float) * 2.0 / (m * (beta * N0 * t + 2.0))
    return 1.0 - np.exp(-z) * (1.0 + z)


def sum_tau(t, b, N0, m):
    return 1.0 - np.exp(-b * N0 * m * t)


def sum_number_density(v, t, b, N0, m):
    from scipy import special

    v = np.asarray(v, float)
    tau = sum_tau(t, b, N0, m)
    if tau == 0.0:
        return N0 / m * np.exp(-v / m)
    sq = np.sqrt(tau)
    z = 2.0 * v * sq / m
    # exp(-(1+tau) v/m) I1(z) = exp(-(1 - sqrt(tau))^2 v/m) * ive(1, z)
    return N0 * (1.0 - tau) / (v * sq) * np.exp(-((1.0 - sq) ** 2) * v / m) * special.ive(1, z)


def sum_moments(t, b, N0, m):
    tau = sum_tau(t, b, N0, m)
    return N0 * (1.0 - tau), N0 * m, 2.0 * N0 * m * m / (1.0 - tau) ** 2


def cell_integrals(density, edges):
    """Number and volume of a number density ``density(v)`` in each cell [edges[k], edges[k+1]]."""
    from scipy import integrate

    num, vol = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        num.append(integrate.quad(density, a, b, limit=200, epsrel=1e-12, epsabs=0)[0])
        vol.append(integrate.quad(lambda v: v * density(v), a, b, limit=200, epsrel=1e-12, epsabs=0)[0])
    return np.array(num), np.array(vol)


def exponential_cells(edges, N0, m):
    """Closed-form number and volume of the exponential density in cells bounded by ``edges``."""
    e = np.asarray(edges, float) / m
    ex = np.exp(-e)
    num = N0 * (ex[:-1] - ex[1:])
    w = np.where(np.isinf(e), 0.0, (1.0 + np.where(np.isinf(e), 0, e)) * ex)
    vol = N0 * m * (w[:-1] - w[1:])
    return num, vol


def product_moments(t, b, M0, M1, M2):
    """(M0, M1, M2) of the product kernel beta = b u v before gelation, from the initial moments
    (any initial distribution): dM0/dt = -b M1^2 / 2, M1 constant, dM2/dt = b M2^2, so
    M2 = M2(0) / (1 - b M2(0) t) and gelation at t = 1 / (b M2(0))."""
    t_gel = 1.0 / (b * M2)
    if t >= t_gel:
        raise ValueError(f"product kernel: t = {t:g} is at or beyond gelation t_gel = {t_gel:g}")
    return M0 - 0.5 * b * M1 * M1 * t, M1, M2 / (1.0 - b * M2 * t)


def monodisperse_numbers(kernel: str, t: float, k) -> np.ndarray:
    """Number of k-mers (k = 1, 2, ...; unit monomer volume) at time t from one monomer per unit
    volume, c_1(0) = 1, for the kernels beta = 1 (``"constant"``), i + j (``"sum"``) and i j
    (``"product"``, before gelation at t = 1): the classical discrete solutions (Smoluchowski;
    Golovin; McLeod 1962), evaluated in logs so that large k do not overflow."""
    from scipy.special import gammaln

    k = np.asarray(k, float)
    if kernel == "constant":
        tau = 0.5 * t  # c_k = tau^(k-1) / (1 + tau)^(k+1)
        return np.exp((k - 1) * np.log(tau) - (k + 1) * np.log1p(tau)) if tau > 0 else (k == 1) * 1.0
    if kernel == "sum":
        tau = -np.expm1(-t)  # c_k = (1-tau) (k tau)^(k-1) e^(-k tau) / k!
        if tau == 0:
            return (k == 1) * 1.0
        return np.exp(np.log1p(-tau) + (k - 1) * np.log(k * tau) - k * tau - gammaln(k + 1))
    if kernel == "product":
        if not 0 <= t < 1:
            raise ValueError(f"product kernel: t = {t:g}; the solution holds before gelation at t = 1")
        if t == 0:
            return (k == 1) * 1.0  # c_k = k^(k-3) t^(k-1) e^(-k t) / (k-1)!
        return np.exp((k - 3) * np.log(k) + (k - 1) * np.log(t) - k * t - gammaln(k))
    raise ValueError(f"kernel {kernel!r}; allowed: 'constant', 'sum', 'product'")
