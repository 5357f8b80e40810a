"""Compiled per-hit kernels: the inner loops of shading, one pass per hit.

NumPy shading costs one pass over memory, one temporary and one Python call per operation;
on the benchmark scene the ~150 NumPy calls per chunk of a frame cost almost as much as
tracing the rays, and with several threads they queue for the GIL.  The kernels here do a
hit's whole surface record, or a whole (hit, light) pair, in one loop that numba compiles
(nogil, cached on disk, no fastmath: see :func:`rtmesh.compiled.kernel`).

Every function with an ``_`` prefix is one row's arithmetic, which LLVM inlines into the
array kernels that call it.

Arrays of 3-vectors are ``(n, 3)``; results are component-major (see
:mod:`rtmesh.batches`) unless said otherwise, as the NumPy code that reads them is fastest
on that layout.
"""

import math

import numba
import numpy as np
from numba import types
from numba.extending import intrinsic

from .compiled import cached, inline_row, kernel, row

_row = row  # one-row helpers: compiled into the kernels that call them

# ------------------------------------------------------------------ float32 offsets
# See rtmesh.accel for the reasoning behind the origin offset and its constants.
ULPS = np.float32(4.0)
EXTENT_EPSILONS = np.float32(16.0 * np.finfo(np.float32).eps)
DIRECTION_SHARE = np.float32(0.25)
_F32_ZERO, _F32_ONE = np.float32(0.0), np.float32(1.0)
_F32_MAX = float(np.finfo(np.float32).max)


@intrinsic
def _float32_bits(typingctx, x):
    """The bits of a float32 as an int32 (a free reinterpretation, like ``ndarray.view``)."""
    if x != types.float32:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int32))

    return types.int32(types.float32), codegen


@intrinsic
def _float32_from_bits(typingctx, bits):
    """The float32 whose bits are the low 32 bits of the integer ``bits``."""
    if not isinstance(bits, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        low = builder.trunc(args[0], context.get_value_type(types.int32)) if bits.bitwidth > 32 else args[0]
        return builder.bitcast(low, context.get_value_type(types.float32))

    return types.float32(bits), codegen


_EXPONENT_MASK = np.int32(0x7F800000)
_ULP_SCALE = np.float32(2.0 ** -23)


@_row
def _ulp32(x):
    """Spacing of float32 numbers at float32 ``x``, read from the exponent bits
    (``2**(e - 23)``); 0 for zeros and subnormals."""
    return _float32_from_bits(_float32_bits(x) & _EXPONENT_MASK) * _ULP_SCALE


@cached(lambda cache: numba.vectorize(["float32(float32)"], nopython=True, cache=cache))
def ulp32(x):
    """Spacing of float32 numbers at each element (a ufunc: any shape and layout).

    ``np.spacing(abs(x))`` for normal floats; 0 for zeros and subnormals.
    """
    return _ulp32(x)


@_row
def _sign32(x):
    if x > 0:
        return _F32_ONE
    if x < 0:
        return -_F32_ONE
    return _F32_ZERO


@_row
def _offset(px, py, pz, nx, ny, nz, dx, dy, dz, scale):
    """One point moved off its surface (see :func:`offset_origins`); float32 ``(x, y, z)``.

    ``d`` is the float32 ray direction, or zeros for a normal-only offset.
    """
    px, py, pz = np.float32(px), np.float32(py), np.float32(pz)
    nx, ny, nz = np.float32(nx), np.float32(ny), np.float32(nz)
    ux, uy, uz = _ulp32(px), _ulp32(py), _ulp32(pz)
    distance = ULPS * ((abs(nx) * ux + abs(ny) * uy) + abs(nz) * uz) + EXTENT_EPSILONS * scale
    mx = nx + DIRECTION_SHARE * np.float32(dx)
    my = ny + DIRECTION_SHARE * np.float32(dy)
    mz = nz + DIRECTION_SHARE * np.float32(dz)
    # plus one ulp in every coordinate that moves: rounding cannot give the old value back
    return (px + (mx * distance + _sign32(mx) * ux),
            py + (my * distance + _sign32(my) * uy),
            pz + (mz * distance + _sign32(mz) * uz))


@kernel
def offset_origins(points, normals, directions, scale):
    """Ray origins moved off a surface; see :func:`rtmesh.accel.offset_ray_origins`.

    Parameters
    ----------
    points, normals : (n, 3) float
    directions : (n, 3) float or (0, 3)
        Directions of the rays, or an empty array for a normal-only offset.
    scale : float32
        Scene size.

    Returns
    -------
    (n, 3) float32
        Component-major.
    """
    n = len(points)
    out = np.empty((3, n), np.float32)
    along = len(directions) > 0
    for i in range(n):
        dx = directions[i, 0] if along else 0.0
        dy = directions[i, 1] if along else 0.0
        dz = directions[i, 2] if along else 0.0
        out[0, i], out[1, i], out[2, i] = _offset(points[i, 0], points[i, 1], points[i, 2],
                                                  normals[i, 0], normals[i, 1], normals[i, 2],
                                                  dx, dy, dz, scale)
    return out.T


# ------------------------------------------------------------------ vectors
@_row
def _dot(ax, ay, az, bx, by, bz):
    # (x + y) + z, the order rtmesh.vecmath.dot sums in
    return (ax * bx + ay * by) + az * bz


@_row
def _normalized(x, y, z, scale):
    """``(x, y, z) * scale / length``; zero stays zero."""
    length = math.sqrt(_dot(x, y, z, x, y, z))
    inv = (1.0 / length if length > 0.0 else 0.0) * scale
    return x * inv, y * inv, z * inv


# Smallest cosine between a bent shading normal and the direction to the viewer: enough to
# keep the Blinn-Phong half vector and the mirror direction well defined.
VIEW_COSINE = 1e-2


@_row
def _face_viewer(sx, sy, sz, gx, gy, gz, dx, dy, dz):
    """One shading normal made to face the viewer; see :func:`rtmesh.vecmath.face_viewer`."""
    cos_o = -_dot(sx, sy, sz, dx, dy, dz)
    above = _dot(sx, sy, sz, gx, gy, gz) > 0.0
    if cos_o >= VIEW_COSINE and above:
        return sx, sy, sz
    if not above:
        sx, sy, sz = gx, gy, gz
    c = max(VIEW_COSINE - _dot(sx, sy, sz, -dx, -dy, -dz), 0.0)
    return _normalized(sx - c * dx, sy - c * dy, sz - c * dz, 1.0)


@kernel
def face_viewer(ns, ng, d):
    """Shading normals that face the viewer; see :func:`rtmesh.vecmath.face_viewer`.

    Returns
    -------
    (k, 3) float64
        A new, component-major array.
    """
    k = len(ns)
    out = np.empty((3, k))
    for i in range(k):
        out[0, i], out[1, i], out[2, i] = _face_viewer(ns[i, 0], ns[i, 1], ns[i, 2],
                                                       ng[i, 0], ng[i, 1], ng[i, 2],
                                                       d[i, 0], d[i, 1], d[i, 2])
    return out.T


# ------------------------------------------------------------------ Embree results
@kernel
def closest_hits(t_far, prim, u, v):
    """Embree's float32 closest-hit results as float64, with ``inf`` for the misses.

    Parameters
    ----------
    t_far, u, v : (n,) float32
    prim : (n,) int32
        Triangle hit, -1 for a miss.

    Returns
    -------
    t, u, v : (n,) float64
    """
    n = len(prim)
    t64, u64, v64 = np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):
        t64[i] = np.float64(t_far[i]) if prim[i] >= 0 else np.inf
        u64[i], v64[i] = np.float64(u[i]), np.float64(v[i])
    return t64, u64, v64


