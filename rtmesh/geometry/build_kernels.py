"""Compiled loops for building a scene from a mesh: the passes over every face and vertex.

Loading a mesh of a million triangles used to spend most of its time in NumPy passes that
each touch every face once and allocate a temporary (gathers, cross products, masks), and in
sorts that a hash table or a counting sort replaces.  The kernels here do those passes in one
loop each, compiled as rtmesh's other kernels are (:func:`rtmesh.core.compiled.kernel`:
``nogil``, disk cache, NumPy's error model, no ``fastmath``).

Every kernel rounds exactly as the NumPy code it replaces, so the scene's arrays (and so the
images) do not change by a bit:

* no ``fastmath``: no fused multiply-adds, no reassociation;
* sums of three products are grouped as NumPy groups them: ``np.linalg.norm(x, axis=1)``
  adds ``(x0^2 + x1^2) + x2^2`` (:func:`_norm`), while ``np.einsum("ij,ij->i", a, b)`` adds
  ``(a0 b0 + a2 b2) + a1 b1`` (:func:`_einsum_dot`; so NumPy 2.4 does on x86-64);
* NumPy's cross product ``a x b`` is ``(a1 b2 - a2 b1, a2 b0 - a0 b2, a0 b1 - a1 b0)``;
* sums over groups add in index order, as ``np.bincount`` does;
* arc tangents stay in NumPy (:func:`rtmesh.geometry.smoothing.face_normals_and_corner_angles`): its
  vectorised ``arctan2`` need not round like the C library's.

``tests/geometry/test_build_kernels.py`` compares every kernel with the NumPy code it replaced, bit
for bit, on the NumPy installed (a NumPy that groups its sums otherwise fails there).  The
kernels do not check their indices: callers pass faces within range.
"""

import math

import numpy as np
from numba import types

from rtmesh.core.compile_ahead import KernelGroup
from rtmesh.core.compiled import kernel, row

_row = row  # one-row helpers: compiled into the kernels that call them


@_row
def _norm(x, y, z):
    """``np.linalg.norm`` of one row: ``sqrt((x^2 + y^2) + z^2)``."""
    return math.sqrt((x * x + y * y) + z * z)


@_row
def _einsum_dot(ax, ay, az, bx, by, bz):
    """``np.einsum("ij,ij->i", a, b)`` of one row: ``(ax bx + az bz) + ay by``."""
    return (ax * bx + az * bz) + ay * by


# ---------------------------------------------------------------- smooth normals
@kernel
def face_normals_and_dots(vertices, faces):
    """Per face the unit normal, twice the area and the three corner dot products.

    The arithmetic of :func:`rtmesh.geometry.smoothing.face_normals_and_corner_angles` up to its
    arc tangents.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int

    Returns
    -------
    normals : (F, 3) float64
        ``cross(e01, -e20) / |cross|``; zero for zero-area faces.
    double_area : (F,) float64
        ``|cross(e01, -e20)|``.
    dots : (3, F) float64
        ``-e01.e20``, ``-e12.e01``, ``-e20.e12`` (component-major: each row is contiguous,
        as NumPy's ``arctan2`` then takes them).
    """
    n = faces.shape[0]
    normals = np.empty((n, 3))
    double_area = np.empty(n)
    dots = np.empty((3, n))
    for f in range(n):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        p0x, p0y, p0z = vertices[i0, 0], vertices[i0, 1], vertices[i0, 2]
        p1x, p1y, p1z = vertices[i1, 0], vertices[i1, 1], vertices[i1, 2]
        p2x, p2y, p2z = vertices[i2, 0], vertices[i2, 1], vertices[i2, 2]
        ax, ay, az = p1x - p0x, p1y - p0y, p1z - p0z  # e01
        bx, by, bz = p2x - p1x, p2y - p1y, p2z - p1z  # e12
        cx, cy, cz = p0x - p2x, p0y - p2y, p0z - p2z  # e20
        mx, my, mz = -cx, -cy, -cz
        nx = ay * mz - az * my
        ny = az * mx - ax * mz
        nz = ax * my - ay * mx
        area = math.sqrt(_einsum_dot(nx, ny, nz, nx, ny, nz))
        d = area if area > 0.0 else math.inf
        normals[f, 0], normals[f, 1], normals[f, 2] = nx / d, ny / d, nz / d
        double_area[f] = area
        dots[0, f] = -_einsum_dot(ax, ay, az, cx, cy, cz)
        dots[1, f] = -_einsum_dot(bx, by, bz, ax, ay, az)
        dots[2, f] = -_einsum_dot(cx, cy, cz, bx, by, bz)
    return normals, double_area, dots


