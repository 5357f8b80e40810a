"""Meshes placed many times: each built once (a prototype) and placed by Embree instances.

A :class:`~rtmesh.scene.model.Scene` with ``instances`` keeps, after its flat (world-space)
triangles, each prototype's triangles once, in the prototype's own (model) coordinates; an
:class:`Instances` record places them.  Every per-face and per-vertex table of the scene
(materials, normals, UVs, colours) covers the prototypes' faces once, so a hit on instance
``j`` reads face ``Instances.face_offset[j] + primID`` of those tables, and its point and
normals are carried to the world by the instance's transform
(:mod:`rtmesh.rendering.path_kernel`; for the batched queries' hits, which report the
placement as ``Hits.instance``, :func:`rtmesh.shading.surfaces.placed_surface_records`).

Only the path kernel traces instances (under path, and in its Whitted configuration), its
passes, denoiser guides and transparent backgrounds included (:func:`unsupported` says what
it does not trace through them yet); everything else renders :func:`flattened`, the copies
the loaders made before instancing existed.
"""

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import scipy.spatial
import trimesh

from rtmesh.core.compiled import kernel
from rtmesh.geometry import build_kernels

# A mesh placed more than once is built once and placed by Embree instances when it has at
# least this many triangles; smaller ones are copied.  Measured (benchmarks/bench_instancing.py
# crossover, docs/BENCHMARKS.md "Instancing"): the copies' build costs ~1 us a triangle a
# copy while the instances' stays ~20 ms, and a frame renders up to 12 % slower through
# instances of a small mesh (a second level of traversal); build and one 128x96, 16 spp
# frame break even between 20 and 80 triangles (400 and 1600 placements)
MIN_TRIANGLES = 64


def _linear(m, v):
    """(k, 3) vectors ``v`` through (k, 9+) row-major 3 x 3 matrices ``m`` (their first nine
    columns), each component summed in the order the kernels sum it."""
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    return np.stack([(m[:, 3 * c] * x + m[:, 3 * c + 1] * y) + m[:, 3 * c + 2] * z for c in range(3)], axis=1)


