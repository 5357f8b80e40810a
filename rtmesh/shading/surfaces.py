"""Surface records in compiled code: hit points, geometric and shading normals of the hits of
a batch of rays, and the shading-normal terminator fix.
"""


import math

import numpy as np

from rtmesh.core.compiled import inline_row, kernel, row
from rtmesh.core.row_vectors import dot3, normalized3

VIEW_COSINE = 1e-2


@row
def face_viewer_row(sx, sy, sz, gx, gy, gz, dx, dy, dz):
    """One shading normal made to face the viewer; see :func:`rtmesh.core.vecmath.face_viewer`."""
    cos_o = -dot3(sx, sy, sz, dx, dy, dz)
    above = dot3(sx, sy, sz, gx, gy, gz) > 0.0
    if cos_o >= VIEW_COSINE and above:
        return sx, sy, sz
    if not above:
        sx, sy, sz = gx, gy, gz
    c = max(VIEW_COSINE - dot3(sx, sy, sz, -dx, -dy, -dz), 0.0)
    return normalized3(sx - c * dx, sy - c * dy, sz - c * dz, 1.0)


@kernel
def face_viewer(ns, ng, d):
    """Shading normals that face the viewer: the shading-normal terminator fix.

    Interpolated (or normal-mapped) normals can lean away from the viewer near
    silhouettes.  Shading with such a normal makes black speckles (the highlight and the
    mirror direction point into the surface) or lights the surface from below.  Normals
    on the wrong side of the geometric normal are replaced by it; normals that face away
    from the viewer are bent toward the viewer, within the plane of the normal and the view
    direction, until ``ns . wo = 0.01`` (:data:`VIEW_COSINE`, before normalising): the
    smallest change that fixes them, and none for every other normal.  Light leaks are
    stopped separately: a light counts only when it is on the geometric side the ray came
    from.

    Parameters
    ----------
    ns : (k, 3) float
        Unit shading normals on the side the ray came from.
    ng : (k, 3) float
        Unit geometric normals, same side (``ng . d < 0``).
    d : (k, 3) float
        Unit incoming ray directions (``wo = -d``).

    Returns
    -------
    (k, 3) float64
        A corrected copy, component-major (a new array); rows that need no change are
        copied as they are.
    """
    k = len(ns)
    out = np.empty((3, k))
    for i in range(k):
        out[0, i], out[1, i], out[2, i] = face_viewer_row(ns[i, 0], ns[i, 1], ns[i, 2],
                                                       ng[i, 0], ng[i, 1], ng[i, 2],
                                                       d[i, 0], d[i, 1], d[i, 2])
    return out.T


# ------------------------------------------------------------------ surfaces
@row
def surface_record(f, a, b, vx, vy, vz, faces, vertex_normals, smooth, fix_terminator):
    """One hit's surface record (see :func:`surface_records`): face ``f`` at barycentrics
    ``(a, b)``, seen along ``(vx, vy, vz)``; ``smooth``: interpolate the vertex normals.
    Returns ``(px, py, pz, gx, gy, gz, sx, sy, sz, front)``.

    The arithmetic of :func:`surface_from_rows`, operation for operation, in the form a
    scalar loop runs fastest: it reads the tables itself (LLVM inlines it into
    :func:`surface_records`) and interpolates the vertex normals only where ``smooth``.
    Calling ``surface_from_rows`` here instead cost the general path 5-9 % of a frame on
    the bundled scenes (a call per hit with 28 arguments, and a normalisation on flat faces
    that a select then drops).  ``tests/rendering/test_direct_stage.py`` holds the two forms to the
    same bits (the fused stage uses the other).
    """
    # (u e1 + v0) + v e2: the order of rtmesh.geometry.accel.barycentric_interpolate
    px = (faces[f, 3] * a + faces[f, 0]) + faces[f, 6] * b
    py = (faces[f, 4] * a + faces[f, 1]) + faces[f, 7] * b
    pz = (faces[f, 5] * a + faces[f, 2]) + faces[f, 8] * b
    gx, gy, gz = faces[f, 9], faces[f, 10], faces[f, 11]
    front = dot3(vx, vy, vz, gx, gy, gz) < 0.0
    flip = 1.0 if front else -1.0
    gx, gy, gz = gx * flip, gy * flip, gz * flip
    sx, sy, sz = gx, gy, gz
    if smooth:
        sx, sy, sz = normalized3(
            (vertex_normals[f, 3] * a + vertex_normals[f, 0]) + vertex_normals[f, 6] * b,
            (vertex_normals[f, 4] * a + vertex_normals[f, 1]) + vertex_normals[f, 7] * b,
            (vertex_normals[f, 5] * a + vertex_normals[f, 2]) + vertex_normals[f, 8] * b,
            flip)
    if fix_terminator:
        sx, sy, sz = face_viewer_row(sx, sy, sz, gx, gy, gz, vx, vy, vz)
    return px, py, pz, gx, gy, gz, sx, sy, sz, front


