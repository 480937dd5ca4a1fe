"""Closed-form solution of two-component aggregation with the constant kernel from the bivariate
exponential start (the two-dimensional PBM's verification: solid volume x, liquid volume y).

Start: n(x, y, 0) = N0 / (mx my) exp(-x / mx - y / my), independent exponentials of mean mx and my.
Constant kernel beta (event rate beta N_a N_b of a pair of particles; dN/dt = -beta N^2 / 2), with
tau = beta N0 t / 2 and theta = tau / (1 + tau) (Lushnikov 1976, J. Colloid Interface Sci. 54:94;
Gelbard & Seinfeld 1978, J. Colloid Interface Sci. 63:472):

    n(x, y, t) = N0 / ((1 + tau)^2 mx my) exp(-x / mx - y / my) I0(2 sqrt(theta x y / (mx my))).

Derivation: with a constant kernel the number of k-fold aggregates (k monomers) is Smoluchowski's
N_k = N0 theta^(k-1) / (1 + tau)^2 whatever the monomers are, and a k-fold aggregate of
independent exponential monomers has x ~ Gamma(k, mx) and y ~ Gamma(k, my), independent; summing
N_k Gamma_k(x) Gamma_k(y) over k gives the series of I0. Hence:

* the size marginal sum_k N_k Gamma_k(x) = N0 / ((1 + tau)^2 mx) exp(-x / ((1 + tau) mx)), Scott's
  one-dimensional solution (``analytical.constant_number_density`` with T = beta N0 t = 2 tau);
* the composition at a given size: P(k | x) is proportional to theta^(k-1) (x / mx)^(k-1) / (k-1)!,
  so k - 1 is Poisson with mean lam = theta x / mx, and y given k is Gamma(k, my):

      E[y | x] = my (1 + lam),   Var[y | x] = my^2 (E[k | x] + Var[k | x]) = my^2 (1 + 2 lam).

* the moments of the liquid: M01 = N0 my (conserved), M02 = 2 N0 my^2 + beta M01^2 t (d M02 / dt =
  beta M01^2: an event adds 2 y y'), M11 = N0 mx my + beta M10 M01 t.

tests/test_pbm2d.py checks the conditional moments against the density integrated over y.
"""

from __future__ import annotations

import numpy as np


def _tau(t, beta, N0):
    return 0.5 * beta * N0 * t


def bivariate_density(x, y, t, beta, N0, mx, my):
    """n(x, y, t) (1/m6 in SI) of the constant kernel from the bivariate exponential start."""
    from scipy.special import i0e

    tau = _tau(t, beta, N0)
    theta = tau / (1.0 + tau)
    x, y = np.asarray(x, float), np.asarray(y, float)
    z = 2.0 * np.sqrt(theta * x * y / (mx * my))
    return N0 / ((1.0 + tau) ** 2 * mx * my) * np.exp(z - x / mx - y / my) * i0e(z)


def size_marginal(x, t, beta, N0, mx):
    """The number density in solid volume, int n(x, y, t) dy (Scott 1968)."""
    tau = _tau(t, beta, N0)
    return N0 / ((1.0 + tau) ** 2 * mx) * np.exp(-np.asarray(x, float) / ((1.0 + tau) * mx))


def liquid_given_size(x, t, beta, N0, mx, my):
    """(mean, variance) of the liquid volume y of the particles of solid volume x."""
    tau = _tau(t, beta, N0)
    lam = tau / (1.0 + tau) * np.asarray(x, float) / mx
    return my * (1.0 + lam), my * my * (1.0 + 2.0 * lam)


def liquid_moments(t, beta, N0, mx, my):
    """(M01, M02, M11): sum over particles of y, y^2 and x y."""
    M01 = N0 * my
    return M01, 2.0 * N0 * my * my + beta * M01 * M01 * t, N0 * mx * my + beta * (N0 * mx) * M01 * t
