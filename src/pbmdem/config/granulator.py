"""The granulator and its charge (bowl, impeller, settled bed, granule material), the one owner of
the quantities derived from them (docs/architecture.md, "Settings")."""

from __future__ import annotations

import math

from .typed import Settings, setting

#: standard gravity (m/s2), for the Froude number
GRAVITY = 9.80665


def tip_speed(rpm, tip_radius: float):
    """Tip speed 2 pi R rpm / 60 (m/s) of an impeller of radius `tip_radius` (m) at `rpm` (a number
    or an array): the one formula, used by `Granulator.tip_speed` and the surrogate's features."""
    return 2.0 * math.pi * tip_radius * rpm / 60.0


class Bowl(Settings):
    """Closed cylindrical bowl: inner diameter and height up to the lid (m), facets of its STL."""

    diameter: float = setting(..., "inner bowl diameter", "m", gt=0, le=10)
    height: float = setting(..., "bowl height up to the lid", "m", gt=0, le=10)
    segments: int = setting(48, "facets around the bowl (its STL)", ge=8, le=720)

    @property
    def radius(self) -> float:
        return 0.5 * self.diameter


class Impeller(Settings):
    """Bladed impeller on the bowl's axis (lengths in m, pitch in degrees)."""

    blades: int = setting(..., "number of blades", ge=1, le=12)
    blade_length: float = setting(..., "axis to blade tip", "m", gt=0, le=10)
    blade_height: float = setting(..., "blade height", "m", gt=0, le=10)
    blade_thickness: float = setting(..., "blade thickness", "m", gt=0, le=10)
    clearance: float = setting(..., "gap under the blades", "m", ge=0, le=10)
    pitch_deg: float = setting(0.0, "blade pitch", "degree", ge=-60, le=60)
    hub_diameter: float = setting(0.01, "hub diameter", "m", gt=0, le=10)

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


class Bed(Settings):
    """The settled bed of granules: its height (m) and the packing fraction of its granules
    (config keys dem.bed_height and dem.packing_fraction, whose bounds are checked there)."""

    height: float
    packing_fraction: float


class GranulatorSection(Settings):
    """The `granulator:` section: bowl and impeller."""

    bowl: Bowl = setting(..., "the closed cylindrical bowl")
    impeller: Impeller = setting(..., "the bladed impeller on the bowl's axis")


class Granulator(GranulatorSection):
    """Bowl, impeller and settled bed of the batch granulator."""

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


class Material(Settings):
    """Granule material of the DEM: density (kg/m3), Young's modulus (Pa), Poisson ratio,
    restitution, sliding and rolling friction."""

    density: float = setting(..., "particle density", "kg/m3", ge=10, le=25000)
    youngs_modulus: float = setting(..., "Young's modulus", "Pa", ge=1.0e4, le=1.0e12)
    poisson_ratio: float = setting(..., "Poisson ratio", ge=0, le=0.5)
    restitution: float = setting(..., "coefficient of restitution", gt=0, le=1)
    friction: float = setting(..., "sliding friction coefficient", ge=0, le=2)
    rolling_friction: float = setting(..., "rolling friction coefficient", ge=0, le=1)
