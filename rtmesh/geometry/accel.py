"""The Embree boundary: the only place where rtmesh converts between float64 and float32.

Shading runs in float64; Embree works in float32.  This module

* uploads the scene's triangles to one Embree scene in robust mode,
* answers batched closest-hit (:meth:`Accel.intersect`) and any-hit
  (:meth:`Accel.occluded`) queries, converting rays to float32 on the way in: through
  Embree's 16-wide packet queries from compiled kernels (:mod:`rtmesh.geometry.embree_packets`)
  where the library embreex installed is one they were verified on, else through
  embreex's one-ray-at-a-time ``run()``,
* reconstructs hit points from the barycentrics Embree returns, on the exact float32
  triangles Embree saw, and
* owns the self-intersection rule (:func:`offset_ray_origins`): embreex's ``run()`` has no
  ``tnear``, so a secondary ray must start on the correct side of the surface it leaves.
"""

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from rtmesh.core.compiled import by_component
from rtmesh.core.rays import repeated_row, take_rows
from rtmesh.geometry import embree_library, embree_packets, float32_rays
from rtmesh.geometry.float32_rays import F32_MAX

_NO_ROWS = np.zeros(0, dtype=np.int64)
_NO_DIRECTIONS = np.zeros((0, 3))  # a normal-only origin offset
# Every query asks for Embree's coherent packet traversal.  Camera rays and shadow rays
# toward one point light gain most (3-4x the rays per second of run(), see
# shared/EMBREE_PACKETS.md); for the secondary rays of the effects scenes it was still as
# fast as or faster than incoherent traversal and than run() (whole renders, 1 thread,
# 200x150, medians of 4 interleaved: glass_edges 154 ms coherent, 244 incoherent, 287
# run(); glossy 1100, 1239, 1234; soft_shadow 2784, 2617, 3280).
_PACKET_FLAGS = embree_packets.RTC_RAY_QUERY_FLAG_COHERENT

# The origin offset (see offset_ray_origins).  A spawned ray must start clear of the surface
# it leaves, by more than two errors (in the spirit of Waechter & Binder, "A Fast and Robust
# Method for Avoiding Self-Intersection", Ray Tracing Gems ch. 6, and pbrt's error bounds):
# * the hit point, rounded to float32, is off the float32 triangle's plane by up to half an
#   ulp of each coordinate, i.e. by sum_i |n_i| ulp(p_i) / 2 along the normal;
# * Embree evaluates the plane relative to the ray origin in float32, with an error of a
#   few float32 epsilons of the triangle's extent, which is at most the scene's size; near
#   the origin, where ulps are tiny, this is the larger term.
# The test suite (self-intersection, acne, grazing emitters) passes down to 1 ulp and half
# an epsilon; the constants keep a margin of 4 and 32 over that.  Both terms are relative to
# the point's own magnitude and the scene's size, so the offset stays a tiny fraction of
# any object even far from the origin (the former fixed 256-ulp offset was ~2 units at
# |x| ~ 1e5, more than a unit object, which rays then tunnelled through).
# The constants (ULPS = 4, EXTENT_EPSILONS = 16 eps32, DIRECTION_SHARE = 1/4) and the arithmetic
# are in rtmesh.geometry.float32_rays, which applies them one row at a time.


def offset_ray_origins(points, normals, dtype=np.float64, scale=1.0, directions=None):
    """Move points off a surface along its geometric normal, in float32 space.

    The distance is ``4 * sum_i |n_i| ulp(p_i) + 16 * eps32 * scale``: a few float32 ulps
    of the point's coordinates (its rounding error) plus a few float32 epsilons of the
    scene's size (the error of Embree's float32 plane test), and every coordinate the
    offset changes moves by one more ulp, toward the side the ray leaves.

    Parameters
    ----------
    points : (n, 3) float
        Points on the surface.
    normals : (n, 3) float
        Unit geometric normals pointing to the side the new ray leaves toward.
    dtype : {np.float64, np.float32}
        Type of the result.  The values are the same; float32 saves two conversions for
        origins that go straight back to :meth:`Accel.occluded` (no arithmetic may be done
        on them outside this module).
    scale : float
        Size of the scene (largest coordinate magnitude of the re-centred scene), which
        bounds the size of the triangles.
    directions : (n, 3) float, optional
        Unit directions of the rays that will start there.  The normal offset lifts a point
        off the face it lies on, but a point on an edge or vertex also lies on the planes
        of the neighbouring faces, and after the normal offset still does when they meet
        at a right angle: a ray from there into the solid (or away from a wall, at a
        concave edge) hits that neighbour at t = 0.  With ``directions`` the point also
        moves a quarter as far along the ray, and at least one ulp in every coordinate
        the ray changes, which puts it on the side of every surface through the point that
        the ray is heading to, so those surfaces are behind the ray.

    Returns
    -------
    (n, 3) float64 or float32
        Offset origins, component-major; every value is exactly representable in
        float32, so handing them to Embree does not round them back onto the surface.
    """
    # every caller's arrays as one layout and dtype (exact conversions; a copy for row-major
    # ones), so that the kernel compiles once
    vectors = (points, normals, _NO_DIRECTIONS if directions is None else directions)
    origins = float32_rays.offset_origins(*(by_component(np.asfortranarray(v, dtype=np.float64)) for v in vectors),
                                          np.float32(scale))
    return origins.astype(dtype, copy=False)


