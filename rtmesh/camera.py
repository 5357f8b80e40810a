"""Pinhole and thin-lens perspective cameras."""

from dataclasses import dataclass

import numpy as np

from .batches import component_major
from .sampling import square_to_uniform_disk_concentric
from .vecmath import normalize


@dataclass
class Camera:
    """A perspective camera.

    Attributes
    ----------
    position : (3,) float
        Eye position, scene units.
    look_at : (3,) float
        Point the camera looks at.
    up : (3,) float
        Approximate up direction; made orthogonal to the view direction.
    fov : float
        Vertical field of view, degrees.
    aperture : float
        Lens diameter, scene units.  0 gives a pinhole camera (everything sharp).
    focus_distance : float or None
        Distance along the view direction that is in focus; None means ``|look_at - position|``.
    shutter : (2,) float
        Times the shutter opens and closes (the time unit of object motion, see
        :mod:`rtmesh.motion`); equal times take an instantaneous picture (no motion blur).
    """

    position: np.ndarray
    look_at: np.ndarray
    up: np.ndarray
    fov: float = 45.0
    aperture: float = 0.0
    focus_distance: float | None = None
    shutter: tuple = (0.0, 0.0)

    def __post_init__(self):
        self.position = np.asarray(self.position, dtype=np.float64)
        self.look_at = np.asarray(self.look_at, dtype=np.float64)
        self.up = np.asarray(self.up, dtype=np.float64)
        self.shutter = (float(self.shutter[0]), float(self.shutter[1]))

    def frame(self):
        """Orthonormal camera frame.

        Returns
        -------
        forward, right, up : (3,) float
            Unit vectors: viewing direction, image right, image up.

        Raises
        ------
        ValueError
            If the camera looks at its own position or ``up`` is parallel to the view.
        """
        forward = self.look_at - self.position
        length = np.linalg.norm(forward)
        if not length > 0.0:
            raise ValueError("camera position and look_at coincide")
        forward = forward / length
        right = _cross(forward, self.up)
        r = np.linalg.norm(right)
        if not r > 1e-9:
            raise ValueError("camera up is parallel to the viewing direction")
        right = right / r
        return forward, right, _cross(right, forward)

    @property
    def focus(self):
        """Focus distance in scene units."""
        if self.focus_distance is not None:
            return float(self.focus_distance)
        return float(np.linalg.norm(self.look_at - self.position))

    def generate_rays(self, film_xy, width, height, lens_uv=None):
        """Primary rays through continuous film positions.

        Parameters
        ----------
        film_xy : (n, 2) float
            Film positions in pixels: x in [0, width) to the right, y in [0, height)
            downwards (row 0 is the top of the image).
        width, height : int
            Image size in pixels.
        lens_uv : (n, 2) float, optional
            Uniform samples in [0, 1)^2 for the aperture; ignored for a pinhole camera.

        Returns
        -------
        origins : (n, 3) float64
        directions : (n, 3) float64
            Unit directions, component-major (see :mod:`rtmesh.batches`).
        """
        forward, right, up = self.frame()
        tan_half = np.tan(np.radians(self.fov) * 0.5)
        aspect = width / height
        # image-plane coordinates at unit distance along forward, each an affine map of one
        # film coordinate (two passes instead of five)
        sx = film_xy[:, 0] * (2.0 * tan_half * aspect / width) - tan_half * aspect
        sy = film_xy[:, 1] * (-2.0 * tan_half / height) + tan_half
        n = len(film_xy)
        if self.aperture > 0.0 and lens_uv is not None:
            # thin lens: every ray through a film point meets the pinhole ray on the plane of
            # focus, so that plane is sharp and everything else blurs with distance from it.
            # d has a forward component of exactly 1, so position + focus * d lies on the
            # plane at depth `focus` (a normalised d would focus on a sphere instead, and
            # blur the off-axis parts of the focus plane)
            d = component_major(forward[:, None] + right[:, None] * sx + up[:, None] * sy)
            focus_points = self.position + d * self.focus
            disk = square_to_uniform_disk_concentric(lens_uv) * (0.5 * self.aperture)
            origins = (
                self.position[None, :]
                + disk[:, :1] * right[None, :]
                + disk[:, 1:] * up[None, :]
            )
            return origins, normalize(focus_points - origins)
        # forward, right and up are orthonormal, so |forward + sx right + sy up|^2 is
        # 1 + sx^2 + sy^2: the direction is normalised without forming its length from the
        # three components (the rounding differs from normalize() by an ulp or so)
        inv_length = sx * sx
        inv_length += sy * sy
        inv_length += 1.0
        np.sqrt(inv_length, out=inv_length)
        np.divide(1.0, inv_length, out=inv_length)
        sx *= inv_length
        sy *= inv_length
        # built component-major (one contiguous row per component; see rtmesh.batches)
        d = np.empty((3, n))
        scratch = np.empty(n)
        for c in range(3):
            np.multiply(inv_length, forward[c], out=d[c])
            d[c] += np.multiply(sx, right[c], out=scratch)
            d[c] += np.multiply(sy, up[c], out=scratch)
        # every ray starts at the eye: a read-only broadcast row, which the Accel hands to
        # Embree without materialising it
        return np.broadcast_to(self.position, (n, 3)), d.T


def _cross(a, b):
    """Cross product of two 3-vectors: np.cross's formula without its per-call overhead
    (tens of microseconds, paid for every chunk of camera rays)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def frame_bounds(bounds, fov=45.0, aspect=1.0, direction=(0.6, 0.45, 1.0), up=(0.0, 1.0, 0.0)):
    """A camera that fits an axis-aligned box in view.

    The camera looks at the centre of the box's bounding sphere from ``direction`` and backs
    off until the sphere fits in both the vertical and the horizontal field of view.

    Parameters
    ----------
    bounds : (2, 3) float
        Minimum and maximum corner, scene units.
    fov : float
        Vertical field of view, degrees.
    aspect : float
        Width / height of the image.
    direction : (3,) float
        Direction from the centre towards the camera.
    up : (3,) float
        Up vector of the camera (+y, the convention of glTF and most OBJ exporters).

    Returns
    -------
    Camera
    """
    bounds = np.asarray(bounds, dtype=np.float64)
    centre = bounds.mean(axis=0)
    radius = max(0.5 * float(np.linalg.norm(bounds[1] - bounds[0])), 1e-6)
    half_v = np.radians(fov) * 0.5
    half_h = np.arctan(np.tan(half_v) * aspect)
    distance = 1.05 * radius / np.sin(min(half_v, half_h))
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    return Camera(position=centre + d * distance, look_at=centre, up=np.asarray(up, float), fov=fov)