@dataclass
class Instances:
    """Where a scene's prototypes are and where they are placed.

    Attributes
    ----------
    first_face, first_vertex : int
        ``Scene.faces[first_face:]`` and ``Scene.vertices[first_vertex:]`` belong to the
        prototypes (model coordinates); everything before is world-space geometry.
    prototype_faces, prototype_vertices : (P + 1,) int64
        Prototype ``p``'s faces are ``Scene.faces[prototype_faces[p]:prototype_faces[p + 1]]``,
        its vertices likewise (face indices are global, as for every face of the scene).
    transforms : (k, 4, 4) float64
        Each placement's model-to-world transform (finite, non-singular, affine).
    prototype : (k,) int64
        Each placement's prototype.
    object_id : (k,) int32
        Each placement's object index (``Scene.object_names``).
    """

    first_face: int
    first_vertex: int
    prototype_faces: np.ndarray
    prototype_vertices: np.ndarray
    transforms: np.ndarray
    prototype: np.ndarray
    object_id: np.ndarray
    # bounds() and world_rows(), formed once (the prototypes' vertices and the placements
    # do not change once the scene is made)
    _bounds: list = field(default_factory=list, init=False, repr=False, compare=False)
    _rows: list = field(default_factory=list, init=False, repr=False, compare=False)

    def __len__(self):
        return len(self.prototype)

    @property
    def face_offset(self):
        """(k,) int64: each placement's first face in the scene's per-face tables."""
        return self.prototype_faces[self.prototype]

    def world_rows(self):
        """The placements as compiled code reads them (the path kernel's ``instances``
        record, :func:`rtmesh.shading.surfaces.placed_surface_records`); formed once.

        Returns
        -------
        face_offset : (k,) int64
            :attr:`face_offset`.
        to_world : (k, 12) float64
            Each model-to-world transform: the linear part row by row, then the translation.
        normal_to_world : (k, 9) float64
            The inverse transpose of each linear part, row by row.
        """
        if not self._rows:
            linear = self.transforms[:, :3, :3]
            to_world = np.concatenate([linear.reshape(-1, 9), self.transforms[:, :3, 3]], axis=1)
            normal_to_world = np.linalg.inv(linear).transpose(0, 2, 1).reshape(-1, 9)
            self._rows.append((np.ascontiguousarray(self.face_offset, dtype=np.int64),
                               np.ascontiguousarray(to_world), np.ascontiguousarray(normal_to_world)))
        return self._rows[0]

    def world_points(self, points, instance):
        """Points on the prototypes carried to the world by their placements, in the
        arithmetic of :func:`rtmesh.shading.surfaces.placed_surface_record`.

        Parameters
        ----------
        points : (n, 3) float64
            Model coordinates where ``instance >= 0``, world coordinates elsewhere.
        instance : (n,) int
            Each point's placement, -1 for a point already in the world.

        Returns
        -------
        (n, 3) float64
            A new array.
        """
        out = np.array(points, dtype=np.float64)
        rows = np.flatnonzero(instance >= 0)
        if len(rows):
            a = self.world_rows()[1][instance[rows]]
            out[rows] = _linear(a, out[rows]) + a[:, 9:12]
        return out

    def world_vectors(self, vectors, instance, matrices=1):
        """Directions (edges, tangents) of the prototypes carried to the world by the linear
        parts of their placements (not normalised).

        Parameters
        ----------
        vectors : (n, 3) float64
            Model-space rows where ``instance >= 0``, world rows elsewhere.
        instance : (n,) int
            Each row's placement, -1 for a row already in the world.
        matrices : int
            Which of :meth:`world_rows`' matrices: 1 the linear parts, 2 their inverse
            transposes (for normals).

        Returns
        -------
        (n, 3) float64
            A new array.
        """
        out = np.array(vectors, dtype=np.float64)
        rows = np.flatnonzero(instance >= 0)
        if len(rows):
            out[rows] = _linear(self.world_rows()[matrices][instance[rows]], out[rows])
        return out

    def world_normals(self, normals, instance):
        """Unit normals of prototype faces (``(n, 3)``, rows as :meth:`world_vectors` takes
        them) carried to the world by the inverse transpose of their placements' linear
        parts and normalised again, in the arithmetic of the path kernel's
        :func:`rtmesh.rendering.path_packets.placed`; a new array."""
        out = self.world_vectors(normals, instance, matrices=2)
        rows = np.flatnonzero(instance >= 0)
        n = out[rows]
        out[rows] = n / np.sqrt((n[:, 0] * n[:, 0] + n[:, 1] * n[:, 1]) + n[:, 2] * n[:, 2])[:, None]
        return out

    def world_tangents(self, tangents, instance):
        """UV tangents and bitangents of prototype faces carried to the world by the linear
        part of their placements, in the arithmetic of the path kernel's
        :func:`rtmesh.rendering.path_surfaces.face_tangents`.

        Parameters
        ----------
        tangents : (n, 6) float64
            Model-space rows where ``instance >= 0``, world rows elsewhere.
        instance : (n,) int
            Each row's placement, -1 for a row already in the world.

        Returns
        -------
        (n, 6) float64
            A new array.
        """
        out = np.array(tangents, dtype=np.float64)
        rows = np.flatnonzero(instance >= 0)
        if len(rows):
            a = self.world_rows()[1][instance[rows]]
            out[rows, :3], out[rows, 3:] = _linear(a, out[rows, :3]), _linear(a, out[rows, 3:])
        return out

    def hit_objects(self, object_id, prim, instance):
        """(n,) int32: the object each hit belongs to: a placement's own for a hit on a
        placement (every placement is an object), else its face's.

        Parameters
        ----------
        object_id : (F,) int
            The scene's per-face object index (a prototype's faces hold its first
            placement's).
        prim, instance : (n,) int
            Faces hit (in the per-face tables) and placements (-1: a world-space face).
        """
        return np.where(instance >= 0, self.object_id[np.maximum(instance, 0)], object_id[prim]).astype(np.int32)

    def bounds(self, vertices):
        """(2, 3) float64: world bounds of every placement.

        The extremes of an affine image of a point set are images of its convex hull's
        vertices, so only those are transformed (exact up to the rounding of the products,
        which the copies' vertices may sum in another order), and only for the placements
        whose box reaches beyond the bounds found so far (:func:`placed_bounds`); formed
        once.

        Parameters
        ----------
        vertices : (V, 3) float64
            The scene's vertices.
        """
        if self._bounds:
            return self._bounds[0].copy()
        bounds = np.array([np.full(3, np.inf), np.full(3, -np.inf)])
        transforms = np.ascontiguousarray(self.transforms[:, :3, :], dtype=np.float64)
        for p in range(len(self.prototype_vertices) - 1):
            placed = np.flatnonzero(self.prototype == p).astype(np.int64)
            if not len(placed):
                continue
            points = vertices[self.prototype_vertices[p]:self.prototype_vertices[p + 1]]
            try:
                points = points[scipy.spatial.ConvexHull(points).vertices]
            except scipy.spatial.QhullError:  # flat or degenerate: every vertex counts
                pass
            # each placement's box from the prototype's box (cheap, and never smaller than its
            # exact image but for rounding): only the placements whose box reaches beyond the
            # exact bounds found so far are transformed (a placement whose box only touches
            # them is skipped: its exact image could pass them by rounding alone, ~1e-16
            # relative, which keeps placements side by side on a plane from all being walked)
            low, high = points.min(axis=0), points.max(axis=0)
            centre, half = (low + high) / 2, (high - low) / 2
            linear = transforms[placed, :, :3]
            middle = linear @ centre + transforms[placed, :, 3]
            reach = np.abs(linear) @ half
            conservative = np.ascontiguousarray(np.stack([middle - reach, middle + reach], axis=1))
            # per side and axis, the placements in the order they may reach furthest out
            order = np.ascontiguousarray(np.stack([np.argsort(conservative[:, 0, :], axis=0, kind="stable").T,
                                                   np.argsort(-conservative[:, 1, :], axis=0, kind="stable").T]),
                                         dtype=np.int64)
            placed_bounds(np.ascontiguousarray(points, dtype=np.float64), transforms, placed, conservative, order,
                          bounds)
        self._bounds.append(bounds)
        return bounds.copy()


