"""Nested dielectric media: which medium each ray travels in, and the index ratio at a surface.

The medium model
----------------
A medium is identified by the id of the transmissive material whose interior it is (``-1``:
the vacuum/air outside every object, index 1).  Every ray carries a small stack of media
(:attr:`rtmesh.core.rays.RayBatch.medium`, shape ``(n, STACK_DEPTH)``), innermost first:
column 0 is the medium the ray travels in, column 1 the one it returns to when it leaves
that, and so on; unused entries are -1.

* Refracting *into* a surface (the ray meets its front, counter-clockwise side) pushes the
  surface's material; refracting *out of* it (the back side) removes the topmost entry of
  that material.  Reflected rays keep their stack.
* The relative index at the interface is ``eta = ior(medium before) / ior(medium after)``,
  the innermost medium of the stack before and after the crossing.  A glass sphere in water
  therefore refracts with 1.33 / 1.5 going in and 1.5 / 1.33 coming out, and an interface
  between two media of the same index (or the same material) has ``eta = 1``: no Fresnel
  reflection, no bending -- it is invisible.
* Priority: the medium entered last wins.  For properly nested closed meshes that is the
  innermost one.  Where objects overlap, the ray is in whichever it entered last, and leaving
  the other one (not on top of the stack) changes nothing (``eta = 1``).
* A ray leaving a material that is not on its stack (it entered the object unseen, e.g.
  through a crack, or the stack overflowed) is taken to have been inside it: ``eta`` is
  ``ior(material) / ior(top of stack)`` and the stack is unchanged.  This reproduces the
  classic "leaving an object returns to air" rule of a stack-free tracer.
* More than ``STACK_DEPTH`` nested media drop the outermost entry.
* Beer-Lambert absorption uses the absorption of the innermost medium (column 0).
* A medium is a material: all its faces, in whatever objects, bound it together.
* Coincident surfaces: two transmissive faces with exactly the same three vertex positions
  (glass touching water, two glass blocks sharing a face) are *twins*: whichever of the two
  the ray hits, both crossings are applied at once, the one that leaves first.  The ray
  thus goes straight from one medium to the other with ``eta = ior(a) / ior(b)``.
  Coplanar faces that overlap without having identical vertices are not twins: the ray
  sees only the face Embree reports (the spawned ray starts beyond both), so model touching
  media with shared triangles, or with a small overlap (the medium entered last wins).
  Placed meshes (:mod:`rtmesh.scene.instances`) find twins within each prototype (in its
  own coordinates) and within the world's faces, not between two placements.

The camera's own stack is found by probe rays from its position (:meth:`Media.camera_stack`):
for every transmissive material, the winding number along a probe ray
(+1 for each crossing out through a back side, -1 for each crossing in through a front
side) is 1 when the camera is inside it; a majority over several probe directions decides,
and the groups are stacked innermost on top, by how far along the probes they are first
met.  Thin-lens cameras use the stack of the lens centre.
"""

import numpy as np

from rtmesh.core.rays import STACK_DEPTH
from rtmesh.core.vecmath import dot
from rtmesh.geometry.accel import offset_ray_origins

# Probe directions for the camera's medium: a few directions with no simple rational
# relation to the axes (so they do not run along the edges of axis-aligned models), spread
# over the sphere.  An odd count makes the majority vote decisive.
_PROBES = np.array([[0.5469, 0.3127, 0.7767], [-0.6713, 0.5312, 0.5168], [0.2831, -0.8517, 0.4410],
                    [-0.4123, -0.3719, -0.8317], [0.8147, -0.2269, -0.5337]])
_PROBES = _PROBES / np.linalg.norm(_PROBES, axis=1)[:, None]
# A probe ray stops after this many crossings (a scene is not expected to stack more
# surfaces than this along one line; the vote of that probe is then discarded).
_MAX_CROSSINGS = 512


