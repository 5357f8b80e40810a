"""Point, directional and spot lights: delta lights with a compiled row
(:mod:`rtmesh.lights.point_light_rows`); see :mod:`rtmesh.lights.interface`.

Each light answers, for a batch of shading points, the unit direction toward it, the
distance to it (``inf`` for directional lights) and the incident term ``E`` that multiplies
the material's Blinn-Phong factor: ``intensity / distance^2`` for point and spot lights
(radiant intensity in W/sr, scene units for distance), ``irradiance`` for directional lights.
"""

from dataclasses import dataclass

import numpy as np

from rtmesh.lights import point_light_rows
from rtmesh.lights.light_types import LightType, aim
from rtmesh.materials.table import as_colour


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
        return point_light_rows.illuminate_points(self.kernel_row(), points)

    def kernel_row(self):
        """The light's row for the kernels (:func:`rtmesh.lights.point_light_rows.pack_row`)."""
        return point_light_rows.pack_row(point_light_rows.POINT, self.position, power=self.intensity)

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
        return point_light_rows.illuminate_points(self.kernel_row(), points)

    def kernel_row(self):
        """See :meth:`PointLight.kernel_row`."""
        return point_light_rows.pack_row(point_light_rows.DIRECTIONAL, direction=self.direction,
                                         power=self.irradiance)

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

    def illuminate(self, points):
        """See :meth:`PointLight.illuminate`; the incident term includes the cone falloff,
        a smoothstep in cos(angle) from the axis between the outer and the inner angle."""
        return point_light_rows.illuminate_points(self.kernel_row(), points)

    def kernel_row(self):
        """See :meth:`PointLight.kernel_row`."""
        return point_light_rows.pack_row(point_light_rows.SPOT, self.position, self.direction, self.intensity,
                                         np.cos(np.radians(self.inner_angle)), np.cos(np.radians(self.outer_angle)))

    @property
    def is_black(self):
        return not (self.intensity > 0).any()


POINT = LightType("point", {"position": "vec3", "intensity": "colour"}, ("position", "intensity"),
                  lambda v: PointLight(v["position"], v["intensity"]))
DIRECTIONAL = LightType("directional", {"direction": "vec3", "irradiance": "colour"}, ("direction", "irradiance"),
                        lambda v: DirectionalLight(v["direction"], v["irradiance"]))
SPOT = LightType("spot", {"position": "vec3", "direction": "vec3", "look_at": "vec3", "intensity": "colour",
                          "inner_angle": "non_negative", "outer_angle": "non_negative"},
                 ("position", "intensity"),
                 lambda v: SpotLight(v["position"], aim(v, "spot"), v["intensity"], v.get("inner_angle", 20.0),
                                     v.get("outer_angle", 30.0)))
