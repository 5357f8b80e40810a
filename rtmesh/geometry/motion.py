"""Motion blur: rigid per-object motion over the shutter, traced exactly at each ray's time.

Model
-----
An object with a :class:`Motion` moves rigidly: at time ``t`` (the scene's time unit; the
camera's shutter ``[open, close]`` is given in the same unit) its rest-pose points ``x``
are at ::

    x(t) = c + R(t * degrees about axis) (x - c) + t * translate

with ``c`` the rotation centre (the object's bounds centre unless given).  ``t = 0`` is the
pose the scene file describes.  Every camera ray gets a time drawn from the shutter by the
render's sampler (:attr:`rtmesh.sampling.patterns.Dim.TIME`, stratified per pixel); every secondary,
shadow and AO ray of that camera sample inherits it.

Design: per-ray rest-frame tracing
----------------------------------
Embree answers queries about geometry at one instant, and embreex exposes no motion-blur
BVH, so the geometry "at the ray's time" has to be built from static scenes.  Two designs:

* **Time slices**: B static scenes with the moving objects baked at B times; each ray is
  traced in the scene of its time bin.  It costs B full BVH builds and B times the memory,
  and it is only an approximation: within a bin an object stands still, so a fast object
  leaves B discrete ghosts (banding) unless B grows with the distance it covers in pixels.
* **Rest-frame tracing** (used here): rigid motion has an exact inverse, so a ray at time
  ``t`` meets the moving object exactly where the *inverse-transformed* ray meets the
  object at rest.  The static part of the scene is one :class:`~rtmesh.geometry.accel.Accel`; each
  moving object is another, built once over its rest-pose triangles.  A query traces the
  rays in the static scene, transforms them (vectorised, every ray with its own time) into
  each moving object's rest frame and traces them there; the closest hit is the minimum of
  the distances (a rigid map preserves them), occlusion the logical or.  Hit points and
  normals are computed on the rest-pose float32 triangles Embree saw and transformed back to
  the world.  It is exact at every time (no ghosting, no bins to choose) and costs one
  extra query per moving object, with no per-time BVH builds.

Numerics: the transforms run in float64 and the :class:`~rtmesh.geometry.accel.Accel` of each object
stays the only float32 boundary.  Secondary rays are offset from the world-space hit point
by :func:`rtmesh.geometry.accel.offset_ray_origins` as usual; a rigid float64 transform moves the
offset origin to the rest frame with an error of a few float64 ulps, far below the
offset's 256 float32 ulps, so the rule stays valid.  The offset's scale is taken from the
bounds swept during the shutter (:func:`swept_bounds`).  Translation-only objects are moved
by adding ``t * translate`` alone (no rotation about a centre), so a zero translation is an
exact identity.

Static scenes never come here: the integrator builds one :class:`Accel` as before unless
some object moves during a shutter of non-zero length.
"""

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from rtmesh.core.compiled import by_component, kernel
from rtmesh.core.rays import component_major, take_rows
from rtmesh.core.row_vectors import dot3
from rtmesh.geometry.accel import Accel, Hits