# ------------------------------------------------------------------ camera
@_row
def _image_plane_point(x, y, pixel, width, inverse_width, image_plane):
    """Image-plane coordinates ``(sx, sy)`` at unit distance along the camera's forward axis
    of film position ``(x, y)``, given in pixels, or inside pixel ``pixel`` (when >= 0)."""
    return _image_plane_xy(x, y, pixel, width, inverse_width, image_plane[0], image_plane[1], image_plane[2],
                           image_plane[3])


@_row
def _image_plane_xy(x, y, pixel, width, inverse_width, ax, bx, ay, by):
    """:func:`_image_plane_point` with the image-plane map ``(ax, bx, ay, by)`` given as
    numbers: a compiled function that takes them instead of the array holds no reference
    to count (see :func:`rtmesh.direct_stage._camera_block`)."""
    if pixel >= 0:
        # the row by a float product and a one-step correction: an integer division a
        # ray would keep the loop from vectorising
        row = np.int64(pixel * inverse_width)
        row += (row + 1) * width <= pixel
        row -= row * width > pixel
        x, y = x + np.float64(pixel - row * width), y + np.float64(row)
    return x * ax + bx, y * ay + by


@_row
def _pinhole_direction(sx, sy, forward, right, up):
    """Unit direction of the pinhole ray through image-plane point ``(sx, sy)``."""
    return _pinhole_xyz(sx, sy, forward[0], forward[1], forward[2], right[0], right[1], right[2], up[0], up[1],
                        up[2])


@_row
def _pinhole_xyz(sx, sy, fx, fy, fz, rx, ry, rz, ux, uy, uz):
    """:func:`_pinhole_direction` with the camera frame (forward ``f``, right ``r``, up ``u``)
    given as numbers (see :func:`_image_plane_xy`)."""
    # forward, right and up are orthonormal, so the squared length of
    # forward + sx right + sy up is 1 + sx^2 + sy^2
    inv = 1.0 / math.sqrt((sx * sx + sy * sy) + 1.0)
    sx, sy = sx * inv, sy * inv
    return (inv * fx + sx * rx) + sy * ux, (inv * fy + sx * ry) + sy * uy, (inv * fz + sx * rz) + sy * uz