@kernel
def placed_bounds(points, transforms, placed, conservative, order, bounds):
    """Grow ``bounds`` by the images of ``points`` under the placements ``placed``.

    Parameters
    ----------
    points : (h, 3) float64
    transforms : (k, 3, 4) float64
        Model-to-world affine transforms.
    placed : (m,) int64
        Which transforms.
    conservative : (m, 2, 3) float64
        A box around each placement's image of ``points``.
    order : (2, 3, m) int64
        Per side (low, high) and axis, the placements (indices into ``placed``) by how far
        out their conservative box reaches: the walk stops at the first that cannot reach
        beyond what is found, so typically a handful are transformed, not all ``m``.
    bounds : (2, 3) float64
        Low and high corners, grown in place.
    """
    for c in range(3):
        for side in range(2):
            best = bounds[side, c]
            for r in range(order.shape[2]):
                i = order[side, c, r]
                if (conservative[i, side, c] >= best) if side == 0 else (conservative[i, side, c] <= best):
                    break
                j = placed[i]
                a0, a1, a2, t = transforms[j, c, 0], transforms[j, c, 1], transforms[j, c, 2], transforms[j, c, 3]
                for q in range(points.shape[0]):
                    # the row of A times the point, then the translation: the copies' order
                    x = ((a0 * points[q, 0] + a1 * points[q, 1]) + a2 * points[q, 2]) + t
                    best = min(best, x) if side == 0 else max(best, x)
            bounds[side, c] = best


def worth_instancing(triangles, placements):
    """Whether a mesh of ``triangles`` placed ``placements`` times is built once and placed
    by instances (else copied): placed more than once and at least :data:`MIN_TRIANGLES`."""
    return placements > 1 and triangles >= MIN_TRIANGLES


