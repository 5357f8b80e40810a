"""Warps: maps of the unit square onto disks, hemispheres, triangles and spherical triangles,
with their densities and inverses.

Each warp is area-preserving or has a closed-form density, so stratified points of the
square (:mod:`rtmesh.sampling.patterns`) stay stratified on the target domain.
"""

import math

import numpy as np
from numba.extending import register_jitable

from rtmesh.core.compiled import kernel, row
from rtmesh.core.row_vectors import normalized3
from rtmesh.core.vecmath import dot, normalize


def square_to_uniform_disk_concentric(u):
    """Shirley-Chiu concentric map of the unit square onto the unit disk.

    Area-preserving and low-distortion, so stratification of ``u`` survives the warp.

    Parameters
    ----------
    u : (n, 2) float
        Points in [0, 1)^2.

    Returns
    -------
    (n, 2) float
        Points in the unit disk; density 1/pi with respect to area.
    """
    return concentric_disk(*(np.ascontiguousarray(u[:, k], dtype=np.float64) for k in (0, 1)))


@kernel
def concentric_disk(u0, u1):
    """:func:`square_to_uniform_disk_concentric` of the points ``(u0, u1)`` ((n,) each), (n, 2)."""
    n = len(u0)
    out = np.empty((n, 2))
    for i in range(n):
        out[i, 0], out[i, 1] = concentric_disk_row(u0[i], u1[i])
    return out


@row
def concentric_disk_row(u0, u1):
    """Shirley-Chiu's concentric map of one point of the square to the unit disk, ``(x, y)``."""
    a = 2.0 * u0 - 1.0
    b = 2.0 * u1 - 1.0
    if abs(a) > abs(b):
        r, phi = a, (np.pi / 4.0) * (b / a)
    else:
        r, phi = b, (np.pi / 2.0) - (np.pi / 4.0) * (a / b)
    if phi != phi:  # a == b == 0 (0 / 0) maps to the centre whatever phi is
        phi = 0.0
    return r * math.cos(phi), r * math.sin(phi)


def uniform_disk_concentric_to_square(d):
    """Inverse of :func:`square_to_uniform_disk_concentric`, (n, 2) -> (n, 2).

    Each of the four sectors of angle pi/2 around the axes came from one triangle of the
    square between its centre and one side; there the side's coordinate is ``+-r`` and the
    other is proportional to the angle from the sector's axis.
    """
    r = np.hypot(d[:, 0], d[:, 1])
    # angle in [-pi/4, 7pi/4): sector k (0..3) is centred on the angle k pi/2
    phi = np.arctan2(d[:, 1], d[:, 0])
    phi = np.where(phi < -np.pi / 4.0, phi + 2.0 * np.pi, phi)
    sector = np.clip(np.floor((phi + np.pi / 4.0) / (np.pi / 2.0)), 0, 3).astype(np.int64)
    side = np.where(sector < 2, r, -r)  # +r for the sectors facing +x, +y; -r for -x, -y
    along = (phi - sector * (np.pi / 2.0)) * side / (np.pi / 4.0)
    a = np.where(sector % 2 == 0, side, -along)
    b = np.where(sector % 2 == 0, along, side)
    return np.stack([0.5 * (a + 1.0), 0.5 * (b + 1.0)], axis=1)


def square_to_uniform_disk_concentric_pdf(d):
    """Area density of :func:`square_to_uniform_disk_concentric`: ``1 / pi`` on the disk."""
    return np.where((d * d).sum(axis=1) <= 1.0, 1.0 / np.pi, 0.0)


def square_to_cosine_hemisphere(u):
    """Cosine-weighted directions on the hemisphere around +z (Malley's method).

    Parameters
    ----------
    u : (n, 2) float
        Points in [0, 1)^2.

    Returns
    -------
    (n, 3) float
        Unit directions with z >= 0; density cos(theta)/pi with respect to solid angle.
    """
    d = square_to_uniform_disk_concentric(u)
    z = np.sqrt(np.maximum(0.0, 1.0 - (d * d).sum(axis=1)))
    return np.column_stack([d, z])


def cosine_hemisphere_to_square(w):
    """Inverse of :func:`square_to_cosine_hemisphere`, (n, 3) -> (n, 2)."""
    return uniform_disk_concentric_to_square(w[:, :2])


def square_to_cosine_hemisphere_pdf(w):
    """Solid-angle density of :func:`square_to_cosine_hemisphere`: ``max(0, z) / pi``."""
    return np.maximum(0.0, w[:, 2]) / np.pi


