"""Emissive meshes as one area light: every triangle whose material has an ``emission``
colour, sampled by area or, where a triangle is seen under a wide solid angle, uniformly in
that angle (Arvo).  Emissive triangles are ordinary geometry too: rays see them, and they
occlude and cast shadows like any surface.  See :mod:`rtmesh.lights.area_lights` for how area
lights emit and :mod:`rtmesh.lights.area_lighting` for the estimator.
"""

import numpy as np

from rtmesh.core.compiled import kernel
from rtmesh.core.rays import component_major, take_rows
from rtmesh.core.vecmath import dot, normalize
from rtmesh.sampling.warps import spherical_triangle_area, square_to_spherical_triangle, uniform_triangle_weights

# Emissive triangles seen under more than this solid angle (sr) are sampled uniformly in it
# (see MeshLight.sample); smaller ones by area.  Arvo's angle sums keep ~10 digits at 1e-3 sr.
SOLID_ANGLE_SAMPLING_FROM = 1e-3


class MeshLight:
    """Emissive triangles as one light emitting on both sides.

    Parameters
    ----------
    triangles : (F, 9) float
        Per face ``[v0, v1 - v0, v2 - v0]`` of the triangles exactly as Embree traces them
        (rows of :attr:`rtmesh.geometry.accel.Accel.triangles`), so a sampled point lies on the
        surface a shadow ray could hit.
    normals : (F, 3) float
        Unit face normals.
    emission : (F, 3) float
        Emitted radiance of each face; every face emits (some channel > 0).
    name : str
        What the triangles are, for messages.
    tint : callable, optional
        ``tint(faces, u, v)`` -> (k, 3) multipliers of the emission at points of the faces
        given by their index among the triangles and barycentrics (emission textures), or
        None where none of those faces has one; without it the faces emit uniformly.
    mean_tint : (F, 3) float, optional
        Each face's average of ``tint``, for choosing faces in proportion to their power.
    """

    two_sided = True
    visible = False  # seen as geometry through Embree, not by :meth:`AreaLighting.intersect`

    def __init__(self, triangles, normals, emission, name="mesh", tint=None, mean_tint=None, scene_faces=None):
        self.name = name
        # the light's face of each scene triangle (-1: not emissive), for pdf() of rays that hit one
        self.scene_faces = None if scene_faces is None else np.asarray(scene_faces, dtype=np.intp)
        self.triangles = component_major(np.asarray(triangles, dtype=np.float64).T)
        self.normals = component_major(np.asarray(normals, dtype=np.float64).T)
        self.emission = component_major(np.asarray(emission, dtype=np.float64).T)
        self.tint = tint
        e1, e2 = self.triangles[:, 3:6], self.triangles[:, 6:9]
        face_area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
        self._face_area = face_area
        self.area = float(face_area.sum())
        # a sphere around each face (centroid, farthest corner): its solid angle bounds the
        # face's, so faces far from a point are known to be small without the exact formula
        self._centroids = self.triangles[:, 0:3] + (e1 + e2) / 3.0
        corners = np.stack([np.zeros_like(e1), e1, e2]) - (e1 + e2) / 3.0
        self._radii = np.sqrt((corners ** 2).sum(axis=2).max(axis=0))
        # faces are chosen in proportion to their power (area x mean emission): uniform by
        # area for a uniform emitter, and no samples wasted on dim faces of a mixed one
        self._mean_emission = (self.emission if mean_tint is None else self.emission * mean_tint).mean(axis=1)
        power = face_area * self._mean_emission
        self._cdf = np.cumsum(power)
        self._power = power
        self._total = float(self._cdf[-1])
        # a guide to the CDF (one cell per face): where the search for a value in each
        # equal part of [0, total) starts (see choose_area_samples)
        cells = len(self._cdf)
        self._guide = np.searchsorted(self._cdf, self._total * (np.arange(cells) / cells), side="right")

    @property
    def is_black(self):
        return not self._total > 0.0

    def sample(self, u, p=None):
        """Points on the emitter, each face in proportion to its power; on the face uniform
        in the solid angle it subtends from ``p`` where that is large, else uniform by area.

        The first coordinate picks the face and is then rescaled to [0, 1) within the face's
        share of the CDF, so one pair of numbers does both and stratification carries over.

        A point close to a face sees it under a large solid angle, and samples uniform by
        area would weigh its near part with ``1 / d^2``: rare, very bright values (fireflies
        beside a lamp).  Uniform in solid angle (Arvo's spherical-triangle sampling) the
        geometric factor is bounded by the face's solid angle.  Faces seen under less than
        :data:`SOLID_ANGLE_SAMPLING_FROM` keep area sampling, which is as good there and
        where Arvo's angle sums lose their precision.

        Parameters
        ----------
        u : (k, 2) float
            Points in [0, 1)^2.
        p : (k, 3) float, optional
            The points being lit; without them every face is sampled by area.

        Returns
        -------
        points, normals, radiance : (k, 3) float
        inverse_pdf : (k,) float
            ``1 / pdf`` with respect to area: ``total power / mean emission of the face``
            (with a tint, the face's emission times its mean tint; the radiance is the
            emission times the tint at the point).
        """
        face, square_t, b_t, points_t = choose_area_samples(np.ascontiguousarray(u[:, 0]), np.ascontiguousarray(u[:, 1]),
                                                            self._total, self._cdf, self._power, self._guide,
                                                            self.triangles.T)
        square, b, points = square_t.T, b_t.T, points_t.T
        emission = take_rows(self.emission, face)
        inverse_pdf = self._total / self._mean_emission[face]
        if p is not None:
            self._sample_solid_angle(p, square, face, points, b, inverse_pdf)
        tint = None if self.tint is None else self.tint(face, b[:, 0], b[:, 1])
        if tint is not None:  # None: none of these faces has an emission texture
            emission = emission * tint
        return points, take_rows(self.normals, face), emission, inverse_pdf

    def pdf(self, origins, faces, points):
        """Solid-angle density with which :meth:`sample` (from ``origins``) draws ``points``
        on the light's ``faces``, (k,): the face's chance times ``1 / omega`` where the
        face is sampled in solid angle from that origin, else times ``d^2 / (|cos_l| A)``.

        Parameters
        ----------
        origins : (k, 3) float
            The points being lit.
        faces : (k,) int
            Indices among the light's faces.
        points : (k, 3) float
            Points on those faces.
        """
        chance = self._power[faces] / self._total
        to_point = points - origins
        d2 = dot(to_point, to_point)
        cos = np.abs(dot(to_point, take_rows(self.normals, faces))) / np.sqrt(np.maximum(d2, 1e-300))
        pdf = np.divide(chance * d2, cos * self._face_area[faces], out=np.full(len(faces), np.inf),
                        where=cos > 0.0)
        omega = self._solid_angles(origins, faces)
        wide = omega > SOLID_ANGLE_SAMPLING_FROM
        pdf[wide] = chance[wide] / omega[wide]
        return pdf

    def _corner_and_edges(self, faces):
        """``v0``, ``v1 - v0`` and ``v2 - v0`` of the given faces, three (k, 3) arrays."""
        return tuple(take_rows(self.triangles[:, k:k + 3], faces) for k in (0, 3, 6))

    def _solid_angles(self, p, face):
        """Solid angle of each face seen from ``p`` where it may exceed
        :data:`SOLID_ANGLE_SAMPLING_FROM` (0 where the bounding sphere rules that out)."""
        offset = take_rows(self._centroids, face) - p
        distance = np.sqrt(dot(offset, offset))
        radius = self._radii[face]
        gap = np.maximum(distance - radius, 0.0)
        cap = 2.0 * np.pi * (1.0 - gap / np.sqrt(gap * gap + radius * radius))  # >= the face's
        omega = np.zeros(len(face))
        near = np.flatnonzero(cap > SOLID_ANGLE_SAMPLING_FROM)
        if len(near):
            v0n, e1n, e2n = self._corner_and_edges(face[near])
            pn = take_rows(p, near)
            unit = [normalize(c) for c in (v0n - pn, v0n + e1n - pn, v0n + e2n - pn)]
            omega[near] = spherical_triangle_area(*unit)
        return omega

    def _sample_solid_angle(self, p, square, face, points, b, inverse_pdf):
        """Move the samples of faces seen under a large solid angle from ``p`` to points
        uniform in that solid angle; updates ``points``, ``b`` and ``inverse_pdf`` in place.

        The area density of such a point is ``P(face) |cos_l| / (omega d^2)``, with
        ``P(face) = area x mean emission / total`` the chance of choosing the face.
        """
        # which faces are seen under more than the threshold depends on p and the face
        # only (never on the sample, which would change the density): the bounding sphere
        # rules out the far ones cheaply, the exact solid angle decides for the rest
        omega = self._solid_angles(p, face)
        rows = np.flatnonzero(omega > SOLID_ANGLE_SAMPLING_FROM)
        if not len(rows):
            return
        v0r, e1r, e2r = self._corner_and_edges(face[rows])
        origin = take_rows(p, rows)
        a, bb, c = (normalize(x) for x in (v0r - origin, v0r + e1r - origin, v0r + e2r - origin))
        w, omega = square_to_spherical_triangle(take_rows(square, rows), a, bb, c)
        n = take_rows(self.normals, face[rows])
        cos = dot(w, n)
        # where the direction meets the face's plane (inside the face up to rounding)
        t = dot(v0r - origin, n) / np.where(cos != 0.0, cos, np.inf)
        y = origin + t[:, None] * w
        # barycentrics of y, for textured emission: least squares on the two edges
        rel = y - v0r
        d00, d01, d11 = dot(e1r, e1r), dot(e1r, e2r), dot(e2r, e2r)
        d20, d21 = dot(rel, e1r), dot(rel, e2r)
        det = d00 * d11 - d01 * d01
        b1 = np.clip((d11 * d20 - d01 * d21) / det, 0.0, 1.0)
        b2 = np.clip((d00 * d21 - d01 * d20) / det, 0.0, 1.0 - b1)
        chance = self._power[face[rows]] / self._total
        # a direction in the face's plane (cos 0: a point in that plane, e.g. on the face
        # itself) gives no solid-angle sample: inf, not 0 / 0, and the area sample is kept
        inverse = np.divide(omega * t * t, chance * np.abs(cos), out=np.full(len(cos), np.inf),
                            where=cos != 0.0)
        ok = np.isfinite(inverse) & (t > 0.0)  # else keep the area sample (a face seen edge-on)
        rows, y, b1, b2, inverse = rows[ok], y[ok], b1[ok], b2[ok], inverse[ok]
        points[rows] = y
        b[rows, 0], b[rows, 1] = b1, b2
        inverse_pdf[rows] = inverse