def float32_ulp(x):
    """The spacing of float32 numbers at ``x``: ``np.spacing(abs(x))`` for normal floats.

    Read from the exponent bits (``2**(e - 23)``), which is an order of magnitude faster than
    ``np.spacing``; zeros and subnormals give 0 instead of the smallest subnormal (the
    offset's scene-size term is far larger anyway).

    Parameters
    ----------
    x : (...) float32

    Returns
    -------
    (...) float32
        Laid out like ``x``.
    """
    return float32_rays.ulp32(x)


class Hits:
    """Closest hits of a ray batch.

    Attributes
    ----------
    t : (n,) float64
        Distance along the (unit) ray direction; ``inf`` for misses.
    prim : (n,) int32
        Triangle index; -1 for misses.
    u, v : (n,) float64
        Barycentric coordinates of the hit (weights of vertices 1 and 2).
    instance : (n,) int32 or None
        In a scene with placed meshes (:mod:`rtmesh.scene.instances`): the placement hit,
        -1 for a world-space face or a miss; ``prim`` is then the prototype's face in the
        per-face tables and ``u``, ``v`` are on the prototype's triangle.  None for a
        scene without placements.
    """

    __slots__ = ("t", "prim", "u", "v", "instance")

    def __init__(self, t, prim, u, v, instance=None):
        self.t, self.prim, self.u, self.v, self.instance = t, prim, u, v, instance

    def __len__(self):
        return len(self.prim)

    @property
    def hit(self):
        """(n,) bool: rays that hit something."""
        return self.prim >= 0