@dataclass
class Motion:
    """Rigid linear motion of one object per unit of time.

    Attributes
    ----------
    translate : (3,) float
        Displacement per unit time, scene units.
    axis : (3,) float
        Rotation axis (need not be unit length; ignored when ``degrees`` is 0).
    degrees : float
        Rotation per unit time about ``axis`` through ``centre``, degrees (right-handed).
    centre : (3,) float or None
        Rotation centre, scene units; None means the centre of the object's bounds (filled
        in by :meth:`rtmesh.scene.model.Scene.from_parts`).
    """

    translate: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    degrees: float = 0.0
    centre: np.ndarray | None = None

    def __post_init__(self):
        self.translate = np.asarray(self.translate, dtype=np.float64).reshape(3)
        axis = np.asarray(self.axis, dtype=np.float64).reshape(3)
        length = float(np.linalg.norm(axis))
        if self.degrees != 0.0 and not length > 0.0:
            raise ValueError("a rotating motion needs a non-zero rotation axis")
        self.axis = axis / length if length > 0.0 else axis
        self.degrees = float(self.degrees)
        if self.centre is not None:
            self.centre = np.asarray(self.centre, dtype=np.float64).reshape(3)

    @property
    def rotates(self):
        """True if the motion has a rotation."""
        return self.degrees != 0.0

    @property
    def moves(self):
        """True unless the motion is the identity at every time."""
        return self.rotates or bool((self.translate != 0.0).any())

    def shifted(self, shift):
        """The same motion for geometry moved by ``-shift`` (the integrator's re-centring)."""
        centre = None if self.centre is None else self.centre - shift
        return dataclasses.replace(self, centre=centre)

    def to_world(self, points, time):
        """Rest-pose points at their times, ``x(t)``.

        Parameters
        ----------
        points : (k, 3) float
        time : (k,) float

        Returns
        -------
        (k, 3) float64
        """
        if self.rotates:
            c = self.centre
            points = rotate(points - c, self.axis, np.radians(self.degrees) * time) + c
        return points + time[:, None] * self.translate

    def matrix(self, time):
        """(4, 4) float64: the motion at ``time`` as an affine transform of rest-pose points."""
        basis = np.vstack([np.zeros(3), np.eye(3)])
        moved = self.to_world(basis, np.full(4, float(time)))
        matrix = np.eye(4)
        matrix[:3, :3] = (moved[1:] - moved[0]).T
        matrix[:3, 3] = moved[0]
        return matrix

    def to_rest(self, points, time):
        """Inverse of :meth:`to_world`: world points at their times to the rest pose."""
        moved = points - time[:, None] * self.translate
        if not self.rotates:
            return moved
        c = self.centre
        return rotate(moved - c, self.axis, -np.radians(self.degrees) * time) + c

    def rays_to_rest(self, origins, directions, time):
        """World rays at their times in the object's rest frame, where its Accel traces them.

        Parameters
        ----------
        origins, directions : (k, 3) float
        time : (k,) float

        Returns
        -------
        origins, directions : (k, 3) float
            Distances along the rays are unchanged (the motion is rigid).
        """
        return (self.to_rest(origins, time),
                self.rotate_vectors(directions, time, inverse=True))

    def rotate_vectors(self, vectors, time, inverse=False):
        """Directions or normals carried by the motion (the rotation alone).

        Parameters
        ----------
        vectors : (k, 3) float
        time : (k,) float
        inverse : bool
            World to rest pose instead of rest pose to world.

        Returns
        -------
        (k, 3) float
            ``vectors`` itself when the motion does not rotate.
        """
        if not self.rotates:
            return vectors
        angle = np.radians(self.degrees) * time
        return rotate(vectors, self.axis, -angle if inverse else angle)


def rotate(vectors, axis, angle):
    """Rotate each row about one unit axis by its own angle (Rodrigues' formula).

    Parameters
    ----------
    vectors : (k, 3) float
    axis : (3,) float
        Unit axis.
    angle : (k,) float
        Radians, right-handed about ``axis``.

    Returns
    -------
    (k, 3) float64
        Component-major.
    """
    v = np.asarray(vectors, dtype=np.float64)
    cos, sin = np.cos(angle), np.sin(angle)
    cross = np.stack([axis[1] * v[:, 2] - axis[2] * v[:, 1],
                      axis[2] * v[:, 0] - axis[0] * v[:, 2],
                      axis[0] * v[:, 1] - axis[1] * v[:, 0]])
    along = (v @ axis) * (1.0 - cos)
    return component_major(v.T * cos + cross * sin + axis[:, None] * along)


def object_motions(scene):
    """The moving objects of a scene: ``{object index: Motion}`` (identity motions left out)."""
    motions = getattr(scene, "motions", None) or {}
    return {k: m for k, m in motions.items() if m is not None and m.moves}


def blurs(scene):
    """True if some object moves while the shutter is open (the ``motion`` stage)."""
    open_, close = scene.camera.shutter
    return close > open_ and bool(object_motions(scene))