def square_to_uniform_triangle(u):
    """Uniform points on a triangle, as barycentric weights of its vertices 1 and 2.

    ``(b1, b2) = sqrt(u0) * (1 - u1, u1)``: the Jacobian of the map is the constant 1/2, so
    the density is uniform over the triangle, and the map is continuous, so stratified
    ``u`` stay stratified on the triangle.

    Parameters
    ----------
    u : (n, 2) float
        Points in [0, 1)^2.

    Returns
    -------
    (n, 2) float
        Barycentric weights ``(b1, b2)`` with ``b1, b2 >= 0`` and ``b1 + b2 <= 1``
        (see :func:`rtmesh.geometry.accel.barycentric_interpolate`); density ``1 / area`` with respect
        to area on any triangle.
    """
    return np.stack(uniform_triangle_weights(u[:, 0], u[:, 1]), axis=1)


@register_jitable
def uniform_triangle_weights(u0, u1):
    """:func:`square_to_uniform_triangle` of ``(u0, u1)``, as the pair ``(b1, b2)``: for
    arrays, and for numbers in compiled code (:func:`rtmesh.lights.mesh_lights.choose_area_samples`)."""
    s = np.sqrt(u0)
    return s * (1.0 - u1), s * u1


def spherical_triangle_area(a, b, c):
    """Solid angle of the spherical triangles with unit-vector corners ``a, b, c``, (n,) sr.

    Van Oosterom and Strackee's formula ``tan(omega / 2) = |a . (b x c)| / (1 + a.b + b.c
    + c.a)``: no cancellation for small triangles, where the sum of the angles minus pi
    loses every digit.
    """
    triple = np.abs(dot(a, np.cross(b, c)))
    return 2.0 * np.arctan2(triple, 1.0 + dot(a, b) + dot(b, c) + dot(c, a))


def square_to_spherical_triangle(u, a, b, c):
    """Directions uniform over the spherical triangles with unit-vector corners ``a, b, c``.

    Arvo's method ("Stratified sampling of spherical triangles", SIGGRAPH 1995): ``u0``
    chooses the sub-triangle ``a, b, c'`` of area ``u0 * omega`` (``c'`` on the arc from
    ``a`` to ``c``), ``u1`` a point on the arc from ``b`` to ``c'`` with the right density.
    The map is continuous, so stratified ``u`` stay stratified.  For triangles of a tiny
    solid angle the angle sums lose their digits: use it above ~1e-4 sr.

    Parameters
    ----------
    u : (n, 2) float
        Points in [0, 1)^2.
    a, b, c : (n, 3) float
        Unit corner directions.

    Returns
    -------
    directions : (n, 3) float
        Unit directions inside the triangles; density ``1 / omega`` per steradian.
    omega : (n,) float
        Solid angles (:func:`spherical_triangle_area`).
    """
    # the angle at corner a, between the great circles through a, b and a, c
    n_ab, n_ac = normalize(np.cross(a, b)), normalize(np.cross(a, c))
    alpha = np.arccos(np.clip(dot(n_ab, n_ac), -1.0, 1.0))
    omega = spherical_triangle_area(a, b, c)
    area = u[:, 0] * omega
    s, t = np.sin(area - alpha), np.cos(area - alpha)
    cos_alpha, sin_alpha = np.cos(alpha), np.sin(alpha)
    uu = t - cos_alpha
    vv = s + sin_alpha * dot(a, b)
    denominator = (vv * s + uu * t) * sin_alpha
    q = np.clip(((vv * t - uu * s) * cos_alpha - vv) / np.where(denominator != 0.0, denominator, 1.0), -1.0, 1.0)
    c_new = q[:, None] * a + np.sqrt(np.maximum(1.0 - q * q, 0.0))[:, None] * normalize(c - dot(c, a)[:, None] * a)
    z = 1.0 - u[:, 1] * (1.0 - dot(c_new, b))
    directions = z[:, None] * b + np.sqrt(np.maximum(1.0 - z * z, 0.0))[:, None] * normalize(c_new - dot(c_new, b)[:, None] * b)
    return normalize(directions), omega


@row
def spherical_triangle_area_row(ax, ay, az, bx, by, bz, cx, cy, cz):
    """:func:`spherical_triangle_area` of one triangle of unit corners (sr), in compiled code."""
    triple = abs((ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz)) + az * (bx * cy - by * cx))
    return 2.0 * math.atan2(triple, ((1.0 + ((ax * bx + ay * by) + az * bz)) + ((bx * cx + by * cy) + bz * cz))
                            + ((cx * ax + cy * ay) + cz * az))


