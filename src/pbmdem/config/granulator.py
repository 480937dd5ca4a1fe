"""The granulator and its charge: bowl, impeller, settled bed, granule material.

These objects own the physical quantities derived from the geometry: the impeller's tip speed,
angular speed and Froude number at a given rpm, the height the blades reach, and the solid
volume of the settled bed (the DEM bed and the PBM hold the same solid volume, so the PBM's
number of granules is the DEM's particle count).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .typed import Settings

#: standard gravity (m/s2), for the Froude number
GRAVITY = 9.80665


def tip_speed(rpm, tip_radius: float):
    """Tip speed 2 pi R rpm / 60 (m/s) of an impeller of radius `tip_radius` (m) at `rpm` (a number
    or an array): the one formula, used by `Granulator.tip_speed` and the surrogate's features."""
    return 2.0 * math.pi * tip_radius * rpm / 60.0


@dataclass(frozen=True)
class Bowl(Settings):
    """Closed cylindrical bowl: inner diameter and height up to the lid (m), facets of its STL."""

    diameter: float
    height: float
    segments: int

    @property
    def radius(self) -> float:
        return 0.5 * self.diameter


@dataclass(frozen=True)
class Impeller(Settings):
    """Bladed impeller on the bowl's axis (lengths in m, pitch in degrees)."""

    blades: int
    blade_length: float
    blade_height: float
    blade_thickness: float
    clearance: float
    pitch_deg: float
    hub_diameter: float

    @property
    def tip_radius(self) -> float:
        """Distance from the axis to the blade tip (m)."""
        return self.blade_length

    @property
    def top(self) -> float:
        """Highest z reached by the blades (m), the pitch taken into account."""
        pitch = math.radians(self.pitch_deg)
        half_extent = 0.5 * (self.blade_height * abs(math.cos(pitch)) + self.blade_thickness * abs(math.sin(pitch)))
        return self.clearance + 0.5 * self.blade_height + half_extent


@dataclass(frozen=True)
class Bed(Settings):
    """The settled bed of granules: its height (m) and the packing fraction of its granules
    (config keys dem.bed_height and dem.packing_fraction)."""

    height: float
    packing_fraction: float


@dataclass(frozen=True)
class Granulator(Settings):
    """Bowl, impeller and settled bed of the batch granulator."""

    bowl: Bowl
    impeller: Impeller
    bed: Bed

    @staticmethod
    def angular_speed(rpm) -> float:
        """Impeller angular speed omega = 2 pi rpm / 60 (rad/s)."""
        return 2.0 * math.pi * rpm / 60.0

    def tip_speed(self, rpm):
        """Impeller tip speed omega R = 2 pi R rpm / 60 (m/s) at `rpm` (a number or a numpy array)."""
        return tip_speed(rpm, self.impeller.tip_radius)

    def froude_number(self, rpm):
        """Fr = omega^2 R / g at the blade tip: centrifugal over gravitational acceleration."""
        return self.angular_speed(rpm) ** 2 * self.impeller.tip_radius / GRAVITY

    @property
    def particle_diameter_limit(self) -> float:
        """Every DEM particle diameter must stay below this (m): three diameters must fit in the
        space between the blade top and the lid, and two within the bowl radius."""
        return min((self.bowl.height - self.impeller.top) / 3.0, self.bowl.radius / 2.0)

    @property
    def bed_solid_volume(self) -> float:
        """Solid volume of the settled bed (m3): bed height x bowl floor area x packing fraction.
        The DEM bed of every operating point and the PBM's population hold this volume."""
        return self.bed.height * math.pi / 4 * self.bowl.diameter**2 * self.bed.packing_fraction


@dataclass(frozen=True)
class Material(Settings):
    """Granule material of the DEM: density (kg/m3), Young's modulus (Pa), Poisson ratio,
    restitution, sliding and rolling friction."""

    density: float
    youngs_modulus: float
    poisson_ratio: float
    restitution: float
    friction: float
    rolling_friction: float