@kernel
def edge_pairs(faces, n_vertices):
    """The two slots of every edge shared by exactly two faces.

    Slot ``3 f + k`` is the edge of face ``f`` from corner ``k`` to corner ``k + 1``.  Slots
    are bucketed by their lower vertex (a counting sort) and matched by the upper one.

    Parameters
    ----------
    faces : (F, 3) int
    n_vertices : int

    Returns
    -------
    pairs : (2, k) int64
        Slot pairs (one per column), in order of their edges' lower vertex; empty when
        ``manifold`` is False.
    manifold : bool
        False when some edge has three slots or more (a non-manifold edge, whose faces
        :func:`rtmesh.geometry.smoothing.smooth_vertex_normals` pairs up in sorted order instead).
    """
    n_faces = faces.shape[0]
    n_slots = 3 * n_faces
    start = np.zeros(n_vertices + 1, dtype=np.int64)
    for f in range(n_faces):
        for k in range(3):
            start[min(faces[f, k], faces[f, (k + 1) % 3]) + 1] += 1
    for v in range(n_vertices):
        start[v + 1] += start[v]
    # each bucket lists its slots and their upper vertices side by side
    fill = start[:-1].copy()
    slot = np.empty(n_slots, dtype=np.int64)
    high = np.empty(n_slots, dtype=np.int64)
    for f in range(n_faces):
        for k in range(3):
            a, b = faces[f, k], faces[f, (k + 1) % 3]
            low = min(a, b)
            i = fill[low]
            fill[low] = i + 1
            slot[i], high[i] = 3 * f + k, max(a, b)
    pairs = np.empty((2, n_slots // 2), dtype=np.int64)
    n_pairs = 0
    for v in range(n_vertices):
        last = start[v + 1]
        for i in range(start[v], last):
            if high[i] < 0:
                continue  # already paired
            partner = -1
            for j in range(i + 1, last):
                if high[j] == high[i]:
                    if partner >= 0:
                        return pairs[:, :0], False
                    partner = j
            if partner >= 0:
                pairs[0, n_pairs], pairs[1, n_pairs] = slot[i], slot[partner]
                n_pairs += 1
                high[partner] = -1
    return pairs[:, :n_pairs].copy(), True


@_row
def _root(parent, i):
    """Root of ``i``'s set, halving the path on the way."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@_row
def _join(parent, x, y):
    """Join the sets of ``x`` and ``y`` under the smaller root."""
    rx, ry = _root(parent, x), _root(parent, y)
    if rx < ry:
        parent[ry] = rx
    elif ry < rx:
        parent[rx] = ry


@kernel
def corner_groups(faces, face_normal, slot_a, slot_b, min_cosine, all_smooth):
    """Group face corners into smooth fans: the connected components of the corner graph.

    Two faces meeting across an edge (slots ``slot_a[i]`` and ``slot_b[i]``) join the
    corners holding the edge's two vertices when their normals' dot product exceeds
    ``min_cosine`` (or always with ``all_smooth``).

    Parameters
    ----------
    faces : (F, 3) int
    face_normal : (F, 3) float64
    slot_a, slot_b : (k,) int
        Slots sharing an edge.
    min_cosine : float
    all_smooth : bool

    Returns
    -------
    group : (3 F,) intp
        Group of every corner, numbered in order of each group's first corner, as SciPy's
        ``connected_components`` numbers components.
    n_groups : int
    """
    n_corners = 3 * faces.shape[0]
    parent = np.arange(n_corners)
    for i in range(slot_a.shape[0]):
        sa, sb = slot_a[i], slot_b[i]
        fa, fb = sa // 3, sb // 3
        if not all_smooth:
            dot = _einsum_dot(face_normal[fa, 0], face_normal[fa, 1], face_normal[fa, 2],
                              face_normal[fb, 0], face_normal[fb, 1], face_normal[fb, 2])
            if not dot > min_cosine:
                continue
        a_end = 3 * fa + (sa + 1) % 3
        b_next = 3 * fb + (sb + 1) % 3
        if faces[fb, sb % 3] == faces[fa, sa % 3]:
            b_start, b_end = sb, b_next
        else:
            b_start, b_end = b_next, sb
        _join(parent, sa, b_start)
        _join(parent, a_end, b_end)
    # a set's root is its first corner, numbered before any other corner of the set
    group = np.empty(n_corners, dtype=np.intp)
    n_groups = 0
    for c in range(n_corners):
        r = _root(parent, c)
        if r == c:
            group[c] = n_groups
            n_groups += 1
        else:
            group[c] = group[r]
    return group, n_groups


@kernel
def group_normals(group, n_groups, faces, face_normal, angle):
    """Angle-weighted unit normal and vertex of every group of corners.

    Parameters
    ----------
    group : (3 F,) int
    n_groups : int
    faces : (F, 3) int
    face_normal : (F, 3) float64
    angle : (F, 3) float64

    Returns
    -------
    normals : (n_groups, 3) float64
        Sum of ``face_normal * angle`` over the group's corners in corner order (as
        ``np.bincount`` adds), divided by its length; zero where the sum is zero.
    source : (n_groups,) intp
        The vertex the group's corners hold.
    """
    total = np.zeros((n_groups, 3))
    source = np.zeros(n_groups, dtype=np.intp)
    for f in range(faces.shape[0]):
        for k in range(3):
            g = group[3 * f + k]
            source[g] = faces[f, k]
            w = angle[f, k]
            for c in range(3):
                total[g, c] += face_normal[f, c] * w
    for g in range(n_groups):
        x, y, z = total[g, 0], total[g, 1], total[g, 2]
        length = math.sqrt(_einsum_dot(x, y, z, x, y, z))
        d = length if length > 0.0 else math.inf
        total[g, 0], total[g, 1], total[g, 2] = x / d, y / d, z / d
    return total, source


# ---------------------------------------------------------------- importers
_EMPTY = -1
# odd multipliers for the hash of a row (int64 products wrap around)
_HASH_A, _HASH_B, _HASH_C = (np.int64(0x1E3779B97F4A7C15), np.int64(0x632BE59BD9B4E019),
                             np.int64(0x165667B19E3779F9))


@kernel
def rows_distinct(keys):
    """Whether the rows of an integer array are pairwise different.

    Parameters
    ----------
    keys : (n, 3) int64
        E.g. vertex positions rounded to the precision at which trimesh merges vertices.

    Returns
    -------
    bool

    Notes
    -----
    One pass with an open-addressing hash table (linear probing, at most half full) in
    place of the sort trimesh's ``unique_rows`` does.
    """
    n = keys.shape[0]
    size = 1
    while size < 2 * n:
        size *= 2
    mask = size - 1
    table = np.full(size, _EMPTY, dtype=np.int64)
    for i in range(n):
        a, b, c = keys[i, 0], keys[i, 1], keys[i, 2]
        h = a * _HASH_A + b * _HASH_B + c * _HASH_C
        h ^= h >> 29
        slot = h & mask
        while True:
            j = table[slot]
            if j == _EMPTY:
                table[slot] = i
                break
            if keys[j, 0] == a and keys[j, 1] == b and keys[j, 2] == c:
                return False
            slot = (slot + 1) & mask
    return True


@kernel
def referenced_and_finite(vertices, faces):
    """Whether every vertex is used by a face and every coordinate is finite.

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int

    Returns
    -------
    bool
    """
    n = vertices.shape[0]
    for i in range(n):
        for c in range(3):
            if not math.isfinite(vertices[i, c]):
                return False
    used = np.zeros(n, dtype=np.bool_)
    count = 0
    for f in range(faces.shape[0]):
        for k in range(3):
            j = faces[f, k]
            if j < 0 or j >= n:
                return False
            if not used[j]:
                used[j] = True
                count += 1
    return count == n


# ---------------------------------------------------------------- placing and flattening parts
@kernel
def finite_without_negative_zero(values):
    """Whether every value is finite and none is -0.0.

    Such vectors come out of a product with the identity matrix unchanged, however the
    product's sums are ordered (``x + 0 = x``; only ``-0 + 0`` would turn a zero's sign).

    Parameters
    ----------
    values : (n, 3) float64

    Returns
    -------
    bool
    """
    for i in range(values.shape[0]):
        for c in range(3):
            x = values[i, c]
            if not math.isfinite(x) or (x == 0.0 and math.copysign(1.0, x) < 0.0):
                return False
    return True


@kernel
def finite_faces(vertices, faces):
    """Faces whose three vertices are finite: ``np.isfinite(v).all(1)[faces].all(1)``.

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int

    Returns
    -------
    (F,) bool
    """
    n = vertices.shape[0]
    finite = np.empty(n, dtype=np.bool_)
    for i in range(n):
        finite[i] = (math.isfinite(vertices[i, 0]) and math.isfinite(vertices[i, 1])
                     and math.isfinite(vertices[i, 2]))
    keep = np.empty(faces.shape[0], dtype=np.bool_)
    for f in range(faces.shape[0]):
        keep[f] = finite[faces[f, 0]] and finite[faces[f, 1]] and finite[faces[f, 2]]
    return keep


@kernel
def face_crosses(vertices, faces):
    """Per face the unit normal ``cross(v1 - v0, v2 - v0) / |cross|`` and ``|cross|``
    (``np.linalg.norm``), twice the face's area.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int

    Returns
    -------
    normal : (F, 3) float64
        Not finite where the length is zero.
    length : (F,) float64
    """
    n = faces.shape[0]
    normal = np.empty((n, 3))
    length = np.empty(n)
    for f in range(n):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        ax = vertices[i1, 0] - vertices[i0, 0]
        ay = vertices[i1, 1] - vertices[i0, 1]
        az = vertices[i1, 2] - vertices[i0, 2]
        bx = vertices[i2, 0] - vertices[i0, 0]
        by = vertices[i2, 1] - vertices[i0, 1]
        bz = vertices[i2, 2] - vertices[i0, 2]
        cx = ay * bz - az * by
        cy = az * bx - ax * bz
        cz = ax * by - ay * bx
        d = _norm(cx, cy, cz)
        normal[f, 0], normal[f, 1], normal[f, 2] = cx / d, cy / d, cz / d
        length[f] = d
    return normal, length


@kernel
def unit_rows(vectors, faces):
    """Unit vertex normals and the faces whose three normals are usable.

    Parameters
    ----------
    vectors : (V, 3) float64
    faces : (F, 3) int

    Returns
    -------
    unit : (V, 3) float64
        ``vectors / np.linalg.norm(vectors, axis=1)`` where that length is finite and
        positive, else zero.
    usable : (F,) bool
        Faces whose three vertices have a finite, positive length.
    """
    n = vectors.shape[0]
    unit = np.empty((n, 3))
    good = np.empty(n, dtype=np.bool_)
    for i in range(n):
        x, y, z = vectors[i, 0], vectors[i, 1], vectors[i, 2]
        length = _norm(x, y, z)
        good[i] = math.isfinite(length) and length > 0.0
        if good[i]:
            unit[i, 0], unit[i, 1], unit[i, 2] = x / length, y / length, z / length
        else:
            unit[i, 0] = unit[i, 1] = unit[i, 2] = 0.0
    usable = np.empty(faces.shape[0], dtype=np.bool_)
    for f in range(faces.shape[0]):
        usable[f] = good[faces[f, 0]] and good[faces[f, 1]] and good[faces[f, 2]]
    return unit, usable


# ---------------------------------------------------------------- integrator tables
@kernel
def face_rows(triangles, face_normals):
    """Per face the triangle's 9 values and its normal, row-major ``(F, 12)``.

    Parameters
    ----------
    triangles : (F, 9) float64
        Any layout (e.g. :attr:`rtmesh.geometry.accel.Accel.triangles`, component-major).
    face_normals : (F, 3) float64

    Returns
    -------
    (F, 12) float64
    """
    n = triangles.shape[0]
    out = np.empty((n, 12))
    for f in range(n):
        for c in range(9):
            out[f, c] = triangles[f, c]
        for c in range(3):
            out[f, 9 + c] = face_normals[f, c]
    return out


@kernel
def corner_rows(values, faces):
    """Row-major ``[value0, value1 - value0, value2 - value0]`` per face, ``(F, 9)``.

    The values of :func:`rtmesh.geometry.accel.corner_table`, laid out row by row.

    Parameters
    ----------
    values : (V, 3) float64
    faces : (F, 3) int

    Returns
    -------
    (F, 9) float64
    """
    n = faces.shape[0]
    out = np.empty((n, 9))
    for f in range(n):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        for c in range(3):
            first = values[i0, c]
            out[f, c] = first
            out[f, 3 + c] = values[i1, c] - first
            out[f, 6 + c] = values[i2, c] - first
    return out


_VECTORS = types.float64[:, ::1]
_FACES = types.int64[:, ::1]
# the passes as a scene build first calls them, for arrays as the loaders and Scene pass
# them (see rtmesh.core.compile_ahead)
BUILD_KERNELS = KernelGroup(__name__, "build", [
    (referenced_and_finite, (_VECTORS, _FACES)),
    (face_normals_and_dots, (_VECTORS, _FACES)),
    (edge_pairs, (_FACES, types.int64)),
    (corner_groups, (_FACES, _VECTORS, types.int64[::1], types.int64[::1], types.float64, types.boolean)),
    (group_normals, (types.int64[::1], types.int64, _FACES, _VECTORS, _VECTORS)),
    (finite_without_negative_zero, (_VECTORS,)),
    (finite_faces, (_VECTORS, _FACES)),
    (face_crosses, (_VECTORS, _FACES)),
    (unit_rows, (_VECTORS, _FACES)),
    (face_rows, (types.float64[::1, :], _VECTORS)),
    (corner_rows, (_VECTORS, types.int32[:, ::1])),
], every_render=True)
