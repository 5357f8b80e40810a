"""Cameras: pinhole and thin-lens perspective, and orthographic."""

import math
from dataclasses import dataclass

import numpy as np

from rtmesh.core.errors import CameraError
from rtmesh.core.rays import repeated_row
from rtmesh.sampling.warps import square_to_uniform_disk_concentric
from rtmesh.scene import camera_rays

PROJECTIONS = ("perspective", "orthographic")


@dataclass
class Camera:
    """A perspective (pinhole or thin-lens) or orthographic camera.

    Attributes
    ----------
    position : (3,) float
        Eye position, scene units.
    look_at : (3,) float
        Point the camera looks at.
    up : (3,) float
        Approximate up direction; made orthogonal to the view direction.
    fov : float
        Vertical field of view, degrees: more than 0 and less than 180 (a pinhole maps
        the image plane at unit distance; 180 degrees would be an infinite plane).
    aperture : float
        Lens diameter, scene units.  0 gives a pinhole camera (everything sharp).
    focus_distance : float or None
        Distance along the view direction that is in focus; None means ``|look_at - position|``.
    shutter : (2,) float
        Times the shutter opens and closes (the time unit of object motion, see
        :mod:`rtmesh.geometry.motion`); equal times take an instantaneous picture (no motion blur).
    projection : {"perspective", "orthographic"}
        Orthographic rays are parallel to the view direction and start on the plane through
        ``position`` facing it (``fov`` does not apply; neither does a lens).
    ortho_height : float or None
        Height of the orthographic view, scene units (its width follows the image's
        aspect ratio); required for an orthographic camera.
    """

    position: np.ndarray
    look_at: np.ndarray
    up: np.ndarray
    fov: float = 45.0
    aperture: float = 0.0
    focus_distance: float | None = None
    shutter: tuple = (0.0, 0.0)
    projection: str = "perspective"
    ortho_height: float | None = None

    def __post_init__(self):
        self.position = np.asarray(self.position, dtype=np.float64)
        self.look_at = np.asarray(self.look_at, dtype=np.float64)
        self.up = np.asarray(self.up, dtype=np.float64)
        self.shutter = (float(self.shutter[0]), float(self.shutter[1]))
        if not 0.0 < self.fov < 180.0:  # NaN included
            raise CameraError(f"camera fov must be more than 0 and less than 180 degrees (got {self.fov!r})")
        if self.projection not in PROJECTIONS:
            raise CameraError(f"camera projection must be one of {', '.join(PROJECTIONS)}")
        if self.orthographic:
            if not (self.ortho_height is not None and 0.0 < self.ortho_height < math.inf):
                raise CameraError("an orthographic camera needs ortho_height > 0")
            if self.aperture > 0.0:
                raise CameraError("an orthographic camera has no lens (aperture must be 0)")

    @property
    def orthographic(self):
        """True for an orthographic camera."""
        return self.projection == "orthographic"

    def frame(self):
        """Orthonormal camera frame.

        Returns
        -------
        forward, right, up : (3,) float
            Unit vectors: viewing direction, image right, image up.

        Raises
        ------
        CameraError
            If the camera looks at its own position or ``up`` is parallel to the view (also
            where the renderer's re-centred frame makes them so); a user error.
        """
        forward = self.look_at - self.position
        length = np.linalg.norm(forward)
        # (apart by less than 1e-12 of their size, the renderer's re-centred frame, which
        # subtracts the scene's centre, could not tell them apart: coincident too)
        if not length > 1e-12 * max(np.linalg.norm(self.position), np.linalg.norm(self.look_at)):
            raise CameraError("camera position and look_at coincide")
        forward = forward / length
        right = _cross(forward, self.up)
        r = np.linalg.norm(right)
        if not r > 1e-9:
            raise CameraError("camera up is parallel to the viewing direction")
        right = right / r
        return forward, right, _cross(right, forward)

    @property
    def focus(self):
        """Focus distance in scene units."""
        if self.focus_distance is not None:
            return float(self.focus_distance)
        return math.dist(self.look_at, self.position)

    def image_plane(self, width, height):
        """The map from film positions to the image plane at unit distance along forward.

        Parameters
        ----------
        width, height : int
            Image size in pixels.

        Returns
        -------
        (4,) float64
            ``(ax, bx, ay, by)``: film position ``(x, y)`` (pixels, y down) lies at
            ``sx = x ax + bx``, ``sy = y ay + by`` on the plane, each an affine map of one
            film coordinate.
        """
        # orthographic: the same affine map onto the view plane, in scene units
        tan_half = 0.5 * self.ortho_height if self.orthographic else np.tan(np.radians(self.fov) * 0.5)
        aspect = width / height
        return np.array([2.0 * tan_half * aspect / width, -tan_half * aspect, -2.0 * tan_half / height, tan_half])

    def _orthographic_rays(self, film_xy, pixels, width, image_plane, forward, right, up):
        """Parallel rays from the view plane (see :meth:`generate_rays`)."""
        x, y = film_xy[:, 0], film_xy[:, 1]
        if pixels is not None:
            pixels = np.asarray(pixels, dtype=np.int64)
            x, y = x + pixels % width, y + pixels // width
        sx = x * image_plane[0] + image_plane[1]
        sy = y * image_plane[2] + image_plane[3]
        origins = self.position + sx[:, None] * right + sy[:, None] * up
        # a real component-major array: later stages may gather or update direction rows
        return origins, np.asfortranarray(np.broadcast_to(forward, origins.shape), dtype=np.float64)

    def lens_disk(self, lens_uv):
        """Points on the thin-lens aperture of uniform samples of the square.

        Thin lens: rays start on the aperture and meet on the plane of focus, so that plane
        is sharp and everything else blurs with distance from it.

        Parameters
        ----------
        lens_uv : (n, 2) float
            Uniform samples in [0, 1)^2.

        Returns
        -------
        (n, 2) float64
            Scene units along the camera's right and up axes; (0, 2) for a pinhole camera.
        """
        if not self.aperture > 0.0:
            return np.zeros((0, 2))
        return square_to_uniform_disk_concentric(lens_uv) * (0.5 * self.aperture)

    def generate_rays(self, film_xy, width, height, lens_uv=None, pixels=None, frame=None):
        """Primary rays through continuous film positions.

        Parameters
        ----------
        film_xy : (n, 2) float
            Film positions in pixels: x in [0, width) to the right, y in [0, height)
            downwards (row 0 is the top of the image); with ``pixels``, positions inside
            those pixels (from their top-left corners).
        width, height : int
            Image size in pixels.
        lens_uv : (n, 2) float, optional
            Uniform samples in [0, 1)^2 for the aperture; ignored for a pinhole camera.
        pixels : (n,) int, optional
            Linear index (``row * width + column``) of the pixel of each ray.
        frame : tuple of three (3,) float, optional
            :meth:`frame`, if the caller has it already.

        Returns
        -------
        origins : (n, 3) float64
        directions : (n, 3) float64
            Unit directions, component-major (see :mod:`rtmesh.core.rays`).
        """
        forward, right, up = self.frame() if frame is None else frame
        image_plane = self.image_plane(width, height)
        if self.orthographic:
            return self._orthographic_rays(np.asarray(film_xy, dtype=np.float64), pixels, width, image_plane,
                                           forward, right, up)
        disk = np.zeros((0, 2)) if lens_uv is None else self.lens_disk(lens_uv)
        origins, directions = camera_rays.camera_rays(
            np.asarray(film_xy, dtype=np.float64), np.zeros(0, np.int64) if pixels is None else pixels, width,
            disk, self.position, forward, right, up, image_plane, self.focus)
        if not len(disk):
            # every ray starts at the eye: a read-only repeated row, which the Accel hands
            # to Embree without materialising it
            origins = repeated_row(np.ascontiguousarray(self.position, dtype=np.float64), len(directions))
        return origins, directions


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
        Vertical field of view, degrees: more than 0 and less than 180 (a pinhole maps
        the image plane at unit distance; 180 degrees would be an infinite plane).
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
    radius = 0.5 * float(np.linalg.norm(bounds[1] - bounds[0]))
    if not radius > 0.0:  # a single point: a size relative to where it is
        radius = max(1e-6 * float(np.abs(centre).max()), 1e-6)
    half_v = np.radians(fov) * 0.5
    half_h = np.arctan(np.tan(half_v) * aspect)
    distance = 1.05 * radius / np.sin(min(half_v, half_h))
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    return Camera(position=centre + d * distance, look_at=centre, up=np.asarray(up, float), fov=fov)