def emissive_mesh_light(triangles, normals, emission, tint=None, mean_tint=None):
    """All emissive triangles of a scene as one :class:`MeshLight`, or None if there are none.

    One light, not one per object: each hit then sends ``light_samples`` shadow rays to
    emissive geometry however many objects emit, and the power-proportional choice of
    triangle shares them out between the emitters as a power-based light sampler would
    (a lamp twice as bright gets twice the samples).  A scene with many dim emissive parts
    costs no more than one with a single lamp.

    Parameters
    ----------
    triangles : (F, 9) float
        :attr:`rtmesh.geometry.accel.Accel.triangles`.
    normals : (F, 3) float
        Unit face normals.
    emission : (F, 3) float
        Emitted radiance of each face (its material's emission).
    tint : callable, optional
        ``tint(prim, u, v)`` -> (k, 3) multipliers of the emission at points of the scene's
        faces ``prim`` (emission textures); see :class:`MeshLight`.
    mean_tint : (F, 3) float, optional
        Each face's average tint (required with ``tint``).

    Returns
    -------
    MeshLight or None
    """
    faces = np.flatnonzero((emission > 0.0).any(axis=1))
    if tint is not None:
        faces = faces[(emission[faces] * mean_tint[faces] > 0.0).any(axis=1)]  # all-black maps emit nothing
    if not len(faces):
        return None
    light_tint = None if tint is None else (lambda face, u, v: tint(faces[face], u, v))
    scene_faces = np.full(len(emission), -1, dtype=np.intp)
    scene_faces[faces] = np.arange(len(faces))
    return MeshLight(take_rows(triangles, faces), normals[faces], emission[faces], "emissive surfaces",
                     light_tint, None if tint is None else mean_tint[faces], scene_faces)


