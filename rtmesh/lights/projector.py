"""Projector light: a spot light that projects an image (a gobo, a slide, a window pattern).

The projector is a pinhole at ``position`` looking along ``direction``, with image ``up``
and a vertical field of view ``fov``; the image's aspect ratio sets the horizontal one.  A
point in front of it receives ``intensity * texel / distance^2`` where ``texel`` is the
image's (linear, bilinearly filtered) colour where the line from the projector to the
point crosses the image plane, and nothing outside the image's frustum or behind the
projector.  Seen from behind the projector, the projected picture is upright and not
mirrored.

It is a delta light (:class:`rtmesh.lights.interface.PointLikeLight`) that answers
:meth:`ProjectorLight.illuminate` in NumPy and has no compiled row of the Whitted kernels:
Whitted renders with it take the general path.  The path integrator gives it a row of its
light table (:mod:`rtmesh.lights.light_table`, kind ``PROJECTOR``), whose
``projector_incident`` is this mapping written for one point.
"""

from dataclasses import dataclass

import numpy as np

from rtmesh.core.vecmath import dot
from rtmesh.io.texture_images import Texture, load_texture
from rtmesh.lights.light_types import LightType, aim
from rtmesh.materials.table import as_colour


@dataclass
class ProjectorLight:
    """A pinhole projector of an image.

    Attributes
    ----------
    position : (3,) float
        The pinhole, scene units.
    direction : (3,) float
        The projection axis (from the projector toward the scene).
    intensity : (3,) float
        Radiant intensity through a white texel, W/sr.
    image : Texture
        The projected image (linear colour; load 8-bit images as sRGB).
    fov : float
        Vertical field of view, degrees, in (0, 180).
    up : (3,) float
        The image's up direction (not parallel to ``direction``).
    """

    position: np.ndarray
    direction: np.ndarray
    intensity: np.ndarray
    image: Texture
    fov: float = 30.0
    up: np.ndarray = (0.0, 1.0, 0.0)

    def __post_init__(self):
        self.position = np.asarray(self.position, dtype=np.float64).reshape(3)
        self.intensity = as_colour(self.intensity)
        if not 0.0 < self.fov < 180.0:
            raise ValueError(f"projector fov must be in (0, 180) degrees, got {self.fov}")
        forward = np.asarray(self.direction, dtype=np.float64).reshape(3)
        length = np.linalg.norm(forward)
        if not length > 0.0:
            raise ValueError("projector direction has zero length")
        self.direction = forward / length
        self.up = np.asarray(self.up, dtype=np.float64).reshape(3)
        right = np.cross(self.direction, self.up)
        if not np.linalg.norm(right) > 1e-9:
            raise ValueError("projector up is parallel to its direction")

    def frame(self):
        """Unit axes of the projector: forward, image right, image up, (3,) each."""
        right = np.cross(self.direction, self.up)
        right /= np.linalg.norm(right)
        return self.direction, right, np.cross(right, self.direction)

    def illuminate(self, points):
        """See :meth:`rtmesh.lights.interface.PointLikeLight.illuminate`.

        Parameters
        ----------
        points : (k, 3) float

        Returns
        -------
        wi : (k, 3) float64
        distance : (k,) float64
        incident : (k, 3) float64
            ``intensity * texel / distance^2`` inside the image's frustum, 0 elsewhere.
        """
        points = np.asarray(points, dtype=np.float64)
        to_light = self.position - points
        distance = np.sqrt(dot(to_light, to_light))
        # a point exactly at the pinhole is lit from nowhere, as for a point light
        safe = np.where(distance > 0.0, distance, np.inf)
        wi = to_light / safe[:, None]
        forward, right, up = self.frame()
        # where the ray from the pinhole through the point crosses the image plane at unit
        # distance; points behind the projector (depth <= 0) get none of its light
        depth = -(wi @ forward)
        ahead = depth > 0.0
        depth = np.where(ahead, depth, 1.0)
        half_height = np.tan(np.radians(self.fov) / 2.0)
        height, width = self.image.shape[:2]
        half_width = half_height * width / height
        uv = np.column_stack([0.5 - (wi @ right) / depth / (2.0 * half_width),
                              0.5 - (wi @ up) / depth / (2.0 * half_height)])
        inside = ahead & (uv >= 0.0).all(axis=1) & (uv <= 1.0).all(axis=1)
        texel = np.zeros((len(points), 3))
        if inside.any():
            colour = self.image.sample(uv[inside])
            texel[inside] = colour[:, :3] if colour.shape[1] >= 3 else colour[:, :1]
        incident = self.intensity * texel / (safe * safe)[:, None]
        return wi, distance, incident

    def kernel_row(self):
        """None: the projector has no row of the Whitted kernels (its texels are looked up in
        NumPy there; the path integrator's light table has its own row for it)."""
        return None

    @property
    def is_black(self):
        return not (self.intensity > 0).any() or not (self.image.pixels > 0).any()


def _build(values):
    image = load_texture(values["image"], srgb=True, wrap="clamp")
    return ProjectorLight(values["position"], aim(values, "projector"), values["intensity"], image,
                          values.get("fov", 30.0), values.get("up", (0.0, 1.0, 0.0)))


PROJECTOR = LightType("projector", {"position": "vec3", "direction": "vec3", "look_at": "vec3", "up": "vec3",
                                    "intensity": "colour", "image": "path", "fov": "positive"},
                      ("position", "intensity", "image"), _build)