def scene_at_time(scene, time):
    """A static copy of ``scene`` with every moving object placed at ``time``.

    Used when the shutter has zero length (no blur, but objects at the shutter's instant),
    and by tests as the reference "N static renders at fixed times".

    Parameters
    ----------
    scene : Scene
    time : float

    Returns
    -------
    Scene
        Without motions; each moving object's ``object_to_world`` (where the scene has
        them) is its motion at ``time`` after its own.
    """
    vertices = scene.vertices.copy()
    to_world = list(getattr(scene, "object_to_world", None) or [])
    face_normals = scene.face_normals.copy()
    vertex_normals = None if scene.vertex_normals is None else scene.vertex_normals.copy()
    world = np.arange(len(scene.faces)) < (len(scene.faces) if scene.instances is None else scene.instances.first_face)
    for k, motion in object_motions(scene).items():
        faces = (scene.object_id == k) & world  # (a prototype's faces carry its first placement's id)
        used = np.unique(scene.faces[faces])
        t = np.full(len(used), float(time))
        vertices[used] = motion.to_world(vertices[used], t)
        face_time = np.full(int(faces.sum()), float(time))
        face_normals[faces] = motion.rotate_vectors(face_normals[faces], face_time)
        if vertex_normals is not None:
            vertex_normals[used] = motion.rotate_vectors(vertex_normals[used], t)
        if k < len(to_world):
            to_world[k] = motion.matrix(float(time)) @ to_world[k]
    changes = {"object_to_world": to_world} if to_world else {}
    return dataclasses.replace(scene, vertices=vertices, face_normals=face_normals,
                               vertex_normals=vertex_normals, motions={}, **changes)


def swept_bounds(scene):
    """(2, 3) float: bounds of the geometry over the whole shutter interval.

    Translation is linear in time, so a translating object's box is the union of its boxes
    at the shutter's ends; a rotating object stays inside the sphere around its centre
    through its farthest vertex, whose centre moves linearly, so the union of that sphere's
    boxes at both ends bounds it.
    """
    lo, hi = scene.bounds
    ends = np.array(scene.camera.shutter, dtype=np.float64)
    for k, motion in object_motions(scene).items():
        points = scene.vertices[np.unique(scene.faces[scene.object_id == k])]
        for t in ends:
            if motion.rotates:
                radius = float(np.linalg.norm(points - motion.centre, axis=1).max())
                centre = motion.centre + t * motion.translate
                box = np.stack([centre - radius, centre + radius])
            else:
                moved = points + t * motion.translate
                box = np.stack([moved.min(axis=0), moved.max(axis=0)])
            lo, hi = np.minimum(lo, box[0]), np.maximum(hi, box[1])
    return np.stack([lo, hi])


class _Mover:
    """One moving object: its Accel over the rest-pose triangles, its global face ids, and a
    sphere holding everything it sweeps during the shutter (to skip the rays that miss it)."""

    __slots__ = ("accel", "faces", "motion", "centre", "radius2")

    def __init__(self, vertices, faces, face_ids, motion, shutter):
        used, local = np.unique(faces[face_ids], return_inverse=True)
        self.accel = Accel(vertices[used], local.reshape(-1, 3))
        self.faces = face_ids
        self.motion = motion
        # the object stays within `reach` of its pivot (rotation keeps distances to the
        # pivot), and the pivot moves along a segment: a sphere around the segment's middle
        points = self.accel.vertices
        pivot = motion.centre if motion.rotates else points.mean(axis=0)
        reach = float(np.linalg.norm(points - pivot, axis=1).max())
        t0, t1 = shutter
        self.centre = pivot + 0.5 * (t0 + t1) * motion.translate
        radius = reach + 0.5 * abs(t1 - t0) * float(np.linalg.norm(motion.translate))
        # generous margin: the test only has to be conservative
        margin = 1e-6 * (radius + max(float(np.abs(self.centre).max()), 1.0))
        self.radius2 = (radius + margin) ** 2

    def candidates(self, origins, directions, t_max):
        """Rows of the rays that can meet the object before ``t_max`` (unit directions)."""
        return rays_near_sphere(*(by_component(np.asfortranarray(v, dtype=np.float64)) for v in (origins, directions)),
                                np.ascontiguousarray(np.broadcast_to(t_max, len(origins)), dtype=np.float64),
                                self.centre, self.radius2)