@row
def surface_from_rows(a, b, vx, vy, vz, v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z, gx, gy, gz, smooth, n0x, n0y,
                      n0z, m1x, m1y, m1z, m2x, m2y, m2z, fix_terminator):
    """The arithmetic of :func:`surface_record` on a face's rows, given as numbers: ``v0``,
    ``e1 = v1 - v0``, ``e2 = v2 - v0``, the unit normal ``g`` (a ``faces`` row) and the
    vertex normals ``n0``, ``m1 = n1 - n0``, ``m2 = n2 - n0`` (a ``vertex_normals`` row;
    any numbers where not ``smooth``: their interpolation is then formed but not used).

    It takes no arrays, so a loop over gathered rows that calls it holds no array
    references per row (numba counts them with atomic instructions), and it has no branch
    LLVM cannot turn into selects: inlined (:data:`surface_from_rows_inlined`), such a
    loop vectorises (the fused stage's surface step).
    """
    # (u e1 + v0) + v e2: the order of rtmesh.geometry.accel.barycentric_interpolate
    px = (e1x * a + v0x) + e2x * b
    py = (e1y * a + v0y) + e2y * b
    pz = (e1z * a + v0z) + e2z * b
    front = dot3(vx, vy, vz, gx, gy, gz) < 0.0
    flip = 1.0 if front else -1.0
    gx, gy, gz = gx * flip, gy * flip, gz * flip
    # formed on flat faces too and then not used: a select instead of a branch
    ix, iy, iz = normalized3((m1x * a + n0x) + m2x * b, (m1y * a + n0y) + m2y * b, (m1z * a + n0z) + m2z * b, flip)
    sx = ix if smooth else gx
    sy = iy if smooth else gy
    sz = iz if smooth else gz
    if fix_terminator:
        sx, sy, sz = face_viewer_row(sx, sy, sz, gx, gy, gz, vx, vy, vz)
    return px, py, pz, gx, gy, gz, sx, sy, sz, front


# The same row, inlined by numba into its callers: too large for LLVM's inliner, it would
# stay a call per row in the fused stage's loop.  The general path keeps the plain row, so
# its kernels compile no longer than before (inlining costs each caller ~0.3 s CPU).
surface_from_rows_inlined = inline_row(surface_from_rows.py_func)


@kernel
def surface_records(prim_all, u_all, v_all, rows, directions_t, view, faces, vertex_normals,
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
    directions_t : (3, n) float
        Unit ray directions of the batch, by component
        (:func:`rtmesh.core.compiled.by_component`).
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
    directions = directions_t.T
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
         front[i]) = surface_record(f, np.float64(u_all[r]), np.float64(v_all[r]), vx, vy, vz, faces,
                                     vertex_normals, has_smooth and smooth[f], fix_terminator)
    return p.T, ng.T, ns.T, front, mat


# ------------------------------------------------------------------ placed surfaces
@row
def _placed_direction(m, x, y, z):
    """A direction times a 3x3 matrix held row by row in ``m[0:9]``, summed as the path
    kernel sums it (``(m0 x + m1 y) + m2 z``), and its length."""
    wx = (m[0] * x + m[1] * y) + m[2] * z
    wy = (m[3] * x + m[4] * y) + m[5] * z
    wz = (m[6] * x + m[7] * y) + m[8] * z
    return wx, wy, wz, math.sqrt((wx * wx + wy * wy) + wz * wz)


@row
def _placed_unit(m, unit_normals, i):
    """Vertex normal ``i`` carried by the matrix ``m`` and normalised as
    :func:`rtmesh.geometry.build_kernels.unit_rows` normalises the copies' (zero where its
    length is not finite and positive)."""
    x, y, z, length = _placed_direction(m, unit_normals[i, 0], unit_normals[i, 1], unit_normals[i, 2])
    if math.isfinite(length) and length > 0.0:
        return x / length, y / length, z / length
    return 0.0, 0.0, 0.0