class Media:
    """The medium tables of a scene with transmissive materials.

    Parameters
    ----------
    materials : MaterialTable
    material_id : (F,) int
        Material of each face.
    vertices : (V, 3) float
        The positions the faces index (only exact equality of positions matters).
    faces : (F, 3) int
    face_normals : (F, 3) float
        Unit geometric normals (counter-clockwise side).
    refracts : (M,) bool, optional
        The materials that bound media; default: those with a Whitted transmission colour
        (the path integrator passes the transmissive materials of its own models, for the
        camera's stack).
    instances : rtmesh.scene.instances.Instances, optional
        The scene's placements: faces from ``instances.first_face`` on are prototypes in
        model coordinates.  Twins are found within the world's faces and within each
        prototype (a placement's faces touch each other as in the model); the camera's
        probes read a placed face's normal in the world.

    Attributes
    ----------
    ior : (m + 1,) float64
        Index of refraction by medium id; entry -1 (the last) is 1.0, the outside.
    absorption : (m + 1, 3) float64
        Beer-Lambert coefficient by medium id (per scene unit); zero outside.
    twin : (F,) intp
        The transmissive face with exactly the same vertex positions, -1 for none.
    twin_opposite : (F,) bool
        True where the twin's normal points the other way (the usual case: two media
        touching).
    group : (F,) intp
        Index of the medium (in ``group_material``) each face bounds, -1 for opaque faces.
    group_material : (g,) int32
        The transmissive materials.
    """

    def __init__(self, materials, material_id, vertices, faces, face_normals, refracts=None, instances=None):
        self.ior = np.concatenate([materials.ior, [1.0]])
        self.absorption = np.concatenate([materials.absorption, np.zeros((1, 3))])
        if refracts is None:
            refracts = (materials.transmission > 0).any(axis=1)
        transmissive = refracts[material_id]
        # a medium is a material: all its surfaces, in whatever objects, bound it together
        # (a water shell may be an outer sphere and an inward-facing inner one)
        self.group_material = np.flatnonzero(refracts).astype(np.int32)
        group_of_material = np.cumsum(refracts) - 1
        self.group = np.where(transmissive, group_of_material[material_id], -1).astype(np.intp)
        space = None
        if instances is not None:
            # the world's vertices, then each prototype's in its own coordinates
            space = np.zeros(len(vertices))
            space[instances.first_vertex:] = np.repeat(np.arange(1, len(instances.prototype_vertices)),
                                                       np.diff(instances.prototype_vertices))
        self.instances = instances
        self.twin = coincident_faces(vertices, faces, transmissive, space)
        has_twin = self.twin >= 0
        self.twin_opposite = np.zeros(len(material_id), dtype=bool)
        self.twin_opposite[has_twin] = np.einsum(
            "ij,ij->i", face_normals[has_twin], face_normals[self.twin[has_twin]]) < 0.0
        self.material_id = np.asarray(material_id, dtype=np.int32)
        self.face_normals = np.asarray(face_normals, dtype=np.float64)
        self.any_twins = bool(has_twin.any())

    # ------------------------------------------------------------------ crossing
    def cross(self, stack, prim, entering):
        """Refraction through the faces ``prim``: relative index and the stacks beyond.

        Parameters
        ----------
        stack : (k, STACK_DEPTH) int
            Media of the incoming rays, innermost first.
        prim : (k,) int
            Face each ray refracts through (transmissive).
        entering : (k,) bool
            True where the ray meets the face's front (counter-clockwise) side.

        Returns
        -------
        eta : (k,) float64
            ``ior(medium before) / ior(medium after)``, exactly 1.0 where both are the same.
        after : (k, STACK_DEPTH) int32
            Media of the refracted rays.
        """
        stack = np.asarray(stack)
        mat = self.material_id.take(prim)
        first_mat, first_entering = mat, entering
        second = None
        if self.any_twins:
            twin = self.twin.take(prim)
            rows = np.flatnonzero(twin >= 0)
            if len(rows):
                twin_mat = self.material_id.take(twin[rows])
                twin_entering = entering[rows] != self.twin_opposite.take(prim[rows])
                # leave before entering, whichever of the two faces was hit
                swap = entering[rows] & ~twin_entering
                first_mat, first_entering = mat.copy(), entering.copy()
                first_mat[rows] = np.where(swap, twin_mat, mat[rows])
                first_entering[rows] = np.where(swap, twin_entering, entering[rows])
                second = (rows, np.where(swap, mat[rows], twin_mat),
                          np.where(swap, entering[rows], twin_entering))
        after, found = _apply(stack, first_mat, first_entering)
        # leaving a material the stack does not hold: the ray was in it all along
        before_medium = np.where(first_entering | found, stack[:, 0], first_mat)
        if second is not None:
            rows, twin_mat, twin_entering = second
            after[rows], _ = _apply(after[rows], twin_mat, twin_entering)
        # the same medium (or two of equal ior) on both sides gives exactly 1: no Fresnel
        # reflection, no bending
        eta = self.ior.take(before_medium) / self.ior.take(after[:, 0])
        return eta, after

    # ------------------------------------------------------------------ camera
    def camera_stack(self, trace, position, scale, to_rest=None):
        """The media a camera at ``position`` sits in, by winding numbers along probe rays.

        Along a probe ray from the camera to infinity, each crossing of a surface of a
        medium counts +1 where the ray leaves (meets the back side) and -1 where it enters:
        the sum is 1 for a closed, outward-facing mesh around the camera and 0 for one that
        is not around it, the same winding convention refraction uses; nested bodies of the
        same material add up.  The camera is in a medium (as many times as the sum says)
        when most probes say so (a probe that misses an open sheet votes "no").

        Parameters
        ----------
        trace : callable
            ``trace(origins, directions) -> Hits`` (closest hits, global face ids).
        position : (3,) float
            Camera position in the frame ``trace`` works in.
        scale : float
            Scene size for :func:`offset_ray_origins`.
        to_rest : callable, optional
            ``to_rest(prim, directions) -> directions`` in the rest frame of the faces hit
            (moving objects), to tell their sides apart; default: identity.

        Returns
        -------
        (STACK_DEPTH,) int32
            Innermost first, -1 padded.
        """
        stack = np.full(STACK_DEPTH, -1, dtype=np.int32)
        n_groups = len(self.group_material)
        if not n_groups:
            return stack
        n_probes = len(_PROBES)
        winding = np.zeros((n_probes, n_groups), dtype=np.int64)
        first_t = np.full((n_probes, n_groups), np.inf)
        directions = _PROBES.copy()
        origins = np.tile(np.asarray(position, dtype=np.float64), (n_probes, 1))
        travelled = np.zeros(n_probes)
        active = np.arange(n_probes)
        for _ in range(_MAX_CROSSINGS):
            hits = trace(origins[active], directions[active])
            hit = hits.prim >= 0
            active, t, prim = active[hit], hits.t[hit], hits.prim[hit].astype(np.intp)
            if not len(active):
                break
            travelled[active] += t
            d = directions[active]
            d_rest = d if to_rest is None else to_rest(prim, d)
            normals = self.face_normals[prim]
            if self.instances is not None and hits.instance is not None:
                normals = self.instances.world_normals(normals, hits.instance[hit])
            leaving = dot(d_rest, normals) > 0.0
            crossed = [(prim, leaving)]
            if self.any_twins:
                twin = self.twin.take(prim)
                crossed.append((twin, leaving != self.twin_opposite.take(prim)))
            for face, face_leaving in crossed:
                group = np.where(face >= 0, self.group.take(np.maximum(face, 0)), -1)
                rows = np.flatnonzero(group >= 0)
                probe, g = active[rows], group[rows]
                np.add.at(winding, (probe, g), np.where(face_leaving[rows], 1, -1))
                first_t[probe, g] = np.minimum(first_t[probe, g], travelled[probe])
            # step past the surface, along the ray (the side it leaves toward)
            points = origins[active] + t[:, None] * d
            origins[active] = offset_ray_origins(points, d, scale=scale, directions=d)
        else:
            # probes still crossing surfaces: their count is unfinished, they do not vote
            winding[active] = 0
        # the nesting count of each medium most probes agree on (0: not around the camera)
        count = np.median(np.maximum(winding, 0), axis=0).astype(np.int64)
        groups = np.flatnonzero(count > 0)
        if not len(groups):
            return stack
        # innermost (met first along the probes) on top
        met = np.where(np.isfinite(first_t[:, groups]), first_t[:, groups], np.nan)
        order = groups[np.argsort(np.nanmedian(met, axis=0), kind="stable")]
        innermost_first = np.repeat(self.group_material[order], count[order])[:STACK_DEPTH]
        stack[:len(innermost_first)] = innermost_first
        return stack