class MotionAccel:
    """Closest-hit and occlusion queries with moving objects placed at each ray's time.

    Offers the queries of :class:`~rtmesh.geometry.accel.Accel` with a per-ray ``time``; triangle
    (``prim``) ids are the scene's global face indices.

    Parameters
    ----------
    vertices : (V, 3) float
        Rest-pose positions (already re-centred by the integrator).
    faces : (F, 3) int
    object_id : (F,) int
    motions : dict of int to Motion
        Moving objects, in the same (re-centred) frame as ``vertices``.
    shutter : (2,) float
        The interval every query time lies in.
    instances : rtmesh.scene.instances.Instances, optional
        Placed meshes (static: a moving placement is copied into the world first), traced
        in the static scene as Embree instances; ``faces`` from ``instances.first_face`` on
        are their prototypes.

    Attributes
    ----------
    triangles : (F, 9) float64
        ``[v0, v1 - v0, v2 - v0]`` of every face in the rest pose, exactly as its Embree
        scene saw it (see :attr:`Accel.triangles`).
    face_mover : (F,) intp
        Index of the face's moving object in :attr:`movers`, -1 for static faces.
    instances : Instances or None
        As given: a hit's ``instance`` is its placement (:meth:`intersect`).
    """

    def __init__(self, vertices, faces, object_id, motions, shutter=(0.0, 1.0), instances=None):
        faces = np.asarray(faces)
        object_id = np.asarray(object_id)
        self.instances = instances
        first_placed = len(faces) if instances is None else instances.first_face
        self.face_mover = np.full(len(faces), -1, dtype=np.intp)
        self.movers = []
        for k in sorted(motions):
            # (a prototype's faces carry its first placement's object id: world faces only)
            face_ids = np.flatnonzero(object_id[:first_placed] == k)
            if len(face_ids):
                self.face_mover[face_ids] = len(self.movers)
                self.movers.append(_Mover(vertices, faces, face_ids, motions[k], shutter))
        # the static scene: the static world faces, then the prototypes (its own face numbers
        # map to the scene's through static_faces)
        self.static_faces = np.flatnonzero(self.face_mover < 0)
        placed = None
        if instances is not None:
            static_world = int(np.count_nonzero(self.face_mover < 0)) - (len(faces) - first_placed)
            placed = dataclasses.replace(instances, first_face=static_world,
                                         prototype_faces=instances.prototype_faces - first_placed + static_world)
        self.static = Accel(vertices, faces[self.static_faces], instances=placed) if len(self.static_faces) else None
        triangles = np.zeros((9, len(faces)))
        if self.static is not None:
            triangles[:, self.static_faces] = self.static.triangles.T
        for mover in self.movers:
            triangles[:, mover.faces] = mover.accel.triangles.T
        self.triangles = component_major(triangles)

    def intersect(self, origins, directions, time=None):
        """Closest hit of each ray with the scene at the ray's time.

        Parameters
        ----------
        origins, directions : (n, 3) float
        time : (n,) float
            Time of each ray (required; the default only keeps the argument order of
            :meth:`rtmesh.geometry.accel.Accel.intersect`).

        Returns
        -------
        Hits
            ``prim`` is the global face index; ``t`` the world distance.
        """
        if time is None:
            raise ValueError("a scene with moving objects is traced at each ray's time")
        n = len(directions)
        instance = None
        if self.static is not None:
            hits = self.static.intersect(origins, directions)
            prim = np.where(hits.prim >= 0, self.static_faces.take(np.maximum(hits.prim, 0)), -1)
            t, u, v, instance = hits.t, hits.u, hits.v, hits.instance
        else:
            t, prim = np.full(n, np.inf), np.full(n, -1, dtype=np.int64)
            u, v = np.zeros(n), np.zeros(n)
            if self.instances is not None:
                instance = np.full(n, -1, dtype=np.int32)
        for mover in self.movers:
            m = mover.motion
            rows = mover.candidates(origins, directions, t)
            if not len(rows):
                continue
            o, d = m.rays_to_rest(take_rows(origins, rows), take_rows(directions, rows), time[rows])
            h = mover.accel.intersect(o, d)
            # the static scene wins ties: a fixed order keeps the result deterministic
            closer = np.flatnonzero(h.t < t[rows])
            if len(closer):
                hit_rows = rows[closer]
                t[hit_rows] = h.t[closer]
                prim[hit_rows] = mover.faces[h.prim[closer]]
                u[hit_rows] = h.u[closer]
                v[hit_rows] = h.v[closer]
                if instance is not None:
                    instance[hit_rows] = -1
        return Hits(t, prim.astype(np.int32), u, v, instance)

    def occluded(self, origins, directions, t_max, rows=None, time=None):
        """Whether anything lies on each ray before ``t_max`` at the ray's time.

        Parameters
        ----------
        origins, directions : (n, 3) float
        t_max : (n,) float
        rows : (k,) int, optional
            Trace only these rays.
        time : (n,) float
            Time of each ray (required; ``time[rows]`` is used with ``rows``).

        Returns
        -------
        (n,) or (k,) bool
        """
        if time is None:
            raise ValueError("a scene with moving objects is traced at each ray's time")
        if rows is not None:
            origins, directions = take_rows(origins, rows), take_rows(directions, rows)
            t_max, time = t_max[rows], time[rows]
        if self.static is not None:
            occluded = self.static.occluded(origins, directions, t_max)
        else:
            occluded = np.zeros(len(t_max), dtype=bool)
        for mover in self.movers:
            free = np.flatnonzero(~occluded)
            if not len(free):
                break
            o, d = take_rows(origins, free).astype(np.float64), take_rows(directions, free)
            near = mover.candidates(o, d, t_max[free])
            if not len(near):
                continue
            free = free[near]
            o, d = mover.motion.rays_to_rest(take_rows(o, near), take_rows(d, near), time[free])
            occluded[free] = mover.accel.occluded(o, d, t_max[free])
        return occluded

    def directions_to_rest(self, prim, time, directions):
        """Ray directions in the rest frame of the object each hit lies on.

        Parameters
        ----------
        prim : (k,) int
            Hit faces.
        time : (k,) float
        directions : (k, 3) float

        Returns
        -------
        (k, 3) float
            ``directions`` itself when no hit lies on a rotating object.
        """
        out = directions
        for i, rows in self._rows_per_mover(prim, rotating_only=True):
            if out is directions:
                out = directions.copy(order="K")
            motion = self.movers[i].motion
            out[rows] = motion.rotate_vectors(directions[rows], time[rows], inverse=True)
        return out

    def surfaces_to_world(self, prim, time, points, ng, ns):
        """Hit points and normals computed in the rest pose, moved to the ray's time.

        Parameters
        ----------
        prim : (k,) int
        time : (k,) float
        points, ng, ns : (k, 3) float
            Rest-pose points, geometric and shading normals (``ns`` may be ``ng`` itself).

        Returns
        -------
        points, ng, ns : (k, 3) float64
            Modified in place where possible; ``ns is ng`` is preserved.
        """
        same = ns is ng
        for i, rows in self._rows_per_mover(prim):
            m, t = self.movers[i].motion, time[rows]
            points[rows] = m.to_world(points[rows], t)
            if m.rotates:
                ng[rows] = m.rotate_vectors(ng[rows], t)
                if not same:
                    ns[rows] = m.rotate_vectors(ns[rows], t)
        return points, ng, ng if same else ns

    def _rows_per_mover(self, prim, rotating_only=False):
        """``(mover index, rows of prim on it)`` for every mover hit at least once."""
        mover = self.face_mover.take(prim)
        for i in np.unique(mover[mover >= 0]):
            if rotating_only and not self.movers[i].motion.rotates:
                continue
            yield int(i), np.flatnonzero(mover == i)


