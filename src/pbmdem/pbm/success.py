"""Aggregation success: the success probability of a pair from the surface liquid of both
granules (:class:`SuccessProbability`) and, velocity-dependent, the viscous Stokes criterion of wet
granule impacts (:class:`StokesCriterion`). docs/pbm.md ("Rate processes", Stokes criterion)
derives both and gives the references; every quantity is in SI units."""

from __future__ import annotations

import math

import numpy as np


def harmonic_mean(a, b) -> np.ndarray:
    """2 a b / (a + b) elementwise (0 where a + b = 0)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    s = a + b
    return np.divide(2.0 * a * b, s, out=np.zeros(np.broadcast(a, b).shape), where=s > 0)


def sphere_mass(d, density: float) -> np.ndarray:
    """Mass (kg) of spheres of diameter d (m) and density (kg/m3)."""
    return density * math.pi / 6.0 * np.asarray(d, float) ** 3


def viscous_stokes_number(d_i, d_j, w, viscosity: float, density: float) -> np.ndarray:
    """St_v = 4 m~ w / (3 pi mu d~^2) of granules of diameters d_i, d_j (m) and density (kg/m3)
    meeting at relative normal approach speed w (m/s) through a binder of viscosity mu (Pa s).
    Broadcasts over d_i, d_j and w."""
    m = harmonic_mean(sphere_mass(d_i, density), sphere_mass(d_j, density))
    d = harmonic_mean(d_i, d_j)
    return 4.0 * m * np.asarray(w, float) / (3.0 * math.pi * viscosity * d**2)


def layer_thickness(d, phi) -> np.ndarray:
    """Thickness (m) of a surface-liquid shell that is the volume fraction phi (0 <= phi < 1) of a
    granule of diameter d (m): d/2 (1 - (1 - phi)^(1/3))."""
    phi = np.clip(np.asarray(phi, float), 0.0, 1.0)
    return 0.5 * np.asarray(d, float) * -np.expm1(np.log1p(-phi) / 3.0)


def critical_stokes_number(h, asperity_height: float, restitution: float) -> np.ndarray:
    """St* = (1 + 1/e) ln(h / h_a) (Ennis et al. 1991); h (m) the layer thickness of the pair,
    h_a (m) the asperity height. -inf where h = 0 (no layer: nothing is held)."""
    h = np.asarray(h, float)
    with np.errstate(divide="ignore"):
        return (1.0 + 1.0 / restitution) * np.log(h / asperity_height)


class StokesCriterion:
    """Success of an impact: St_v(w) < St*, evaluated at each velocity bin's representative speed
    (docs/pbm.md, "Rate processes": the Stokes criterion); SI units: viscosity mu (Pa s),
    restitution e, asperity height h_a (m), granule density (kg/m3)."""

    def __init__(self, viscosity: float, restitution: float, asperity_height: float, density: float):
        self.viscosity, self.restitution = float(viscosity), float(restitution)
        self.asperity_height, self.density = float(asperity_height), float(density)

    def __repr__(self) -> str:
        return (
            f"StokesCriterion(viscosity={self.viscosity:g} Pa s, restitution={self.restitution:g}, "
            f"asperity_height={self.asperity_height:g} m, density={self.density:g} kg/m3)"
        )

    def critical_stokes(self, d, phi) -> np.ndarray:
        """(K, K) St* of every pair of bins with diameters d (m) and surface-liquid fractions phi."""
        h = layer_thickness(d, phi)
        return critical_stokes_number(0.5 * (h[:, None] + h[None, :]), self.asperity_height, self.restitution)

    def critical_velocity(self, d, phi) -> np.ndarray:
        """(K, K) critical approach speed w*_ij (m/s): impacts slower than w* are held (0 where
        St* <= 0)."""
        d = np.asarray(d, float)
        key = d.tobytes()
        if getattr(self, "_st1_key", None) != key:  # the PBM's bins do not move: cache per diameters
            # St_v at 1 m/s, linear in w
            self._st1 = viscous_stokes_number(d[:, None], d[None, :], 1.0, self.viscosity, self.density)
            self._st1_key = key
        return np.maximum(self.critical_stokes(d, phi), 0.0) / self._st1


class SuccessProbability:
    """psi_ij = p(phi_i) p(phi_j) from the surface-liquid volume fraction phi of both granules
    (``model`` ``"step"``, ``"logistic"`` or ``"always"``, docs/pbm.md "Rate processes"); with a
    ``velocity`` criterion (:class:`StokesCriterion`) the success of an impact at speed v also needs
    the criterion to hold at v, and :class:`CollisionKernel` needs velocity-resolved encounter rates."""

    def __init__(self, model: str = "step", threshold: float = 0.02, width: float = 0.005, velocity=None):
        self.velocity = velocity
        self.model, self.threshold, self.width = model, float(threshold), float(width)

    def __repr__(self) -> str:
        vel = "" if self.velocity is None else f", velocity={self.velocity!r}"
        return f"SuccessProbability({self.model!r}, threshold={self.threshold:g}, width={self.width:g}{vel})"

    @property
    def velocity_dependent(self) -> bool:
        """True if the success also depends on the impact velocity (``velocity`` criterion set)."""
        return self.velocity is not None

    def per_particle(self, phi: np.ndarray) -> np.ndarray:
        """p(phi) of every granule: the compiled success model (``_compiled.success_probability``,
        the one the model's rates use)."""
        from . import _compiled  # lazy: numba + compiled cache ~3 s (measured), loaded when a model is built

        phi = np.asarray(phi, float)
        p = np.empty(phi.size)
        _compiled.success_probability(
            _compiled.SUCCESS_CODES[self.model], self.threshold, self.width, np.ascontiguousarray(phi).ravel(), p
        )
        return p.reshape(phi.shape)

    def __call__(self, phi: np.ndarray) -> np.ndarray:
        p = self.per_particle(phi)
        return np.outer(p, p)