@row
def spherical_triangle_row(u0, u1, ax, ay, az, bx, by, bz, cx, cy, cz, omega):
    """:func:`square_to_spherical_triangle` of one point ``(u0, u1)`` and one triangle of
    unit corners whose solid angle is ``omega``, in compiled code: the unit direction."""
    nbx, nby, nbz = normalized3(ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx, 1.0)
    ncx, ncy, ncz = normalized3(ay * cz - az * cy, az * cx - ax * cz, ax * cy - ay * cx, 1.0)
    alpha = math.acos(min(max((nbx * ncx + nby * ncy) + nbz * ncz, -1.0), 1.0))
    area = u0 * omega
    s, t = math.sin(area - alpha), math.cos(area - alpha)
    cos_alpha, sin_alpha = math.cos(alpha), math.sin(alpha)
    uu = t - cos_alpha
    vv = s + sin_alpha * ((ax * bx + ay * by) + az * bz)
    denominator = (vv * s + uu * t) * sin_alpha
    q = ((vv * t - uu * s) * cos_alpha - vv) / (denominator if denominator != 0.0 else 1.0)
    q = min(max(q, -1.0), 1.0)
    ca = (cx * ax + cy * ay) + cz * az
    ox, oy, oz = normalized3(cx - ca * ax, cy - ca * ay, cz - ca * az, 1.0)
    r = math.sqrt(max(1.0 - q * q, 0.0))
    nx, ny, nz = q * ax + r * ox, q * ay + r * oy, q * az + r * oz
    z = 1.0 - u1 * (1.0 - ((nx * bx + ny * by) + nz * bz))
    nb = (nx * bx + ny * by) + nz * bz
    px, py, pz = normalized3(nx - nb * bx, ny - nb * by, nz - nb * bz, 1.0)
    r = math.sqrt(max(1.0 - z * z, 0.0))
    return normalized3(z * bx + r * px, z * by + r * py, z * bz + r * pz, 1.0)


def spherical_triangle_to_square(directions, a, b, c):
    """Inverse of :func:`square_to_spherical_triangle`: directions inside the spherical
    triangles ``a, b, c`` back to ``u``, (n, 3) -> (n, 2).

    ``c'`` is where the great circle through ``b`` and the direction meets the arc from
    ``a`` to ``c``; ``u0`` is the area of ``a, b, c'`` over the whole, ``u1`` the position
    of the direction on the arc from ``b`` to ``c'``.
    """
    c_new = normalize(np.cross(np.cross(b, directions), np.cross(a, c)))
    c_new *= np.where(dot(c_new, a + c) < 0.0, -1.0, 1.0)[:, None]  # the one between a and c
    u0 = spherical_triangle_area(a, b, c_new) / spherical_triangle_area(a, b, c)
    u1 = (1.0 - dot(directions, b)) / np.maximum(1.0 - dot(c_new, b), 1e-300)
    return np.stack([u0, u1], axis=1)


def uniform_triangle_to_square(b):
    """Inverse of :func:`square_to_uniform_triangle`, (n, 2) -> (n, 2)."""
    total = b[:, 0] + b[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        u1 = np.where(total > 0.0, b[:, 1] / total, 0.0)
    return np.stack([total * total, u1], axis=1)


def direction_to_latlong(directions, rotation=0.0):
    """Latitude-longitude image coordinates of unit directions (+Y up).

    Parameters
    ----------
    directions : (k, 3) float
    rotation : float
        Degrees the map is turned about +Y (the direction is turned back by it first).

    Returns
    -------
    (k, 2) float64
        u in [0, 1] (azimuth ``atan2(z, x)`` from -pi at 0 to +pi at 1), v in [0, 1]
        (straight down at 0, straight up at 1).
    """
    angle = math.radians(rotation)
    c, s = math.cos(angle), math.sin(angle)
    x, y, z = directions[:, 0], directions[:, 1], directions[:, 2]
    xr = c * x - s * z
    zr = s * x + c * z
    u = 0.5 + np.arctan2(zr, xr) / (2.0 * math.pi)
    v = 0.5 + np.arcsin(np.clip(y, -1.0, 1.0)) / math.pi
    return np.stack([u, v], axis=1)


def latlong_to_direction(uv, rotation=0.0):
    """Unit directions of latitude-longitude image coordinates: the inverse of
    :func:`direction_to_latlong`.

    Parameters
    ----------
    uv : (k, 2) float
    rotation : float
        Degrees about +Y.

    Returns
    -------
    (k, 3) float64
    """
    angle = math.radians(rotation)
    return _latlong_directions(np.ascontiguousarray(uv, dtype=np.float64), math.cos(angle), math.sin(angle))


@row
def latlong_direction(u, v, cos_rotation, sin_rotation):
    """The unit direction ``(x, y, z)`` of one image point ``(u, v)`` of a lat-long image
    turned about +Y (see :func:`latlong_to_direction`), and ``cos`` of its elevation
    (``sin(theta)`` from the pole, the Jacobian's factor)."""
    azimuth = (u - 0.5) * 2.0 * math.pi
    elevation = (v - 0.5) * math.pi
    cos_el = math.cos(elevation)
    xr, zr = cos_el * math.cos(azimuth), cos_el * math.sin(azimuth)
    return cos_rotation * xr + sin_rotation * zr, math.sin(elevation), -sin_rotation * xr + cos_rotation * zr, cos_el


@kernel
def _latlong_directions(uv, cos_rotation, sin_rotation):
    """:func:`latlong_direction` of every row of ``uv``, (k, 3)."""
    out = np.empty((uv.shape[0], 3))
    for i in range(uv.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], _ = latlong_direction(uv[i, 0], uv[i, 1], cos_rotation, sin_rotation)
    return out