@kernel
def rays_near_sphere(origins_t, directions_t, t_max, centre, radius2):
    """Rows of the rays whose segment ``[0, t_max]`` can meet a sphere.

    Parameters
    ----------
    origins_t, directions_t : (3, n) float64
        Origins and unit directions, by component (:func:`rtmesh.core.compiled.by_component`).
    t_max : (n,) float64
    centre : (3,) float64
    radius2 : float
        The squared radius.

    Returns
    -------
    (k,) int64
        In increasing order: ``b = oc . d``, ``disc = b^2 - (oc . oc - r^2)``, kept where
        ``disc >= 0``, ``sqrt(disc) - b >= 0`` and ``-b - sqrt(disc) <= t_max`` (``oc``
        the origin minus the centre; dot products summed ``(x + y) + z``).
    """
    n = len(t_max)
    near = np.empty(n, np.bool_)
    for i in range(n):
        ox, oy, oz = origins_t[0, i] - centre[0], origins_t[1, i] - centre[1], origins_t[2, i] - centre[2]
        b = dot3(ox, oy, oz, directions_t[0, i], directions_t[1, i], directions_t[2, i])
        c = dot3(ox, oy, oz, ox, oy, oz) - radius2
        disc = b * b - c
        root = math.sqrt(disc if disc > 0.0 else 0.0)
        near[i] = (disc >= 0.0) & (root - b >= 0.0) & (-b - root <= t_max[i])
    return np.flatnonzero(near)