class Accel:
    """Embree scene over a triangle soup.

    Parameters
    ----------
    vertices : (V, 3) float
        Vertex positions.  Keep the scene near the origin (the integrator re-centres it):
        float32 resolution is relative to the magnitude of the coordinates.
    faces : (F, 3) int
        Vertex indices.
    packets : bool, optional
        Trace with Embree's packet queries (True: raise RuntimeError where they cannot be
        used) or with embreex's ``run()`` (False).  Default: packets where
        :func:`rtmesh.geometry.embree_library.packet_library` verified them.  Both give the same
        hits on scenes without coplanar overlapping triangles; where two triangles are hit
        at exactly the same distance, each path keeps the one its traversal meets first.
    instances : rtmesh.scene.instances.Instances, optional
        Faces from ``instances.first_face`` on are prototypes in model coordinates (their
        ``vertices`` not re-centred): each is built once into an Embree scene of its own
        and placed by ``instances.transforms`` (already re-centred) as Embree instances of
        the top-level scene, after the world-space faces.  Packets only; :meth:`intersect`
        reports the placement of each hit (:attr:`Hits.instance`).

    Attributes
    ----------
    packets : bool
        Which path traces.
    vertices32 : (V, 3) float32
        The positions Embree traces.
    vertices : (V, 3) float64
        The same values in float64.
    faces : (F, 3) int32
    triangles : (F, 9) float64
        Per face ``[v0, v1 - v0, v2 - v0]`` of the float32 triangles, component-major; see
        :func:`barycentric_interpolate`.

    Notes
    -----
    After construction the Embree scene is committed and read-only, so :meth:`intersect`
    and :meth:`occluded` may be called from several threads at once; both paths release the
    GIL while they trace.
    """

    def __init__(self, vertices, faces, packets=None, instances=None):
        library = embree_library.packet_library() if packets is None or packets or instances is not None else None
        if (packets or instances is not None) and library is None:
            raise RuntimeError("Embree packet queries are not available here (see the log)")
        self.packets = library is not None
        self.instances = instances
        self.faces = np.ascontiguousarray(faces, dtype=np.int32)
        # what intersect maps a placement's primID by (empty: no placements)
        self._face_offset = _NO_ROWS if instances is None else instances.world_rows()[0]
        if instances is not None:
            self._shared = _InstancedScene(library, vertices, self.faces, instances)
            self.vertices32 = self._shared.vertices32
            self._intersect, self._occluded = library.intersect, library.occluded
        elif self.packets:
            self._shared = embree_library.SharedScene(library, vertices, self.faces)
            self.vertices32 = self._shared.vertices32
            self._intersect, self._occluded = library.intersect, library.occluded
        else:
            self.vertices32 = np.ascontiguousarray(vertices, dtype=np.float32)
            self._scene = rtcore_scene.EmbreeScene(robust=True)
            TriangleMesh(self._scene, self.vertices32, self.faces)
            # run() commits lazily and is not thread-safe while doing so: commit now
            self._scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), query="OCCLUDED")
        # the float64 copy of exactly the triangles Embree sees, for hit reconstruction
        self.vertices = self.vertices32.astype(np.float64)
        # Per-face [v0, v1 - v0, v2 - v0], so one gather per hit gives everything
        # hit_points needs.  The edges are differences of float32 numbers, which float64
        # represents exactly: the table still describes exactly the triangles Embree saw.
        self.triangles = corner_table(self.vertices, self.faces)

    def intersect(self, origins, directions, time=None):
        """Closest hit of each ray.

        Parameters
        ----------
        origins : (n, 3) float
        directions : (n, 3) float
            Unit directions.
        time : (n,) float, optional
            Each ray's time; a static scene stands still, so it is not read (the argument
            makes the query interface that of :class:`rtmesh.geometry.motion.MotionAccel` and
            :class:`rtmesh.geometry.cutouts.CutoutAccel`).

        Returns
        -------
        Hits
        """
        n = len(origins)
        placed = self.instances is not None
        if n == 0:
            empty = np.zeros(0)
            return Hits(empty, np.zeros(0, np.int32), empty, empty, np.zeros(0, np.int32) if placed else None)
        if self.packets:
            intersect_rays, _ = embree_packets.query_kernels()
            t, prim, u, v, instance = intersect_rays(self._intersect, self._shared.handle,
                                                     *embree_packets.closest_rays(origins, directions), _PACKET_FLAGS,
                                                     self._face_offset)
            return Hits(t, prim, u, v, instance if placed else None)
        result = self._scene.run(_embree_rays(origins), _embree_rays(directions), output=1)
        prim = result["primID"]
        t, u, v = float32_rays.closest_hits(result["tfar"], prim, result["u"], result["v"])
        return Hits(t, prim, u, v)

    def occluded(self, origins, directions, t_max, rows=None, time=None):
        """Whether anything lies on each ray between its origin and ``t_max``.

        Parameters
        ----------
        origins : (n, 3) float
        directions : (n, 3) float
            Unit directions.
        t_max : (n,) float
            Segment length; ``inf`` for rays to infinitely distant lights.
        rows : (k,) int, optional
            Trace only these rays (the gather is fused with the float32 conversion).
        time : (n,) float, optional
            Not read (see :meth:`intersect`).

        Returns
        -------
        (n,) or (k,) bool
        """
        # (rtcOccluded16 on the top-level scene sees the placements: nothing to map)
        if self.packets:
            rows = _NO_ROWS if rows is None else np.asarray(rows, dtype=np.int64)
            o, d, t = embree_packets.shadow_rays(origins, directions, t_max)
            _, occluded_rays = embree_packets.query_kernels()
            return occluded_rays(self._occluded, self._shared.handle, o, d, t, rows, _PACKET_FLAGS)
        if rows is not None:
            t_max = t_max[rows]
        if len(t_max) == 0:
            return np.zeros(0, dtype=bool)
        # embreex writes into the distance array it is given: always pass a fresh one.
        # float32 max stands in for inf, which Embree's robust mode handles less predictably.
        # (for float32 input, as light_samples gives, one ufunc call: this runs per chunk)
        t = np.minimum(t_max, F32_MAX).astype(np.float32, copy=False)
        o, d = _embree_rays(origins, rows), _embree_rays(directions, rows)
        return self._scene.run(o, d, dists=t, query="OCCLUDED") != -1

    def hit_points(self, hits, mask=None):
        """World positions of hits, interpolated on the float32 triangles Embree traced.

        Interpolating with the barycentrics keeps the error relative to the triangle's own
        coordinates, whereas ``origin + t * direction`` carries the error of ``t``, which grows
        with the ray's length.

        Parameters
        ----------
        hits : Hits
        mask : (n,) bool, optional
            Only these hits (default: all, which must all be hits).

        Returns
        -------
        (k, 3) float64
            Component-major (see :mod:`rtmesh.core.rays`) without placements; hits on a
            placement are interpolated on the prototype's triangle and carried to the
            world by its transform (:meth:`rtmesh.scene.instances.Instances.world_points`).
        """
        prim, u, v, instance = hits.prim, hits.u, hits.v, hits.instance
        if mask is not None:
            prim, u, v = prim[mask], u[mask], v[mask]
            instance = None if instance is None else instance[mask]
        points = barycentric_interpolate(take_rows(self.triangles, prim), u, v)
        if instance is None or not (instance >= 0).any():
            return points
        return self.instances.world_points(points, instance)