@row
def placed_surface_record(f, j, a, b, vx, vy, vz, faces, corners, unit_normals, smooth, fix_terminator, to_world,
                          normal_to_world):
    """One hit on placement ``j`` of a prototype's face ``f`` (model coordinates) as the
    hit on its flattened copy reads (:func:`rtmesh.scene.instances.flattened`), seen along
    the world direction ``(vx, vy, vz)``; returns what :func:`surface_record` returns, in the
    world.

    Operation for operation what the copy's tables give, but for the point: the copy's
    is interpolated on its float32 world triangle, this one on the prototype's float32
    triangle and carried by the placement's float64 transform (the two agree to float32
    rounding).  The geometric normal is the prototype's by the inverse transpose,
    normalised (the copy's cross product, a mirrored copy's winding reversed, points the
    same way); smooth faces interpolate the vertex normals each carried by the inverse
    transpose and normalised first, as the copy's vertex normals are, so a non-uniform
    scale bends them as it bends the copy's.  Sides and the terminator fix are decided in
    the world, as on the copy.
    """
    p = to_world[j]
    m = normal_to_world[j]
    # (u e1 + v0) + v e2 on the prototype's triangle, then the placement
    px = (faces[f, 3] * a + faces[f, 0]) + faces[f, 6] * b
    py = (faces[f, 4] * a + faces[f, 1]) + faces[f, 7] * b
    pz = (faces[f, 5] * a + faces[f, 2]) + faces[f, 8] * b
    wx = ((p[0] * px + p[1] * py) + p[2] * pz) + p[9]
    wy = ((p[3] * px + p[4] * py) + p[5] * pz) + p[10]
    wz = ((p[6] * px + p[7] * py) + p[8] * pz) + p[11]
    gx, gy, gz, length = _placed_direction(m, faces[f, 9], faces[f, 10], faces[f, 11])
    gx, gy, gz = gx / length, gy / length, gz / length
    front = dot3(vx, vy, vz, gx, gy, gz) < 0.0
    flip = 1.0 if front else -1.0
    gx, gy, gz = gx * flip, gy * flip, gz * flip
    sx, sy, sz = gx, gy, gz
    if smooth:
        # the copy's unit vertex normals (rtmesh.geometry.build_kernels.unit_rows), then its
        # corner row [n0, n1 - n0, n2 - n0] interpolated as surface_record does
        n0x, n0y, n0z = _placed_unit(m, unit_normals, corners[f, 0])
        n1x, n1y, n1z = _placed_unit(m, unit_normals, corners[f, 1])
        n2x, n2y, n2z = _placed_unit(m, unit_normals, corners[f, 2])
        sx, sy, sz = normalized3(((n1x - n0x) * a + n0x) + (n2x - n0x) * b,
                                 ((n1y - n0y) * a + n0y) + (n2y - n0y) * b,
                                 ((n1z - n0z) * a + n0z) + (n2z - n0z) * b, flip)
    if fix_terminator:
        sx, sy, sz = face_viewer_row(sx, sy, sz, gx, gy, gz, vx, vy, vz)
    return wx, wy, wz, gx, gy, gz, sx, sy, sz, front


@kernel
def placed_surface_records(prim_all, u_all, v_all, instance_all, rows, directions_t, faces, vertex_normals, smooth,
                           material_id, fix_terminator, to_world, normal_to_world, corners, unit_normals):
    """:func:`surface_records` of a batch whose rays may hit placed meshes (Embree
    instances, :mod:`rtmesh.scene.instances`): rows on world-space faces exactly as
    there, rows on a placement by :func:`placed_surface_record`.

    Parameters
    ----------
    prim_all, u_all, v_all, rows, directions_t, faces, vertex_normals, smooth, material_id, fix_terminator
        As for :func:`surface_records` (``prim_all`` the faces in the per-face tables, a
        placement's being its prototype's; no motion: a scene with placements has none).
    instance_all : (n,) int32
        The placement each ray hit, -1 for a world-space face.
    to_world : (k, 12) float64
        Each placement's model-to-world transform (the linear part row by row, then the
        translation), in the integrator's frame.
    normal_to_world : (k, 9) float64
        The inverse transpose of each linear part, row by row.
    corners : (F, 3) int
        The scene's faces (vertex indices).
    unit_normals : (V, 3) float64 or (0, 3)
        The scene's unit vertex normals (model coordinates on the prototypes); empty
        without smooth shading.

    Returns
    -------
    p, ng, ns, front, mat
        As for :func:`surface_records`, in the world.
    """
    directions = directions_t.T
    k = len(rows)
    p, ng, ns = np.empty((3, k)), np.empty((3, k)), np.empty((3, k))
    front = np.empty(k, np.bool_)
    mat = np.empty(k, np.intp)
    has_smooth = len(vertex_normals) > 0
    for i in range(k):
        r = rows[i]
        f = np.intp(prim_all[r])
        j = instance_all[r]
        mat[i] = material_id[f]
        vx, vy, vz = directions[r, 0], directions[r, 1], directions[r, 2]
        if j < 0:
            (p[0, i], p[1, i], p[2, i], ng[0, i], ng[1, i], ng[2, i], ns[0, i], ns[1, i], ns[2, i],
             front[i]) = surface_record(f, np.float64(u_all[r]), np.float64(v_all[r]), vx, vy, vz, faces,
                                         vertex_normals, has_smooth and smooth[f], fix_terminator)
        else:
            (p[0, i], p[1, i], p[2, i], ng[0, i], ng[1, i], ng[2, i], ns[0, i], ns[1, i], ns[2, i],
             front[i]) = placed_surface_record(f, j, np.float64(u_all[r]), np.float64(v_all[r]), vx, vy, vz, faces,
                                               corners, unit_normals, has_smooth and smooth[f], fix_terminator,
                                               to_world, normal_to_world)
    return p.T, ng.T, ns.T, front, mat
