"""Camera rays in compiled code: image-plane points of film positions and pinhole or thin-lens
directions (see :class:`rtmesh.scene.camera.Camera`).
"""

import math

import numpy as np

from rtmesh.core.compiled import kernel, row
from rtmesh.core.row_vectors import floor_quotient, normalized3


# ------------------------------------------------------------------ camera
@row
def image_plane_point(x, y, pixel, width, inverse_width, image_plane):
    """Image-plane coordinates ``(sx, sy)`` at unit distance along the camera's forward axis
    of film position ``(x, y)``, given in pixels, or inside pixel ``pixel`` (when >= 0)."""
    return image_plane_xy(x, y, pixel, width, inverse_width, image_plane[0], image_plane[1], image_plane[2],
                          image_plane[3])


@row
def image_plane_xy(x, y, pixel, width, inverse_width, ax, bx, ay, by):
    """:func:`image_plane_point` with the image-plane map ``(ax, bx, ay, by)`` given as
    numbers: a compiled function that takes them instead of the array holds no reference
    to count (see :func:`rtmesh.rendering.direct_blocks.camera_block`)."""
    if pixel >= 0:
        row = floor_quotient(pixel, width, inverse_width)
        x, y = x + np.float64(pixel - row * width), y + np.float64(row)
    return x * ax + bx, y * ay + by


@row
def pinhole_direction(sx, sy, forward, right, up):
    """Unit direction of the pinhole ray through image-plane point ``(sx, sy)``."""
    return pinhole_xyz(sx, sy, forward[0], forward[1], forward[2], right[0], right[1], right[2], up[0], up[1],
                       up[2])


@row
def thin_lens_xyz(sx, sy, lx, ly, ex, ey, ez, fx, fy, fz, rx, ry, rz, ux, uy, uz, focus):
    """Origin and unit direction ``(ox, oy, oz, dx, dy, dz)`` of the thin-lens ray through
    image-plane point ``(sx, sy)`` from the aperture point ``(lx, ly)`` (scene units along
    right and up, :meth:`rtmesh.scene.camera.Camera.lens_disk`), for the eye ``e``, the
    camera frame (forward ``f``, right ``r``, up ``u``) and the focus distance."""
    # every ray through a film point meets the pinhole ray on the plane of focus: the
    # unnormalised pinhole direction has a forward component of exactly 1, so
    # eye + focus * direction lies on the plane at depth `focus`
    ox = (ex + lx * rx) + ly * ux
    oy = (ey + lx * ry) + ly * uy
    oz = (ez + lx * rz) + ly * uz
    dx = (ex + ((fx + rx * sx) + ux * sy) * focus) - ox
    dy = (ey + ((fy + ry * sx) + uy * sy) * focus) - oy
    dz = (ez + ((fz + rz * sx) + uz * sy) * focus) - oz
    dx, dy, dz = normalized3(dx, dy, dz, 1.0)
    return ox, oy, oz, dx, dy, dz


@row
def pinhole_xyz(sx, sy, fx, fy, fz, rx, ry, rz, ux, uy, uz):
    """:func:`pinhole_direction` with the camera frame (forward ``f``, right ``r``, up ``u``)
    given as numbers (see :func:`image_plane_xy`)."""
    # forward, right and up are orthonormal, so the squared length of
    # forward + sx right + sy up is 1 + sx^2 + sy^2
    inv = 1.0 / math.sqrt((sx * sx + sy * sy) + 1.0)
    sx, sy = sx * inv, sy * inv
    return (inv * fx + sx * rx) + sy * ux, (inv * fy + sx * ry) + sy * uy, (inv * fz + sx * rz) + sy * uz


@kernel
def camera_rays(film_xy, pixels, width, disk, position, forward, right, up, image_plane, focus):
    """Primary rays through film positions; see :meth:`rtmesh.scene.camera.Camera.generate_rays`.

    Parameters
    ----------
    film_xy : (n, 2) float
        Film positions in pixels, or positions inside ``pixels``.
    pixels : (n,) int or (0,)
        Linear pixel index (``row * width + column``) of each ray, or empty when
        ``film_xy`` holds whole-film positions.
    width : int
        Image width in pixels.
    disk : (n, 2) float or (0, 2)
        Lens positions (points on the aperture disk, scene units, in the right/up plane);
        empty for a pinhole camera.
    position, forward, right, up : (3,) float64
        Eye and camera frame.
    image_plane : (4,) float64
        ``(ax, bx, ay, by)``: the image-plane coordinates at unit distance along
        ``forward`` are ``sx = x ax + bx`` and ``sy = y ay + by``.
    focus : float
        Focus distance (thin lens).

    Returns
    -------
    origins : (n, 3) float64, or (0, 3) for a pinhole camera (every ray starts at the eye)
    directions : (n, 3) float64
        Unit directions, component-major.
    """
    n = len(film_xy)
    lens, in_pixels = len(disk) > 0, len(pixels) > 0
    origins = np.empty((3, n if lens else 0))
    d = np.empty((3, n))
    inverse_width = 1.0 / width
    for i in range(n):
        sx, sy = image_plane_point(film_xy[i, 0], film_xy[i, 1], pixels[i] if in_pixels else -1, width,
                                    inverse_width, image_plane)
        if lens:
            origins[0, i], origins[1, i], origins[2, i], d[0, i], d[1, i], d[2, i] = thin_lens_xyz(
                sx, sy, disk[i, 0], disk[i, 1], position[0], position[1], position[2], forward[0], forward[1],
                forward[2], right[0], right[1], right[2], up[0], up[1], up[2], focus)
        else:
            d[0, i], d[1, i], d[2, i] = pinhole_direction(sx, sy, forward, right, up)
    return origins.T, d.T
