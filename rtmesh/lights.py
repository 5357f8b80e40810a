"""Point, directional and spot lights.

Each light answers, for a batch of shading points, the unit direction toward it, the
distance to it (``inf`` for directional lights) and the incident term ``E`` that multiplies
the material's Blinn-Phong factor: ``intensity / distance^2`` for point and spot lights
(radiant intensity in W/sr, scene units for distance), ``irradiance`` for directional lights.
"""

from dataclasses import dataclass

import numpy as np

from .batches import component_major
from .materials import as_colour
from .vecmath import norm


@dataclass
class PointLight:
    """Isotropic point light.

    Attributes
    ----------
    position : (3,) float
    intensity : (3,) float
        Radiant intensity per colour channel, W/sr.
    """

    position: np.ndarray
    intensity: np.ndarray

    def __post_init__(self):
        self.position = np.asarray(self.position, dtype=np.float64).reshape(3)
        self.intensity = as_colour(self.intensity)

    def illuminate(self, points):
        """Direction, distance and incident term at ``points``.

        Parameters
        ----------
        points : (k, 3) float

        Returns
        -------
        wi : (k, 3) float
            Unit directions from the points toward the light.
        distance : (k,) float
        incident : (k, 3) float
            ``intensity / distance^2`` (inverse-square falloff).
        """
        to_light = self.position[None, :] - points
        distance = norm(to_light)
        # a light sitting exactly on a point lights it from nowhere: direction 0, term 0
        safe = np.where(distance > 0.0, distance, np.inf)
        wi = np.divide(to_light, safe[:, None], out=to_light)  # in place: one temporary fewer
        # component-major like the points (see rtmesh.batches): the shading arithmetic
        # that combines the two then runs on contiguous columns
        incident = component_major(self.intensity[:, None] / (safe * safe))
        return wi, distance, incident

    @property
    def is_black(self):
        return not (self.intensity > 0).any()


@dataclass
class DirectionalLight:
    """Light from infinitely far away along one direction (the sun).

    Attributes
    ----------
    direction : (3,) float
        Direction the light travels (from the light toward the scene).
    irradiance : (3,) float
        Irradiance on a surface facing the light, W/m^2.
    """

    direction: np.ndarray
    irradiance: np.ndarray

    def __post_init__(self):
        d = np.asarray(self.direction, dtype=np.float64).reshape(3)
        length = np.linalg.norm(d)
        if not length > 0.0:
            raise ValueError("directional light direction has zero length")
        self.direction = d / length
        self.irradiance = as_colour(self.irradiance)

    def illuminate(self, points):
        """See :meth:`PointLight.illuminate`; the distance is ``inf``."""
        k = len(points)
        wi = np.broadcast_to(-self.direction, (k, 3))
        return wi, np.full(k, np.inf), np.broadcast_to(self.irradiance, (k, 3))

    @property
    def is_black(self):
        return not (self.irradiance > 0).any()


@dataclass
class SpotLight:
    """Point light restricted to a cone, with a smooth falloff between two angles.

    Attributes
    ----------
    position : (3,) float
    direction : (3,) float
        Cone axis (from the light outward).
    intensity : (3,) float
        Radiant intensity on the axis, W/sr.
    inner_angle, outer_angle : float
        Half-angles of the cone in degrees: full intensity inside ``inner_angle``, none
        beyond ``outer_angle``, a smoothstep in cos(angle) between them.
    """

    position: np.ndarray
    direction: np.ndarray
    intensity: np.ndarray
    inner_angle: float = 20.0
    outer_angle: float = 30.0

    def __post_init__(self):
        self.position = np.asarray(self.position, dtype=np.float64).reshape(3)
        d = np.asarray(self.direction, dtype=np.float64).reshape(3)
        length = np.linalg.norm(d)
        if not length > 0.0:
            raise ValueError("spot light direction has zero length")
        self.direction = d / length
        self.intensity = as_colour(self.intensity)
        if not 0.0 <= self.inner_angle <= self.outer_angle <= 180.0:
            raise ValueError("spot light needs 0 <= inner_angle <= outer_angle <= 180")

    def falloff(self, cos_angle):
        """Cone falloff in [0, 1] for the cosine of the angle from the axis, (k,) -> (k,)."""
        cos_inner = np.cos(np.radians(self.inner_angle))
        cos_outer = np.cos(np.radians(self.outer_angle))
        if cos_inner - cos_outer <= 0.0:
            return (cos_angle >= cos_outer).astype(np.float64)
        x = np.clip((cos_angle - cos_outer) / (cos_inner - cos_outer), 0.0, 1.0)
        return x * x * (3.0 - 2.0 * x)

    def illuminate(self, points):
        """See :meth:`PointLight.illuminate`; the incident term includes the cone falloff."""
        to_light = self.position[None, :] - points
        distance = norm(to_light)
        safe = np.where(distance > 0.0, distance, np.inf)
        wi = np.divide(to_light, safe[:, None], out=to_light)  # in place: one temporary fewer
        cone = self.falloff(-(wi @ self.direction))
        incident = component_major(self.intensity[:, None] * (cone / (safe * safe)))
        return wi, distance, incident

    @property
    def is_black(self):
        return not (self.intensity > 0).any()
