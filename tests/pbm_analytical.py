"""Closed-form solutions of pure aggregation, pure breakage and aggregation with breakage from an
exponential initial distribution.

Initial number density n(v, 0) = (N0 / m) exp(-v / m) (mean volume m, total volume N0 m).

Constant kernel beta (Scott 1968, J. Atmos. Sci. 25:54; Smoluchowski), with T = beta N0 t:
    n(v, t) = N0 / m * 4 / (T + 2)^2 * exp(-2 v / (m (T + 2)))
    M0 = 2 N0 / (T + 2),  M1 = N0 m,  M2 = 2 N0 m^2 + beta M1^2 t.

Sum (Golovin) kernel beta(u, v) = b (u + v) (Golovin 1963; Scott 1968), tau = 1 - exp(-b N0 m t):
    n(v, t) = N0 (1 - tau) / (v sqrt(tau)) exp(-(1 + tau) v / m) I1(2 v sqrt(tau) / m)
    M0 = N0 (1 - tau),  M1 = N0 m,  M2 = 2 N0 m^2 / (1 - tau)^2.

Breakage with uniform daughters b(v|u) = 2/u and selection S(v) = a v^p (Ziff & McGrady 1985,
J. Phys. A 18:3027), with x = v/m and tau = a m^p t:
    p = 1: n(v, t) = N0 / m (1 + tau)^2 exp(-(1 + tau) x);  M0 = N0 (1 + tau), M2 = 2 N0 m^2 / (1 + tau)
    p = 2: n(v, t) = N0 / m exp(-tau x^2 - x) (1 + 2 tau (1 + x));  M0 = N0 (1 + 2 tau J0),
           M2 = N0 m^2 (J0 + J1), with J_k = int_0^inf x^k exp(-tau x^2 - x) dx
    (J0 = sqrt(pi / (4 tau)) erfcx(1 / (2 sqrt(tau))), J1 = (1 - J0) / (2 tau)); M1 = N0 m.
Both satisfy dn/dt = -S(v) n + int_v^inf S(u) b(v|u) n(u) du (tests/test_pbm_breakage.py checks
it by quadrature).

Constant aggregation beta with linear selection S = s v and any binary fragments: the number obeys
dM0/dt = s M1 - beta M0^2 / 2, so M0(t) = A (M0(0) + A tanh(theta)) / (A + M0(0) tanh(theta)) with
A = sqrt(2 s M1 / beta), theta = A beta t / 2. With uniform daughters the steady state is
n(v) = (2 s / beta) exp(-lambda v), lambda = sqrt(2 s / (beta M1)) (an exponential: aggregation
births (beta/2) A^2 v e^(-lambda v) balance breakage deaths s v A e^(-lambda v); Patil & Andrews
1998, Chem. Eng. Sci. 53:599; Lage 2002, Chem. Eng. Sci. 57:4253).
"""

from __future__ import annotations

import numpy as np
from scipy import integrate, special
from scipy.special import erfcx, gammaln


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


#: selection exponents p of the Ziff-McGrady solutions (S = a v^p, uniform daughters)
BREAKAGE_EXPONENTS = (1, 2)


def _breakage_tau(t, a, exponent, m):
    if exponent not in BREAKAGE_EXPONENTS:
        raise ValueError(f"breakage selection exponent {exponent!r}; allowed: {list(BREAKAGE_EXPONENTS)}")
    return a * m**exponent * t


def breakage_number_density(v, t, a, exponent, N0, m):
    """n(v, t) of pure breakage with uniform daughters and S = a v^exponent (exponent 1 or 2)
    from the exponential n(v, 0) = N0/m exp(-v/m) (Ziff & McGrady 1985)."""
    tau = _breakage_tau(t, a, exponent, m)
    x = np.asarray(v, float) / m
    if exponent == 1:
        return N0 / m * (1.0 + tau) ** 2 * np.exp(-(1.0 + tau) * x)
    return N0 / m * np.exp(-tau * x * x - x) * (1.0 + 2.0 * tau * (1.0 + x))


def breakage_moments(t, a, exponent, N0, m):
    """(M0, M1, M2) of :func:`breakage_number_density`."""
    tau = _breakage_tau(t, a, exponent, m)
    if exponent == 1:
        return N0 * (1.0 + tau), N0 * m, 2.0 * N0 * m * m / (1.0 + tau)
    if tau == 0:
        return N0, N0 * m, 2.0 * N0 * m * m
    J0 = np.sqrt(np.pi / (4.0 * tau)) * erfcx(0.5 / np.sqrt(tau))
    J1 = (1.0 - J0) / (2.0 * tau)
    return N0 * (1.0 + 2.0 * tau * J0), N0 * m, N0 * m * m * (J0 + J1)


def aggregation_breakage_number(t, beta, s, M0, M1):
    """Total number at t of constant aggregation ``beta`` with binary breakage at the linear
    selection S = s v, from M0 particles carrying the volume M1: the Riccati solution of
    dM0/dt = s M1 - beta M0^2 / 2."""
    A = np.sqrt(2.0 * s * M1 / beta)
    th = np.tanh(0.5 * A * beta * t)
    return A * (M0 + A * th) / (A + M0 * th)


def aggregation_breakage_steady_density(v, beta, s, M1):
    """The steady number density of constant aggregation ``beta`` with uniform-daughter breakage at
    S = s v, for the total volume M1: (2 s / beta) exp(-lambda v), lambda = sqrt(2 s / (beta M1))."""
    lam = np.sqrt(2.0 * s / (beta * M1))
    return 2.0 * s / beta * np.exp(-lam * np.asarray(v, float))


def cell_integrals(density, edges):
    """Number and volume of a number density ``density(v)`` in each cell [edges[k], edges[k+1]]."""
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


def solution(kernel, v, t, N0, m):
    """Number density n(v, t) (1/m3) of a ConstantKernel or SumKernel for the exponential start."""
    if hasattr(kernel, "beta0"):
        return constant_number_density(v, t, kernel.beta0, N0, m)
    return sum_number_density(v, t, kernel.b, N0, m)


def moments(kernel, t, N0, m):
    """(M0, M1, M2) of a ConstantKernel or SumKernel for the exponential start."""
    if hasattr(kernel, "beta0"):
        return constant_moments(t, kernel.beta0, N0, m)
    return sum_moments(t, kernel.b, N0, m)