@kernel
def choose_area_samples(u0, u1, total, cdf, power, guide, triangles_t):
    """Points on an emissive mesh's faces, each face chosen in proportion to its power, on
    the face uniform by area.

    The first number picks the face and is rescaled to [0, 1) within the face's share of
    the CDF, so one pair of numbers does both and stratification carries over.

    Parameters
    ----------
    u0, u1 : (k,) float64
        Points in [0, 1)^2.
    total : float
        The last entry of ``cdf``.
    cdf, power : (F,) float64
        Cumulative and per-face power.
    guide : (F,) int64
        For each of F equal parts of [0, total), the index ``np.searchsorted(cdf, left
        end, side="right")``: where the search for a value in that part may start.
    triangles_t : (9, F) float64
        The faces ``[v0, v1 - v0, v2 - v0]`` by component.

    Returns
    -------
    face : (k,) int64
        ``min(np.searchsorted(cdf, u0 * total, side="right"), F - 1)``.
    square_t : (2, k) float64
        The rescaled first number and ``u1``.
    b_t : (2, k) float64
        Barycentric weights of vertices 1 and 2
        (:func:`rtmesh.sampling.warps.square_to_uniform_triangle`).
    points_t : (3, k) float64
        The points (:func:`rtmesh.geometry.accel.barycentric_interpolate`: ``(e1 b1 + v0) + e2 b2``).

    Notes
    -----
    The search starts from the guide's entry and gallops forward, then halves the
    interval: about one step for faces of similar power (NumPy's binary search over every
    face took half of an emissive mesh's sampling time), never more than twice a binary
    search's for any spread of powers.
    """
    k, faces = len(u0), len(cdf)
    below_one = np.nextafter(1.0, 0.0)
    cells_per_power = faces / total
    face = np.empty(k, np.int64)
    square_t, b_t, points_t = np.empty((2, k)), np.empty((2, k)), np.empty((3, k))
    for i in range(k):
        x = u0[i] * total
        # one cell before the one x falls in, so that rounding of the cell index cannot
        # start past the answer; the check after it makes that certain
        cell = min(max(int(x * cells_per_power), 1), faces) - 1
        lo = guide[cell]
        if lo > 0 and cdf[lo - 1] > x:
            lo = 0
        # every entry before lo is <= x; gallop until an entry is > x, then halve
        hi, step = lo, 1
        while hi < faces and cdf[hi] <= x:
            lo = hi + 1
            hi += step
            step *= 2
        hi = min(hi, faces)
        while lo < hi:
            middle = (lo + hi) >> 1
            if cdf[middle] <= x:
                lo = middle + 1
            else:
                hi = middle
        f = min(lo, faces - 1)
        remapped = (x - (cdf[f] - power[f])) / power[f]
        # as np.clip: NaN stays NaN
        remapped = 0.0 if remapped < 0.0 else remapped
        remapped = below_one if remapped > below_one else remapped
        b1, b2 = uniform_triangle_weights(remapped, u1[i])
        face[i] = f
        square_t[0, i], square_t[1, i] = remapped, u1[i]
        b_t[0, i], b_t[1, i] = b1, b2
        for c in range(3):
            points_t[c, i] = (triangles_t[3 + c, f] * b1 + triangles_t[c, f]) + triangles_t[6 + c, f] * b2
    return face, square_t, b_t, points_t