def check_transforms(transforms, names, source):
    """The placements whose transform cannot place a mesh: non-finite, singular or not
    affine (bottom row other than ``0 0 0 1``).

    Parameters
    ----------
    transforms : (k, 4, 4) float
    names : sequence of str
        Each placement's name, for the message.
    source : str

    Returns
    -------
    str or None
        A one-line description of the first bad placement, or None.
    """
    t = np.asarray(transforms, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        finite = np.isfinite(t).all(axis=(1, 2))
        affine = (t[:, 3] == (0.0, 0.0, 0.0, 1.0)).all(axis=1)
        det = np.where(finite, np.linalg.det(np.where(finite[:, None, None], t, 0.0)[:, :3, :3]), 0.0)
    bad = np.flatnonzero(~finite | ~affine | (det == 0.0))
    if not len(bad):
        return None
    j = int(bad[0])
    why = ("a non-finite transform" if not finite[j] else "a transform that is not affine" if not affine[j]
           else "a singular transform (zero scale)")
    more = f" ({len(bad) - 1} more placements likewise)" if len(bad) > 1 else ""
    return f"{source}: instance {names[j]!r} has {why}{more}"


def unsupported(scene, settings):
    """What keeps a scene's instances from being traced as instances (phrases; empty: the
    path kernel traces them, under path or in its Whitted configuration; the integrator
    adds what only it knows, :class:`rtmesh.rendering.integrator.Integrator`).

    Parameters
    ----------
    scene : Scene
        With ``instances``.
    settings : RenderSettings
    """
    from rtmesh.geometry import embree_library

    missing = []
    if not embree_library.packet_library():
        missing.append("the single-ray Embree path")
    return missing


def subset(placed, placements):
    """The :class:`Instances` of the ``placements`` (indices) of ``placed`` alone (for a
    memory estimate of their copies; the placements left after some are copied)."""
    return dataclasses.replace(placed, transforms=placed.transforms[placements],
                               prototype=placed.prototype[placements], object_id=placed.object_id[placements])


def flattened(scene, placements=None):
    """The scene with every placement (or those named) as a copy of its prototype (what the
    loaders made before instancing): vertices placed as :func:`trimesh.transform_points`
    places them, the winding reversed under a mirroring transform, normals by the inverse
    transpose.

    Parameters
    ----------
    scene : Scene
        With ``instances``.
    placements : (m,) int, optional
        The placements to copy; the others stay placed (their prototypes kept after the
        copies, the world-space faces).  Default: all of them.

    Returns
    -------
    Scene
        Without ``instances`` when every placement is copied (the prototypes' own faces
        are gone), else with the placements left.
    """

    inst = scene.instances
    f0, v0 = inst.first_face, inst.first_vertex
    flat = slice(0, f0)
    parts = {name: [] for name in ("vertices", "faces", "face_normals", "vertex_normals", "smooth", "material_id",
                                   "object_id", "uv", "vertex_colors")}

    def take(vertices, faces, normals, face_normals, faces_of, vertices_of, object_id):
        offset = sum(len(v) for v in parts["vertices"])
        parts["vertices"].append(vertices)
        parts["faces"].append(faces + offset)
        parts["face_normals"].append(face_normals)
        if scene.vertex_normals is not None:
            parts["vertex_normals"].append(normals)
            parts["smooth"].append(scene.smooth[faces_of])
        parts["material_id"].append(scene.material_id[faces_of])
        parts["object_id"].append(np.full(len(faces), object_id, np.int32) if object_id is not None
                                  else scene.object_id[faces_of])
        for name in ("uv", "vertex_colors"):
            if getattr(scene, name) is not None:
                parts[name].append(getattr(scene, name)[vertices_of])

    take(scene.vertices[:v0], scene.faces[flat], None if scene.vertex_normals is None else scene.vertex_normals[:v0],
         scene.face_normals[flat], flat, slice(0, v0), None)
    copied = np.arange(len(inst)) if placements is None else np.unique(np.asarray(placements, dtype=np.int64))
    for j in copied:
        p = inst.prototype[j]
        faces_of = slice(int(inst.prototype_faces[p]), int(inst.prototype_faces[p + 1]))
        vertices_of = slice(int(inst.prototype_vertices[p]), int(inst.prototype_vertices[p + 1]))
        matrix = inst.transforms[j]
        vertices = np.ascontiguousarray(trimesh.transform_points(scene.vertices[vertices_of], matrix))
        faces = np.asarray(scene.faces[faces_of], dtype=np.int64) - vertices_of.start
        if np.linalg.det(matrix[:3, :3]) < 0:
            faces = np.ascontiguousarray(faces[:, ::-1])  # a mirroring transform flips the winding
        face_normals, _ = build_kernels.face_crosses(vertices, faces)
        normals = None
        if scene.vertex_normals is not None:
            normals = scene.vertex_normals[vertices_of] @ np.linalg.inv(matrix[:3, :3])
            normals, _ = build_kernels.unit_rows(np.ascontiguousarray(normals), faces)
        take(vertices, faces, normals, face_normals, faces_of, vertices_of, int(inst.object_id[j]))
    left = np.setdiff1d(np.arange(len(inst)), copied)
    placed = None
    if len(left):
        # the prototypes after the copies, placed by the placements left
        first_face = sum(len(f) for f in parts["faces"])
        first_vertex = sum(len(v) for v in parts["vertices"])
        prototypes = slice(f0, len(scene.faces))
        take(scene.vertices[v0:], np.asarray(scene.faces[prototypes], dtype=np.int64) - v0,
             None if scene.vertex_normals is None else scene.vertex_normals[v0:], scene.face_normals[prototypes],
             prototypes, slice(v0, len(scene.vertices)), None)
        placed = dataclasses.replace(subset(inst, left), first_face=first_face, first_vertex=first_vertex,
                                     prototype_faces=inst.prototype_faces - f0 + first_face,
                                     prototype_vertices=inst.prototype_vertices - v0 + first_vertex)
    joined = {name: (np.concatenate(arrays) if arrays else None) for name, arrays in parts.items()}
    return dataclasses.replace(scene, instances=placed, vertices=joined["vertices"],
                               faces=joined["faces"].astype(np.int32), face_normals=joined["face_normals"],
                               vertex_normals=joined["vertex_normals"], smooth=joined["smooth"],
                               material_id=joined["material_id"], object_id=joined["object_id"],
                               uv=joined["uv"], vertex_colors=joined["vertex_colors"])


def object_geometry(scene, objects):
    """World vertices and faces of some objects of a scene, placements copied as
    :func:`flattened` copies them (for what traces objects alone: the amodal masks of
    :mod:`rtmesh.batch.coco`), one placement's copy at a time, never the whole scene's.

    Parameters
    ----------
    scene : Scene
    objects : iterable of int
        Object indices (``Scene.object_names``).

    Returns
    -------
    vertices : (V', 3) float64
        ``scene.vertices`` itself when none of the objects is a placement (the faces index
        it), else the vertices the faces use, world-space ones then each copy's.
    faces : (F', 3) int
    """
    objects = np.asarray(list(objects), dtype=np.int64)
    inst = scene.instances
    if inst is None:
        return scene.vertices, scene.faces[np.isin(scene.object_id, objects)]
    f0 = inst.first_face
    world = scene.faces[:f0][np.isin(scene.object_id[:f0], objects)]
    placed = np.flatnonzero(np.isin(inst.object_id, objects))
    if not len(placed):
        return scene.vertices, world
    used, corners = np.unique(np.asarray(world).ravel(), return_inverse=True)
    vertices, faces = [scene.vertices[used]], [corners.reshape(-1, 3)]
    offset = len(used)
    for j in placed:
        p = inst.prototype[j]
        va, vb = int(inst.prototype_vertices[p]), int(inst.prototype_vertices[p + 1])
        matrix = inst.transforms[j]
        copy = np.asarray(scene.faces[inst.prototype_faces[p]:inst.prototype_faces[p + 1]], dtype=np.int64) - va
        if np.linalg.det(matrix[:3, :3]) < 0:
            copy = copy[:, ::-1]  # a mirroring transform flips the winding
        vertices.append(trimesh.transform_points(scene.vertices[va:vb], matrix))
        faces.append(copy + offset)
        offset += vb - va
    return np.concatenate(vertices), np.ascontiguousarray(np.concatenate(faces), dtype=np.int32)