def _apply(stack, mat, entering):
    """Push ``mat`` where ``entering``, else remove its topmost entry.

    Returns
    -------
    after : (k, STACK_DEPTH) int32
    found : (k,) bool
        Where a leaving ray found ``mat`` on its stack (True for entering rays too).
    """
    k = len(stack)
    stack = stack.astype(np.int32, copy=False)
    mat = mat.astype(np.int32, copy=False)
    outside = np.full((k, 1), -1, dtype=np.int32)
    # entering: everything moves one place down, the outermost entry falls off the bottom;
    # leaving the top (the nested case): everything moves one place up
    pushed = np.concatenate([mat[:, None], stack[:, :-1]], axis=1)
    popped = np.concatenate([stack[:, 1:], outside], axis=1)
    on_top = stack[:, 0] == mat
    after = np.where(entering[:, None], pushed, np.where(on_top[:, None], popped, stack))
    found = entering | on_top
    # leaving a medium below the top (overlapping objects): only that entry goes
    rows = np.flatnonzero(~found)
    if len(rows):
        match = stack[rows] == mat[rows, None]
        below = match.any(axis=1)
        rows, match = rows[below], match[below]
        if len(rows):
            first = match.argmax(axis=1)
            columns = np.arange(stack.shape[1])
            source = columns + (columns >= first[:, None])
            padded = np.concatenate([stack[rows], outside[rows]], axis=1)
            after[rows] = np.take_along_axis(padded, source, axis=1)
            found[rows] = True
    return after, found