# a part of the scene this many times smaller than the whole would be far below a pixel
OUTLIER_RATIO = 1e6


def framing_bounds(vertices, faces, focus=None):
    """The faces a render keeps: all of them, or their main cluster when faces far away would
    shrink the rest below a pixel (and below the precision of the renderer's float32 frame,
    centred on the scene's bounds); an automatic camera frames what is kept.

    Faces split into clusters along an axis where no face's extent bridges the gap between
    them.  The cluster with the most faces (the one nearest the origin among equals) is
    the main one, and is split again, for as long as the part kept is more than
    :data:`OUTLIER_RATIO` times smaller than what it was cut from (largest extent over the
    three axes).  Any ordinary scene (objects side by side, a sky dome around a figure, a
    card above a floor) keeps every face.  The faces are sorted only where the vertices leave
    a gap of a 512th of the scene along some axis (:func:`_has_empty_bins`), so most large
    meshes cost a few passes over their vertices.

    Parameters
    ----------
    vertices : (v, 3) float
    faces : (f, 3) int
    focus : (3,) float, optional
        A point the camera looks at (a scene's own camera): the main cluster is then the one
        nearest it, not the one with the most faces.

    Returns
    -------
    bounds : (2, 3) float
        Of the faces kept.
    keep : (k,) int or None
        The faces kept, ascending; None when they are all of them.
    """
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    points = vertices[used]
    if not _has_empty_bins(points):
        # no gap of a 512th of the scene along any axis: nothing far from the rest (the
        # common case, decided in a few passes over the vertices instead of sorting faces)
        return np.stack([points.min(axis=0), points.max(axis=0)]), None
    triangles = vertices[faces]
    lo, hi = triangles.min(axis=1), triangles.max(axis=1)
    keep = np.arange(len(faces))
    changed = True
    while changed and len(keep) > 1:
        changed = False
        for axis in range(3):
            low, high = lo[keep, axis], hi[keep, axis]
            order = np.argsort(low, kind="stable")
            reach = np.maximum.accumulate(high[order])
            cuts = np.flatnonzero(low[order][1:] > reach[:-1]) + 1
            if not len(cuts):
                continue
            starts, stops = np.concatenate([[0], cuts]), np.concatenate([cuts, [len(order)]])
            if focus is None:
                sizes = stops - starts
                centres = np.abs(0.5 * (low[order[starts]] + reach[stops - 1]))
                candidates = np.flatnonzero(sizes == sizes.max())
                main = candidates[np.argmin(centres[candidates])]
            else:  # the cluster whose span along the axis is nearest the focus
                below = low[order[starts]] - focus[axis]
                above = focus[axis] - reach[stops - 1]
                main = int(np.argmin(np.maximum(np.maximum(below, above), 0.0)))
            members = order[starts[main]:stops[main]]
            # sizes over every axis (a flat part is not small)
            whole = np.max(hi[keep].max(axis=0) - lo[keep].min(axis=0))
            part = np.max(hi[keep[members]].max(axis=0) - lo[keep[members]].min(axis=0))
            if whole > OUTLIER_RATIO * part:
                keep, changed = np.sort(keep[members]), True
                break
    kept = triangles[keep].reshape(-1, 3)
    bounds = np.stack([kept.min(axis=0), kept.max(axis=0)])
    return bounds, (None if len(keep) == len(faces) else keep)


def _has_empty_bins(points, bins=1024):
    """Whether, along some axis, two neighbouring slices of ``bins`` equal slices of the
    points' extent hold no point: a necessary condition for a gap between faces of two
    slices (a face's extent along an axis lies between its corners, so a slice no face
    covers holds no corner).  Single empty slices are common in regular meshes (an
    icosphere's vertices leave one at its equator); the faces far from the rest that
    :func:`framing_bounds` looks for leave almost every slice empty."""
    low, high = points.min(axis=0), points.max(axis=0)
    for axis in range(3):
        extent = high[axis] - low[axis]
        if not extent > 0.0:
            continue
        slot = np.minimum(((points[:, axis] - low[axis]) / extent * bins).astype(np.int64), bins - 1)
        empty = np.bincount(slot, minlength=bins) == 0
        if (empty[1:] & empty[:-1]).any():
            return True
    return False