class _InstancedScene:
    """World-space faces and prototypes placed by instances, as one top-level Embree scene
    (see :class:`Accel`'s ``instances``).

    Attributes
    ----------
    handle : int
        The top-level ``RTCScene``: the world-space triangles (geometry 0 when there are
        any), then one instance array of every placement (a hit's ``instPrimID`` is the
        placement).
    vertices32 : (V, 3) float32
        Every vertex as Embree holds it (world-space ones, then each prototype's, in model
        coordinates), for the per-face tables.
    """

    def __init__(self, library, vertices, faces, instances):
        f0, v0 = instances.first_face, instances.first_vertex
        self._prototypes = []
        for p in range(len(instances.prototype_faces) - 1):
            fa, fb = instances.prototype_faces[p], instances.prototype_faces[p + 1]
            va, vb = instances.prototype_vertices[p], instances.prototype_vertices[p + 1]
            self._prototypes.append(embree_library.SharedScene(library, vertices[va:vb], faces[fa:fb] - va))
        self._top = embree_library.SharedScene(library, vertices[:v0], faces[:f0],
                                               (self._prototypes, instances.prototype, instances.transforms[:, :3, :]))
        self.handle = self._top.handle
        self.vertices32 = np.concatenate([self._top.vertices32] + [p.vertices32 for p in self._prototypes])


def _embree_rays(array, rows=None):
    """float32 ray origins or directions for ``embreex.run()``, from any ``(n, 3)`` layout.

    embreex reads the rays through the buffer's strides, so a component-major array is
    converted in its own layout (contiguous passes) instead of being transposed to
    row-major, which costs NumPy several times more.

    Parameters
    ----------
    array : (n, 3) float
    rows : (m,) intp, optional
        Only these rays.

    Returns
    -------
    (n, 3) or (m, 3) float32
    """
    if array.strides[0] == 0 and rows is None:
        # one row broadcast to every ray (the origin of pinhole camera rays): Embree reads
        # rays through the strides, so it is converted once instead of materialised n times
        return repeated_row(array[0].astype(np.float32), len(array))
    return take_rows(array, rows).astype(np.float32, copy=False)


def corner_table(values, faces):
    """Per face, a per-vertex quantity at vertex 0 and its changes toward vertices 1 and 2.

    Parameters
    ----------
    values : (V, 3) float
        Per-vertex values (positions, normals).
    faces : (F, 3) int

    Returns
    -------
    (F, 9) float64
        ``[value0, value1 - value0, value2 - value0]``, component-major (see
        :func:`barycentric_interpolate`).  Built one component at a time with 1-D gathers
        into the rows of the result: gathering (F, 3) rows and transposing them takes
        three times as long on a million faces.
    """
    columns = np.ascontiguousarray(np.asarray(values, dtype=np.float64).T)
    corners = np.ascontiguousarray(np.asarray(faces).T, dtype=np.intp)
    table = np.zeros((9, len(corners[0])))
    for c in range(3):
        first = columns[c].take(corners[0], out=table[c])
        np.subtract(columns[c].take(corners[1]), first, out=table[3 + c])
        np.subtract(columns[c].take(corners[2]), first, out=table[6 + c])
    return table.T


def barycentric_interpolate(corner_and_edges, u, v):
    """Interpolate a per-vertex quantity at barycentric coordinates.

    Parameters
    ----------
    corner_and_edges : (k, 9) float
        Per hit: the value at vertex 0, its change toward vertex 1 and toward vertex 2
        (e.g. gathered rows of :attr:`Accel.triangles`).
    u, v : (k,) float
        Barycentric weights of vertices 1 and 2.

    Returns
    -------
    (k, 3) float64
        ``value0 + u * (value1 - value0) + v * (value2 - value0)``, laid out like the input.
    """
    # in place: one temporary fewer; (u * e1 + value0) + v * e2 rounds exactly like the
    # formula above (addition commutes)
    out = corner_and_edges[:, 3:6] * u[:, None]
    out += corner_and_edges[:, 0:3]
    out += corner_and_edges[:, 6:9] * v[:, None]
    return out