def coincident_faces(vertices, faces, candidates, space=None):
    """Pairs of candidate faces with exactly the same three vertex positions.

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int
    candidates : (F,) bool
        Faces that may pair up (the transmissive ones).
    space : (V,) float, optional
        The coordinate frame of each vertex (placed prototypes each have their own): only
        positions in the same frame are equal.

    Returns
    -------
    (F,) intp
        The other face of each pair, -1 for faces without one.  Three or more faces at the
        same position pair up only the first two (in face order).
    """
    twin = np.full(len(faces), -1, dtype=np.intp)
    ids = np.flatnonzero(candidates)
    if len(ids) < 2:
        return twin
    # equal positions get equal ids even where the mesh has duplicate vertices
    points = np.asarray(vertices) if space is None else np.column_stack([vertices, space])
    _, position = np.unique(points, axis=0, return_inverse=True)
    corners = np.sort(position.reshape(-1)[np.asarray(faces)[ids]], axis=1)
    _, triangle, counts = np.unique(corners, axis=0, return_inverse=True, return_counts=True)
    triangle = triangle.reshape(-1)
    order = np.argsort(triangle, kind="stable")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    paired = starts[counts >= 2]
    a, b = ids[order[paired]], ids[order[paired + 1]]
    twin[a], twin[b] = b, a
    return twin