@kernel
def camera_rays(film_xy, pixels, width, disk, position, forward, right, up, image_plane, focus):
    """Primary rays through film positions; see :meth:`rtmesh.camera.Camera.generate_rays`.

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
        sx, sy = _image_plane_point(film_xy[i, 0], film_xy[i, 1], pixels[i] if in_pixels else -1, width,
                                    inverse_width, image_plane)
        if lens:
            # every ray through a film point meets the pinhole ray on the plane of focus: the
            # unnormalised pinhole direction has a forward component of exactly 1, so
            # position + focus * direction lies on the plane at depth `focus`
            for c in range(3):
                toward = (forward[c] + right[c] * sx) + up[c] * sy
                origins[c, i] = (position[c] + disk[i, 0] * right[c]) + disk[i, 1] * up[c]
                d[c, i] = (position[c] + toward * focus) - origins[c, i]
            d[0, i], d[1, i], d[2, i] = _normalized(d[0, i], d[1, i], d[2, i], 1.0)
        else:
            d[0, i], d[1, i], d[2, i] = _pinhole_direction(sx, sy, forward, right, up)
    return origins.T, d.T


# ------------------------------------------------------------------ surfaces
@_row
def _surface_record(f, a, b, vx, vy, vz, faces, vertex_normals, smooth, fix_terminator):
    """One hit's surface record (see :func:`surface_records`): face ``f`` at barycentrics
    ``(a, b)``, seen along ``(vx, vy, vz)``; ``smooth``: interpolate the vertex normals.
    Returns ``(px, py, pz, gx, gy, gz, sx, sy, sz, front)``."""
    # vertex normals exist only where smooth shading was asked for: on flat faces the
    # interpolation runs on zeros and is not used
    n0x = n0y = n0z = m1x = m1y = m1z = m2x = m2y = m2z = 0.0
    if smooth:
        n0x, n0y, n0z = vertex_normals[f, 0], vertex_normals[f, 1], vertex_normals[f, 2]
        m1x, m1y, m1z = vertex_normals[f, 3], vertex_normals[f, 4], vertex_normals[f, 5]
        m2x, m2y, m2z = vertex_normals[f, 6], vertex_normals[f, 7], vertex_normals[f, 8]
    return _surface_from_rows(a, b, vx, vy, vz, faces[f, 0], faces[f, 1], faces[f, 2], faces[f, 3], faces[f, 4],
                              faces[f, 5], faces[f, 6], faces[f, 7], faces[f, 8], faces[f, 9], faces[f, 10],
                              faces[f, 11], smooth, n0x, n0y, n0z, m1x, m1y, m1z, m2x, m2y, m2z, fix_terminator)


@_row
def _surface_from_rows(a, b, vx, vy, vz, v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z, gx, gy, gz, smooth, n0x, n0y,
                       n0z, m1x, m1y, m1z, m2x, m2y, m2z, fix_terminator):
    """The arithmetic of :func:`_surface_record` on a face's rows, given as numbers: ``v0``,
    ``e1 = v1 - v0``, ``e2 = v2 - v0``, the unit normal ``g`` (a ``faces`` row) and the
    vertex normals ``n0``, ``m1 = n1 - n0``, ``m2 = n2 - n0`` (a ``vertex_normals`` row;
    any numbers where not ``smooth``: their interpolation is then formed but not used).

    It takes no arrays, so a loop over gathered rows that calls it holds no array
    references per row (numba counts them with atomic instructions), and it has no branch
    LLVM cannot turn into selects: inlined (:data:`_surface_from_rows_inlined`), such a
    loop vectorises (the fused stage's surface step).
    """
    # (u e1 + v0) + v e2: the order of rtmesh.accel.barycentric_interpolate
    px = (e1x * a + v0x) + e2x * b
    py = (e1y * a + v0y) + e2y * b
    pz = (e1z * a + v0z) + e2z * b
    front = _dot(vx, vy, vz, gx, gy, gz) < 0.0
    flip = 1.0 if front else -1.0
    gx, gy, gz = gx * flip, gy * flip, gz * flip
    # formed on flat faces too and then not used: a select instead of a branch
    ix, iy, iz = _normalized((m1x * a + n0x) + m2x * b, (m1y * a + n0y) + m2y * b, (m1z * a + n0z) + m2z * b, flip)
    sx = ix if smooth else gx
    sy = iy if smooth else gy
    sz = iz if smooth else gz
    if fix_terminator:
        sx, sy, sz = _face_viewer(sx, sy, sz, gx, gy, gz, vx, vy, vz)
    return px, py, pz, gx, gy, gz, sx, sy, sz, front


# The same row, inlined by numba into its callers: too large for LLVM's inliner, it would
# stay a call per row in the fused stage's loop.  The general path keeps the plain row, so
# its kernels compile no longer than before (inlining costs each caller ~0.3 s CPU).
_surface_from_rows_inlined = inline_row(_surface_from_rows.py_func)


@kernel
def surface_records(prim_all, u_all, v_all, rows, directions, view, faces, vertex_normals,
                    smooth, material_id, fix_terminator):
    """Hit points, facing normals and materials of the hit rows of a ray batch.

    Parameters
    ----------
    prim_all : (n,) int
        Triangle hit by each ray of the batch.
    u_all, v_all : (n,) float
        Barycentric weights of vertices 1 and 2.
    rows : (k,) intp
        The rows of the batch that hit a triangle.
    directions : (n, 3) float
        Unit ray directions of the batch.
    view : (k, 3) float or (0, 3)
        Directions of the hit rows in the frame of the triangles (motion blur), or empty
        when that is ``directions``.
    faces : (F, 12) float64, row-major
        Per face ``[v0, v1 - v0, v2 - v0, unit geometric normal]``.
    vertex_normals : (F, 9) float64, row-major, or (0, 9)
        Per face ``[n0, n1 - n0, n2 - n0]`` of the vertex normals; empty without smooth
        shading.
    smooth : (F,) bool
        Faces that interpolate their vertex normals.
    material_id : (F,) intp
    fix_terminator : bool
        Apply :func:`face_viewer` to the shading normals (smooth shading without normal
        maps; with normal maps it runs after them).

    Returns
    -------
    p : (k, 3) float64
        ``v0 + u (v1 - v0) + v (v2 - v0)`` on the float32 triangle Embree traced.
    ng, ns : (k, 3) float64
        Unit geometric and shading normals, flipped to the side the ray came from; ``ns``
        is ``ng`` on flat faces, and an interpolated normal of zero length stays zero
        (:func:`face_viewer` replaces it).
    front : (k,) bool
        The ray arrived on the outer (counter-clockwise) side.
    mat : (k,) intp

    Notes
    -----
    The kernel is bound by the memory it writes (~80 bytes a hit), so what the caller can
    take by itself (the directions, primitives and barycentrics of the rows) is not
    copied here.
    """
    k = len(rows)
    p, ng, ns = np.empty((3, k)), np.empty((3, k)), np.empty((3, k))
    front = np.empty(k, np.bool_)
    mat = np.empty(k, np.intp)
    rest_frame = len(view) > 0
    has_smooth = len(vertex_normals) > 0
    for i in range(k):
        r = rows[i]
        f = np.intp(prim_all[r])
        mat[i] = material_id[f]
        if rest_frame:
            vx, vy, vz = view[i, 0], view[i, 1], view[i, 2]
        else:
            vx, vy, vz = directions[r, 0], directions[r, 1], directions[r, 2]
        (p[0, i], p[1, i], p[2, i], ng[0, i], ng[1, i], ng[2, i], ns[0, i], ns[1, i], ns[2, i],
         front[i]) = _surface_record(f, np.float64(u_all[r]), np.float64(v_all[r]), vx, vy, vz, faces,
                                     vertex_normals, has_smooth and smooth[f], fix_terminator)
    return p.T, ng.T, ns.T, front, mat


# ------------------------------------------------------------------ lights
POINT, DIRECTIONAL, SPOT = 0, 1, 2


@_row
def _illuminate(light, px, py, pz):
    """Direction, distance and incident term of one light at one point.

    ``light`` is a light's :meth:`kernel_parameters` row: ``[kind, position (3),
    direction (3), power (3), cos_inner, cos_outer]``.  Returns ``(wx, wy, wz, distance,
    er, eg, eb)``.  Every kind is formed and the light's own picked by selects, not
    branches, so that the loops calling this vectorise.
    """
    kind = light[0]
    directional, spot = kind == DIRECTIONAL, kind == SPOT
    tx, ty, tz = light[1] - px, light[2] - py, light[3] - pz
    distance = math.sqrt(_dot(tx, ty, tz, tx, ty, tz))
    # a light sitting exactly on a point lights it from nowhere: direction 0, term 0
    safe = distance if distance > 0.0 else np.inf
    wx, wy, wz = tx / safe, ty / safe, tz / safe
    square = safe * safe
    # the spot's cone: a smoothstep in cos(angle) between the outer and the inner angle
    # (a step when they are equal)
    cos_angle = -_dot(wx, wy, wz, light[4], light[5], light[6])
    cos_inner, cos_outer = light[10], light[11]
    x = min(max((cos_angle - cos_outer) / (cos_inner - cos_outer), 0.0), 1.0)
    step = 1.0 if cos_angle >= cos_outer else 0.0
    cone = x * x * (3.0 - 2.0 * x) if cos_inner - cos_outer > 0.0 else step
    falloff = cone / square
    # point: intensity / distance^2; spot: intensity * (cone / distance^2); directional:
    # the irradiance, from -direction, infinitely far
    er = light[7] if directional else (light[7] * falloff if spot else light[7] / square)
    eg = light[8] if directional else (light[8] * falloff if spot else light[8] / square)
    eb = light[9] if directional else (light[9] * falloff if spot else light[9] / square)
    return (-light[4] if directional else wx, -light[5] if directional else wy,
            -light[6] if directional else wz, np.inf if directional else distance, er, eg, eb)


@kernel
def illuminate(light, points):
    """Direction toward a light, distance and incident term at each point.

    Parameters
    ----------
    light : (12,) float64
        The light's :meth:`kernel_parameters`.
    points : (k, 3) float

    Returns
    -------
    wi : (k, 3) float64
    distance : (k,) float64
    incident : (k, 3) float64
    """
    k = len(points)
    wi, distance, incident = np.empty((3, k)), np.empty(k), np.empty((3, k))
    for i in range(k):
        (wi[0, i], wi[1, i], wi[2, i], distance[i],
         incident[0, i], incident[1, i], incident[2, i]) = _illuminate(light, points[i, 0],
                                                                       points[i, 1], points[i, 2])
    return wi.T, distance, incident.T


# ------------------------------------------------------------------ Blinn-Phong
# The factor is kd max(0, n.wi) + ks max(0, n.h)^shininess (the highlight only where
# n.wi > 0 and the material has one).  The power is the one operation LLVM cannot vectorise
# (a libm call, ~20 ns); on the hot path (light_samples) the cosines are formed first and
# NumPy, which has SIMD pow, raises them, and everything else is vectorised by LLVM.


@_row
def _highlight_cosine(nx, ny, nz, ox, oy, oz, wx, wy, wz):
    """``max(0, n.h)`` with ``h`` the normalised ``wo + wi``; 0 where ``n.wi <= 0`` (light
    below the shading horizon) or ``wo + wi = 0``."""
    hx, hy, hz = ox + wx, oy + wy, oz + wz
    h_len = math.sqrt(_dot(hx, hy, hz, hx, hy, hz))
    cos_h = max(_dot(nx, ny, nz, hx, hy, hz) / h_len, 0.0)
    return cos_h if (_dot(nx, ny, nz, wx, wy, wz) > 0.0) & (h_len > 0.0) else 0.0


@_row
def _blinn_phong(kd0, kd1, kd2, ks0, ks1, ks2, cos_i, power):
    """``kd max(0, cos_i) + ks power`` per channel (``power``: the raised highlight cosine,
    0 without a highlight)."""
    lam = max(cos_i, 0.0)
    return kd0 * lam + ks0 * power, kd1 * lam + ks1 * power, kd2 * lam + ks2 * power


@kernel
def blinn_phong(n, wo, wi, diffuse, specular, shininess):
    """Blinn-Phong factor per row; see :func:`rtmesh.materials.blinn_phong`.

    ``specular`` and ``shininess`` may be empty (``(0, 3)``, ``(0,)``): no highlight.
    """
    k = len(n)
    out = np.empty((3, k))
    highlight = len(specular) > 0
    for i in range(k):
        power, ks0, ks1, ks2 = 0.0, 0.0, 0.0, 0.0
        if highlight:
            power = _highlight_cosine(n[i, 0], n[i, 1], n[i, 2], wo[i, 0], wo[i, 1], wo[i, 2],
                                      wi[i, 0], wi[i, 1], wi[i, 2]) ** shininess[i]
            ks0, ks1, ks2 = specular[i, 0], specular[i, 1], specular[i, 2]
        out[0, i], out[1, i], out[2, i] = _blinn_phong(
            diffuse[i, 0], diffuse[i, 1], diffuse[i, 2], ks0, ks1, ks2,
            _dot(n[i, 0], n[i, 1], n[i, 2], wi[i, 0], wi[i, 1], wi[i, 2]), power)
    return out.T


@_row
def _colour(table, m, tint, r, c):
    """Channel ``c`` of material ``m``'s colour in ``table``, times row ``r``'s texture tint
    where there is one (an empty ``tint``: none)."""
    value = table[m, c]
    return value * tint[r, c] if len(tint) else value


@_row
def _shade(r, m, cos_i, power, diffuse, tint_d, specular, tint_s):
    """Blinn-Phong factor of hit row ``r`` with material ``m`` (and the row's tints) from
    ``n . wi`` and the raised highlight cosine (0 without a highlight)."""
    return _blinn_phong(_colour(diffuse, m, tint_d, r, 0), _colour(diffuse, m, tint_d, r, 1),
                        _colour(diffuse, m, tint_d, r, 2), _colour(specular, m, tint_s, r, 0),
                        _colour(specular, m, tint_s, r, 1), _colour(specular, m, tint_s, r, 2),
                        cos_i, power)


@kernel
def surface_reflectance(ns, d, wi, lit, mat, diffuse, tint_d, specular, tint_s, exponent):
    """Blinn-Phong factor of hits toward unit directions ``wi``.

    Parameters
    ----------
    ns, d : (k, 3) float
        Shading normals and incoming ray directions.
    wi : (k, 3) float
        Directions toward the light.
    lit : (k,) bool
        Rows that get a highlight (elsewhere only the diffuse term is formed).
    mat : (k,) intp
    diffuse, specular : (M, 3) float64
        Material colours.
    tint_d, tint_s : (k, 3) float or (0, 3)
        Texture tints of the colours, or empty.
    exponent : (M,) float64
        Shininess, negative for materials without a highlight.

    Returns
    -------
    (k, 3) float64
    """
    k = len(ns)
    out = np.empty((3, k))
    for i in range(k):
        m = mat[i]
        power = 0.0
        if lit[i] and exponent[m] >= 0.0:
            power = _highlight_cosine(ns[i, 0], ns[i, 1], ns[i, 2], -d[i, 0], -d[i, 1], -d[i, 2],
                                      wi[i, 0], wi[i, 1], wi[i, 2]) ** exponent[m]
        out[0, i], out[1, i], out[2, i] = _shade(
            i, m, _dot(ns[i, 0], ns[i, 1], ns[i, 2], wi[i, 0], wi[i, 1], wi[i, 2]), power,
            diffuse, tint_d, specular, tint_s)
    return out.T


# ------------------------------------------------------------------ point-like lights
@_row
def _reaches(wx, wy, wz, er, eg, eb, gx, gy, gz):
    """Whether a light with direction ``w`` and incident term ``e`` (see :func:`_illuminate`)
    lights a point with geometric normal ``g``: it is on the side the ray came from
    (``wi . ng > 0``: no leaks through the surface) and its term is not zero."""
    # bitwise operators: short-circuits are branches, which stop vectorisation
    return (_dot(wx, wy, wz, gx, gy, gz) > 0.0) & ((er > 0.0) | (eg > 0.0) | (eb > 0.0))


# Shadow rays to point and spot lights stop this fraction short of the light, so a light
# placed exactly on a surface does not count that surface as an occluder.
SHADOW_SHORTEN = 1.0 - 1e-5
# rows per block of light_samples: its scratch arrays (~70 bytes a row) stay in L1
_BLOCK = 256


@kernel
def light_samples(light, p, ng, ns, d, mat, exponent, visible_from, scale, shorten):
    """One point-like light at every hit: the lit hits, their shadow rays, and what shading
    them needs once the shadow rays are traced (see :func:`add_light`).

    Parameters
    ----------
    light : (12,) float64
        The light's :meth:`kernel_parameters`.
    p, ng, ns, d : (k, 3) float64
        Surface records: points, geometric and shading normals, incoming directions.
    mat : (k,) intp
    exponent : (M,) float64
        Shininess per material, negative for materials without a highlight.
    visible_from : (M,) float64
        Per material, the smallest highlight cosine whose power is kept (see
        :func:`highlight_thresholds`).
    scale : float32
        Scene size, for the origin offset.
    shorten : float
        Shadow rays end this fraction of the way to the light.

    Returns
    -------
    lit : (j,) intp
        The lit rows: the light is on the side the ray came from and reaches them.
    origins, directions : (j, 3) float32
        Row-major shadow rays, origins offset off the surface.
    t_max : (j,) float32
        Shadow ray lengths (clamped to the float32 range).
    cos_i : (j,) float64
        ``ns . wi``.
    incident : (j, 3) float64
        The light's incident term.
    highlight_rows : (h,) intp
        The lit rows (indices into the arrays above) with a highlight worth raising.
    highlight, power_exponent : (h,) float64
        ``highlight ** power_exponent`` is the highlight's power there (``max(0, ns . h)``
        and the shininess); it is 0 on the other lit rows.  Left for NumPy to raise: its
        pow is vectorised where a compiled loop calls libm once a row, but only for
        ordinary operands: a zero base or an underflowing power takes a slow path (tens of
        times slower), so those rows are not handed to it.

    Notes
    -----
    A block of rows is formed by a loop without branches, gathers or calls, which LLVM
    vectorises; a second loop over the block keeps the lit rows.
    """
    k = len(p)
    lit = np.empty(k, np.intp)
    origins, directions = np.empty((k, 3), np.float32), np.empty((k, 3), np.float32)
    t_max = np.empty(k, np.float32)
    cos_i, incident = np.empty(k), np.empty((k, 3))
    highlight_rows, highlight, power_exponent = np.empty(k, np.intp), np.empty(k), np.empty(k)
    block_incident, block_cos = np.empty((3, _BLOCK)), np.empty((2, _BLOCK))
    block_ray = np.empty((6, _BLOCK), np.float32)
    block_length, block_lit = np.empty(_BLOCK, np.float32), np.empty(_BLOCK, np.bool_)
    j = h = 0
    for start in range(0, k, _BLOCK):
        n = min(_BLOCK, k - start)
        for b in range(n):
            i = start + b
            wx, wy, wz, distance, er, eg, eb = _illuminate(light, p[i, 0], p[i, 1], p[i, 2])
            block_lit[b] = _reaches(wx, wy, wz, er, eg, eb, ng[i, 0], ng[i, 1], ng[i, 2])
            block_incident[0, b], block_incident[1, b], block_incident[2, b] = er, eg, eb
            block_cos[0, b] = _dot(ns[i, 0], ns[i, 1], ns[i, 2], wx, wy, wz)
            block_cos[1, b] = _highlight_cosine(ns[i, 0], ns[i, 1], ns[i, 2], -d[i, 0], -d[i, 1], -d[i, 2],
                                                wx, wy, wz)
            # the shadow ray's direction in float32, as Embree will see it, also sets the offset
            dx, dy, dz = np.float32(wx), np.float32(wy), np.float32(wz)
            block_ray[0, b], block_ray[1, b], block_ray[2, b] = _offset(
                p[i, 0], p[i, 1], p[i, 2], ng[i, 0], ng[i, 1], ng[i, 2], dx, dy, dz, scale)
            block_ray[3, b], block_ray[4, b], block_ray[5, b] = dx, dy, dz
            block_length[b] = np.float32(min(distance * shorten, _F32_MAX))
        for b in range(n):
            if not block_lit[b]:
                continue
            i = start + b
            for c in range(3):
                origins[j, c] = block_ray[c, b]
                directions[j, c] = block_ray[3 + c, b]
                incident[j, c] = block_incident[c, b]
            t_max[j] = block_length[b]
            cos_i[j] = block_cos[0, b]
            m = mat[i]
            e = exponent[m]
            # a power of 0 is 1 whatever the cosine (0 ** 0 included)
            c = 1.0 if e == 0.0 else block_cos[1, b]
            if e >= 0.0 and c > 0.0 and c >= visible_from[m]:
                highlight_rows[h], highlight[h], power_exponent[h] = j, c, e
                h += 1
            lit[j] = i
            j += 1
    return (lit[:j], origins[:j], directions[:j], t_max[:j], cos_i[:j], incident[:j], highlight_rows[:h],
            highlight[:h], power_exponent[:h])


def highlight_thresholds(exponent):
    """Per material, the smallest highlight cosine whose power :func:`light_samples` keeps.

    Below ``2 ** (-1000 / shininess)`` the power is under ``2 ** -1000`` (1e-301), nothing
    an image can show, and NumPy's pow would take its slow underflow path; 0 for a
    shininess of 0 (a power of 1), inf without a highlight.

    Parameters
    ----------
    exponent : (M,) float
        Shininess, negative without a highlight.

    Returns
    -------
    (M,) float64
    """
    exponent = np.asarray(exponent, dtype=np.float64)
    with np.errstate(divide="ignore"):
        threshold = np.exp2(-1000.0 / exponent)
    return np.where(exponent > 0.0, threshold, np.where(exponent == 0.0, 0.0, np.inf))


@kernel
def add_light(total, target, lit, occluded, cos_i, incident, highlight_rows, power, mat, diffuse, tint_d,
              specular, tint_s):
    """Add one light's Blinn-Phong term to the lit rows whose shadow rays are clear.

    Parameters
    ----------
    total : (K, 3) float64
        Accumulated direct light (updated in place).
    target : (j,) intp
        Row of ``total`` for each lit row.
    lit : (j,) intp
        The lit rows of ``mat`` and the tints (see :func:`light_samples`).
    occluded : (j,) bool
        Shadow-ray results.
    cos_i : (j,) float64
        ``ns . wi``.
    incident : (j, 3) float64
    highlight_rows : (h,) intp
        Ascending lit rows with a highlight.
    power : (h,) float64
        The raised highlight cosine of those rows (0 on the others).
    mat : (k,) intp
    diffuse, specular : (M, 3) float64
        Material colours.
    tint_d, tint_s : (k, 3) float or (0, 3)
        Texture tints of the colours, or empty.
    """
    q = 0  # next highlight row: both lists are ascending
    for j in range(len(lit)):
        highlight = 0.0
        if q < len(highlight_rows) and highlight_rows[q] == j:
            highlight = power[q]
            q += 1
        if occluded[j]:
            continue
        i, r = lit[j], target[j]
        f0, f1, f2 = _shade(i, mat[i], cos_i[j], highlight, diffuse, tint_d, specular, tint_s)
        total[r, 0] += f0 * incident[j, 0]
        total[r, 1] += f1 * incident[j, 1]
        total[r, 2] += f2 * incident[j, 2]


# ------------------------------------------------------------------ film
@kernel
def accumulate_samples(total, total_sq, count, pixels, radiance, image):
    """Add samples and their squares to per-pixel sums, each pixel's samples in order.

    A pixel without samples so far (``count`` 0) takes its first sample by assignment, so
    the sums need not be zeroed beforehand (see :class:`rtmesh.film.Film`).  With an
    ``image``, each pixel's mean is written too, while its sums are in registers (a film
    whose pixels are final once added, instead of a pass over the film at the end).

    Parameters
    ----------
    total, total_sq : (P, 3) float64
        Sums over samples of radiance and of radiance squared (updated in place).
    count : (P,) int
        Samples per pixel before these (not updated here).
    pixels : (m,) int
        Distinct pixel indices.
    radiance : (m, spp, 3) float
        The new samples of each pixel.
    image : (P, 3) float32 or (0, 3)
        Receives the added pixels' means, as :func:`mean_image` forms them; (0, 3): none.
    """
    means = image.shape[0] > 0
    for i in range(len(pixels)):
        px = pixels[i]
        first = 0
        if count[px] == 0:
            for c in range(3):
                r = radiance[i, 0, c]
                total[px, c] = r
                total_sq[px, c] = r * r
            first = 1
        for s in range(first, radiance.shape[1]):
            for c in range(3):
                r = radiance[i, s, c]
                total[px, c] += r
                total_sq[px, c] += r * r
        if means:
            inverse = 1.0 / np.float64(count[px] + radiance.shape[1])
            for c in range(3):
                image[px, c] = np.float32(total[px, c] * inverse)


@kernel
def add_rows(target, rows, values):
    """``target[rows] += values`` for distinct ``rows``.

    Parameters
    ----------
    target : (n, k) float64
        Updated in place.
    rows : (m,) int
        Distinct row indices.
    values : (m, k) float
    """
    for c in range(target.shape[1]):
        for i in range(len(rows)):
            target[rows[i], c] += values[i, c]


@kernel
def mean_image(total, count, out):
    """Per-pixel means of sample sums, as float32 rows.

    Parameters
    ----------
    total : (P, k) float64
        Sums over each pixel's samples.
    count : (P,) int
        Samples per pixel; pixels without any give 0.
    out : (P, k) float32
        Receives ``total / max(count, 1)``.
    """
    for i in range(total.shape[0]):
        # one division per pixel (the pass is bound by division throughput): the float64
        # product differs from the quotient by at most an ulp, far below float32's
        inverse = 1.0 / np.float64(max(count[i], 1))
        for c in range(total.shape[1]):
            out[i, c] = np.float32(total[i, c] * inverse)


@kernel
def pixel_errors(total, total_sq, count, start, stop, floor, display):
    """Per-pixel standard error of the mean, relative to the pixel's brightness, for the
    pixels ``start .. stop - 1`` (see :meth:`rtmesh.film.Film.pixel_relative_error` and
    :meth:`~rtmesh.film.Film.pixel_display_error`).

    Each value is formed as the NumPy expressions of ``Film`` formed it, operation for
    operation (sample variance, clamped at 0, over ``n``; its square root; divided by
    ``|mean| + floor`` or its square root; the three channels summed in order and divided
    by 3), in one pass instead of a dozen passes over the film.

    Parameters
    ----------
    total, total_sq : (P, 3) float64
        Per-pixel sums of the samples and of their squares.
    count : (P,) int
        Samples per pixel.
    start, stop : int
    floor : float
    display : bool
        Divide by ``sqrt(|mean| + floor)`` (the display scale) instead of ``|mean| + floor``.

    Returns
    -------
    (stop - start,) float64
        NaN for pixels with fewer than two samples.
    """
    out = np.empty(stop - start)
    for j in range(stop - start):
        i = start + j
        n = np.float64(count[i])
        at_least_one = max(n, 1.0)
        error = 0.0
        for c in range(3):
            mean = total[i, c] / at_least_one
            variance = (total_sq[i, c] - n * mean * mean) / max(n - 1.0, 1.0)
            # np.maximum(variance, 0) keeps a NaN; np.where(n > 1, ..., 0)
            clamped = variance if (variance >= 0.0) | (variance != variance) else 0.0
            std_err = math.sqrt((clamped if n > 1.0 else 0.0) / at_least_one)
            scale = abs(mean) + floor
            term = std_err / (math.sqrt(scale) if display else scale)
            error = term if c == 0 else error + term
        out[j] = error / 3.0 if count[i] >= 2 else np.nan
    return out
