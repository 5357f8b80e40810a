"""Area lights (quads, disks, emissive meshes) and the soft shadows they cast.

Emission
--------
An area light emits the radiance ``L`` (per colour channel, W / (sr m^2)) uniformly over its
surface.  Quad and disk lights emit on one side only, the side their normal points to.
Emissive meshes (triangles whose material has an ``emission`` colour) emit on both sides,
because camera rays see their emission from both sides too and mesh winding from files is
not reliable; on a closed mesh the inner side never reaches anything outside anyway.

Consistency with the point lights of :mod:`rtmesh.lights.point_lights`
---------------------------------------------------------
The shading model multiplies a Blinn-Phong factor ``f(wi) = kd cos_s + ks cos_h^n`` (no 1/pi)
by ``E = I / d^2`` for a point light of intensity ``I``.  Split into small patches ``dA``,
an area light is a sum of point lights of intensity ``dI = L cos_l dA`` (a flat Lambertian
emitter seen at ``cos_l`` from its normal), so its direct light is::

    integral over the light of  V(p, y) f(wi) L cos_l / d^2  dA(y)

and a light small against its distance converges to the point light ``I = L A cos_l``.  The
diffuse part is therefore ``kd * E_phys`` with ``E_phys = integral L cos_s dw`` the physical
irradiance (``pi L r^2 / (r^2 + h^2)`` on the axis of a disk of radius ``r`` at height
``h``): ``kd`` acts as the value of the BRDF, so a white surface (kd = 1) under a light
filling its whole hemisphere reflects ``pi L``.  That is the price of Phong's ``kd`` without
the 1/pi, kept so that area and point lights agree.

Estimator
---------
Per (hit, light), ``N = light_samples`` points ``y_j`` are drawn uniformly by area (pdf
``1 / A``; all the emissive triangles of a scene form one light, on which a triangle is
chosen in proportion to its power, area x mean emission, then a point uniformly on it) and
each gets a shadow ray::

    (1 / N) sum_j V(p, y_j) f(wi_j) L(y_j) cos_l,j / (d_j^2 pdf_A(y_j))

Area sampling is unbiased and maps the sampler's strata straight onto equal parts of the
light (a jittered set of N samples puts one in each of N equal cells of a quad), which is
what makes penumbrae smooth at small N.  Its variance grows only for points closer to the
light than the light's own size, where ``1 / d^2`` varies strongly over the light;
solid-angle sampling (Urena et al. 2013 for rectangles) would remove that.

The sample points come from the render's sampler (:meth:`rtmesh.sampling.sampler.Sampler.area_light`,
keyed by seed, pixel, sample, ray and dimension), in dimensions from :attr:`rtmesh.sampling.patterns.Dim.LIGHT` upward:
the ``spp * N`` points a pixel's samples send to one light are one stratified set, and the
``N`` of each hit are stratified among themselves.

Visibility
----------
Quad and disk lights are not Embree geometry: like the area lamps of Blender's Cycles they
cast no shadows and do not block ambient occlusion.  Unless ``visible`` is false, camera,
reflection and refraction rays that meet one from its emitting side before any surface
end there and see ``L`` (:meth:`AreaLighting.intersect`), so a light shows in the image and
in mirrors; from behind it is invisible.  Emissive meshes are ordinary geometry: they are
seen, occlude and cast shadows like any surface.
"""

from dataclasses import dataclass

import numpy as np

from rtmesh.core.rays import component_major, take_rows
from rtmesh.core.vecmath import dot, normalize, orthonormal_basis
from rtmesh.geometry.accel import barycentric_interpolate, offset_ray_origins
from rtmesh.lights.interface import AreaLight
from rtmesh.lights.light_types import LightType, aim
from rtmesh.materials.table import as_colour
from rtmesh.sampling.sampler import Sampler
from rtmesh.sampling.warps import (spherical_triangle_area, square_to_spherical_triangle,
                                   square_to_uniform_disk_concentric, square_to_uniform_triangle)

# Rays meeting a visible light and a surface at the same distance (a light placed flush on a
# ceiling) see the light: Embree's float32 distance to the surface carries a relative error
# of a few 1e-7, so the light wins within this relative margin.
_FLUSH_MARGIN = 1.0 + 1e-5
# Emissive triangles seen under more than this solid angle (sr) are sampled uniformly in it
# (see MeshLight.sample); smaller ones by area.  Arvo's angle sums keep ~10 digits at 1e-3 sr.
SOLID_ANGLE_SAMPLING_FROM = 1e-3


def _area_pdf_to_solid_angle(area, normal, directions, t):
    """Solid-angle density of points drawn uniformly by area on a flat light of ``area`` and
    unit ``normal``, toward unit ``directions`` that meet it at distances ``t``, (k,):
    ``t^2 / (|cos_l| area)``; ``inf`` for a direction in the light's plane."""
    cos = np.abs(directions @ normal)
    return np.divide(t * t, cos * area, out=np.full(len(cos), np.inf), where=cos > 0.0)


def _vec3(value, name):
    v = np.asarray(value, dtype=np.float64).reshape(3)
    if not np.isfinite(v).all():
        raise ValueError(f"{name} must be finite")
    return v


@dataclass
class QuadLight:
    """A one-sided parallelogram light (a rectangle when the edges are orthogonal).

    Attributes
    ----------
    position : (3,) float
        Centre.
    edge1, edge2 : (3,) float
        Full edge vectors; the light emits toward ``normal = edge1 x edge2`` (right-hand rule).
    radiance : (3,) float
        Emitted radiance, W / (sr m^2) per channel.
    visible : bool
        Whether camera, reflection and refraction rays see the light.
    """

    position: np.ndarray
    edge1: np.ndarray
    edge2: np.ndarray
    radiance: np.ndarray
    visible: bool = True

    two_sided = False

    def __post_init__(self):
        self.position = _vec3(self.position, "quad light position")
        self.edge1 = _vec3(self.edge1, "quad light edge1")
        self.edge2 = _vec3(self.edge2, "quad light edge2")
        self.radiance = as_colour(self.radiance)
        cross = np.cross(self.edge1, self.edge2)
        area = float(np.linalg.norm(cross))
        if not area > 0.0:
            raise ValueError("quad light edges are zero or parallel")
        self.area = area
        self.normal = cross / area
        self.corner = self.position - 0.5 * (self.edge1 + self.edge2)
        # dual basis: (p - corner) . dual_k is p's coordinate along edge_k, in [0, 1] on the light
        self._dual1 = np.cross(self.edge2, cross) / (area * area)
        self._dual2 = np.cross(cross, self.edge1) / (area * area)

    @property
    def is_black(self):
        return not (self.radiance > 0).any()

    def sample(self, u, p=None):
        """Points spread uniformly over the light.

        Parameters
        ----------
        u : (k, 2) float
            Points in [0, 1)^2; ``u`` maps linearly onto the parallelogram, so strata of the
            square are equal parts of the light.
        p : (k, 3) float, optional
            The points being lit (not used: the light is sampled by area).  Sampling its
            two triangles uniformly in solid angle (as :class:`MeshLight` does) lowered the
            error at 4-64 samples but slowed Sobol's convergence across shadow edges
            (RMSE slope -0.75 instead of -1); a spherical-rectangle warp would keep it.

        Returns
        -------
        points : (k, 3) float
            Component-major.
        normals : (3,) float
            The light's unit normal (the same for every point).
        radiance : (3,) float
        inverse_pdf : float
            ``1 / pdf`` with respect to area: the area.
        """
        points = component_major(self.corner[:, None] + self.edge1[:, None] * u[:, 0]
                                 + self.edge2[:, None] * u[:, 1])
        return points, self.normal, self.radiance, self.area

    def pdf(self, origins, directions, t):
        """Solid-angle density with which :meth:`sample` reaches the light along unit
        ``directions`` from ``origins`` that meet it at distances ``t``, (k,)."""
        return _area_pdf_to_solid_angle(self.area, self.normal, directions, t)

    def to_square(self, points):
        """Inverse of :meth:`sample`: points in the light's plane to ``u``, (k, 3) -> (k, 2).

        ``u`` is in [0, 1]^2 for points on the light (the coordinates along the two edges,
        from the corner).
        """
        p = points - self.corner
        return np.stack([p @ self._dual1, p @ self._dual2], axis=1)

    def intersect(self, origins, directions):
        """Distance along each ray to the light's emitting side; ``inf`` where it misses.

        Parameters
        ----------
        origins, directions : (n, 3) float

        Returns
        -------
        (n,) float
        """
        cos = directions @ self.normal
        # rays parallel to the plane get t = inf or NaN and fail every test below
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((self.corner - origins) @ self.normal) / cos
            u = self.to_square(origins + directions * t[:, None])
            hit = (cos < 0.0) & (t > 0.0) & ((u >= 0.0) & (u <= 1.0)).all(axis=1)
        return np.where(hit, t, np.inf)


@dataclass
class DiskLight:
    """A one-sided disk light.

    Attributes
    ----------
    position : (3,) float
        Centre.
    normal : (3,) float
        Direction the light emits toward (normalised here).
    radius : float
    radiance : (3,) float
        Emitted radiance, W / (sr m^2) per channel.
    visible : bool
        Whether camera, reflection and refraction rays see the light.
    """

    position: np.ndarray
    normal: np.ndarray
    radius: float
    radiance: np.ndarray
    visible: bool = True

    two_sided = False

    def __post_init__(self):
        self.position = _vec3(self.position, "disk light position")
        n = _vec3(self.normal, "disk light normal")
        length = float(np.linalg.norm(n))
        if not length > 0.0:
            raise ValueError("disk light normal has zero length")
        self.normal = n / length
        if not (np.isfinite(self.radius) and self.radius > 0.0):
            raise ValueError("disk light radius must be > 0")
        self.radius = float(self.radius)
        self.radiance = as_colour(self.radiance)
        self.area = np.pi * self.radius ** 2
        t, b = orthonormal_basis(self.normal[None, :])
        self._tangents = np.stack([t[0], b[0]]) * self.radius  # (2, 3)

    @property
    def is_black(self):
        return not (self.radiance > 0).any()

    def sample(self, u, p=None):
        """Points spread uniformly over the disk; see :meth:`QuadLight.sample`.

        The concentric map keeps the strata of ``u`` compact and of equal area on the disk.
        """
        d = square_to_uniform_disk_concentric(u)
        points = component_major(self.position[:, None] + self._tangents.T @ d.T)
        return points, self.normal, self.radiance, self.area

    def pdf(self, origins, directions, t):
        """See :meth:`QuadLight.pdf`."""
        return _area_pdf_to_solid_angle(self.area, self.normal, directions, t)

    def intersect(self, origins, directions):
        """See :meth:`QuadLight.intersect`."""
        cos = directions @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):  # see QuadLight.intersect
            t = ((self.position - origins) @ self.normal) / cos
            p = origins + directions * t[:, None] - self.position
            hit = (cos < 0.0) & (t > 0.0) & (dot(p, p) <= self.radius ** 2)
        return np.where(hit, t, np.inf)


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
        x = u[:, 0] * self._total
        face = np.minimum(np.searchsorted(self._cdf, x, side="right"), len(self._cdf) - 1)
        start = self._cdf[face] - self._power[face]
        remapped = np.clip((x - start) / self._power[face], 0.0, np.nextafter(1.0, 0.0))
        square = np.stack([remapped, u[:, 1]], axis=1)
        triangles = take_rows(self.triangles, face)
        b = square_to_uniform_triangle(square)
        points = barycentric_interpolate(triangles, b[:, 0], b[:, 1])
        emission = take_rows(self.emission, face)
        inverse_pdf = self._total / self._mean_emission[face]
        if p is not None:
            self._sample_solid_angle(p, square, triangles, face, points, b, inverse_pdf)
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
        omega = self._solid_angles(origins, faces, take_rows(self.triangles, faces))
        wide = omega > SOLID_ANGLE_SAMPLING_FROM
        pdf[wide] = chance[wide] / omega[wide]
        return pdf

    def _solid_angles(self, p, face, triangles):
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
            v0n, e1n, e2n = (take_rows(triangles[:, k:k + 3], near) for k in (0, 3, 6))
            pn = take_rows(p, near)
            unit = [normalize(c) for c in (v0n - pn, v0n + e1n - pn, v0n + e2n - pn)]
            omega[near] = spherical_triangle_area(*unit)
        return omega

    def _sample_solid_angle(self, p, square, triangles, face, points, b, inverse_pdf):
        """Move the samples of faces seen under a large solid angle from ``p`` to points
        uniform in that solid angle; updates ``points``, ``b`` and ``inverse_pdf`` in place.

        The area density of such a point is ``P(face) |cos_l| / (omega d^2)``, with
        ``P(face) = area x mean emission / total`` the chance of choosing the face.
        """
        # which faces are seen under more than the threshold depends on p and the face
        # only (never on the sample, which would change the density): the bounding sphere
        # rules out the far ones cheaply, the exact solid angle decides for the rest
        omega = self._solid_angles(p, face, triangles)
        rows = np.flatnonzero(omega > SOLID_ANGLE_SAMPLING_FROM)
        if not len(rows):
            return
        v0, e1, e2 = triangles[:, 0:3], triangles[:, 3:6], triangles[:, 6:9]
        pr, v0r_, e1r_, e2r_ = take_rows(p, rows), take_rows(v0, rows), take_rows(e1, rows), take_rows(e2, rows)
        a, bb, c = (normalize(x) for x in (v0r_ - pr, v0r_ + e1r_ - pr, v0r_ + e2r_ - pr))
        w, omega = square_to_spherical_triangle(take_rows(square, rows), a, bb, c)
        n = take_rows(self.normals, face[rows])
        origin, e1r, e2r, v0r = take_rows(p, rows), take_rows(e1, rows), take_rows(e2, rows), take_rows(v0, rows)
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


QUAD = LightType("quad", {"position": "vec3", "edge1": "vec3", "edge2": "vec3", "radiance": "colour",
                         "visible": "bool"}, ("position", "edge1", "edge2", "radiance"),
                 lambda v: QuadLight(v["position"], v["edge1"], v["edge2"], v["radiance"], v.get("visible", True)))
DISK = LightType("disk", {"position": "vec3", "direction": "vec3", "look_at": "vec3", "radius": "positive",
                         "radiance": "colour", "visible": "bool"}, ("position", "radius", "radiance"),
                 lambda v: DiskLight(v["position"], aim(v, "disk"), v["radius"], v["radiance"], v.get("visible", True)))


def is_area_light(light):
    """True for the lights this module's stage handles: those of the area-light interface
    (:class:`rtmesh.lights.interface.AreaLight`: sampled, not ``illuminate``-d)."""
    return isinstance(light, AreaLight)


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


class AreaLighting:
    """Soft shadows and camera visibility of a scene's area lights.

    Parameters
    ----------
    lights : list of QuadLight, DiskLight or MeshLight
        In the integrator's (re-centred) frame.
    accel : Accel
        Traces the shadow rays.
    settings : RenderSettings
        ``light_samples``, ``sampler``, ``seed`` and ``spp`` (the size of the sets of pixel
        samples whose light samples are stratified together).
    offset_scale : float
        Scene size for :func:`rtmesh.geometry.accel.offset_ray_origins`.
    """

    def __init__(self, lights, accel, settings, offset_scale):
        self.lights = list(lights)
        self.accel = accel
        self.samples = settings.light_samples
        self.sampler = Sampler.for_settings(settings)
        self.offset_scale = offset_scale
        self.visible = [light for light in self.lights if light.visible]
        # the scene's emissive triangles (one MeshLight, see emissive_mesh_light), if any
        self.emitters = next((light for light in self.lights if getattr(light, "scene_faces", None) is not None),
                             None)

    def direct(self, p, ng, reflectance, pixel, sample, depth, stats, clock, time=None):
        """Direct light from every area light, ``light_samples`` shadow rays per (hit, light).

        Parameters
        ----------
        p : (k, 3) float
            Shading points.
        ng : (k, 3) float
            Unit geometric normals on the side the incoming ray came from: lights behind
            the surface do not light it, and shadow rays leave on that side.
        reflectance : callable
            ``reflectance(wi, lit, pdf) -> (k, 3)``: the material's reflection factor for
            unit directions ``wi`` toward the light, evaluated (at least) where ``lit``;
            ``pdf`` is the solid-angle density of each sample (for MIS weights).
        pixel, sample : (k,) int
            Pixel and sample-in-pixel of each hit: the keys of its random numbers.
        depth : int
            Path depth of the hits (its own sample dimensions).
        stats : RenderStats
            Shadow rays are counted as ``area_shadow``.
        clock : object with ``lap(stage)``
            Times the work as ``shade`` and ``shadow``.
        time : (k,) float, optional
            Time of each hit's ray, with motion blur: the shadow rays see the moving objects
            at that time (``accel`` is then a :class:`rtmesh.geometry.motion.MotionAccel`).

        Returns
        -------
        (k, 3) float64 or None
            None when no sample reached any hit.
        """
        n = self.samples
        total = None
        for light_index, light in enumerate(self.lights):
            for j in range(n):
                u = self.sampler.area_light(pixel, sample, depth, light_index, len(self.lights), j, n)
                contribution = self._one_sample(p, ng, reflectance, light, u, stats, clock, time)
                if contribution is not None:
                    total = contribution if total is None else total + contribution
        if total is not None:
            total *= 1.0 / n
        return total

    def _one_sample(self, p, ng, reflectance, light, u, stats, clock, time=None):
        """One light sample per hit: ``V f L cos_l / (d^2 pdf_A)``, (k, 3) or None."""
        y, n_light, radiance, inverse_pdf = light.sample(u, p)
        to_light = y - p
        distance2 = dot(to_light, to_light)
        distance = np.sqrt(distance2)
        wi = to_light / np.where(distance > 0.0, distance, np.inf)[:, None]
        facing = -(wi @ n_light) if n_light.ndim == 1 else -dot(wi, n_light)
        cos_light = np.abs(facing) if light.two_sided else facing
        lit = (cos_light > 0.0) & (dot(wi, ng) > 0.0)
        rows = np.flatnonzero(lit)
        if not len(rows):
            return None
        # The shadow ray leaves the hit like every spawned ray, and ends just short of the
        # sampled point: the point is moved off the light toward the hit by the same float32
        # ulp offset (the ray run backwards), so an emissive triangle, which is in Embree,
        # cannot occlude its own sample, and a light flush with a ceiling is not hidden by
        # it, even at grazing angles.
        wi_rows = take_rows(wi, rows)
        start = offset_ray_origins(take_rows(p, rows), take_rows(ng, rows), scale=self.offset_scale,
                                   directions=wi_rows)
        toward = np.where(facing > 0.0, 1.0, -1.0)
        n_rows = (n_light[None, :] if n_light.ndim == 1 else take_rows(n_light, rows)) * toward[rows, None]
        target = offset_ray_origins(take_rows(y, rows), n_rows, scale=self.offset_scale,
                                    directions=-wi_rows)
        segment = target - start
        length = np.sqrt(dot(segment, segment))
        direction = segment / np.where(length > 0.0, length, np.inf)[:, None]
        clock.lap("shade")
        if time is None:
            occluded = self.accel.occluded(start, direction, length)
        else:
            occluded = self.accel.occluded(start, direction, length, time=time[rows])
        stats.rays["area_shadow"] += len(rows)
        clock.lap("shadow")
        visible = np.zeros(len(lit), dtype=bool)
        visible[rows[~occluded]] = True
        if not visible.any():
            return None
        weight = np.zeros(len(lit))
        v = np.flatnonzero(visible)
        inv = inverse_pdf if np.ndim(inverse_pdf) == 0 else inverse_pdf[v]
        weight[v] = cos_light[v] * inv / distance2[v]
        # the sample's solid-angle density, for reflectances that weigh it against BSDF sampling
        pdf = np.full(len(lit), np.inf)
        pdf[v] = 1.0 / weight[v]
        value = reflectance(wi, visible, pdf)
        value *= radiance
        value *= weight[:, None]
        return value

    def intersect(self, origins, directions, hits):
        """End rays on the visible quad and disk lights they meet before any surface.

        Parameters
        ----------
        origins, directions : (n, 3) float
        hits : Hits
            Closest surface hits of the rays; rows that meet a light first are changed in
            place to ``t`` = distance to the light and ``prim = -2`` (neither a surface nor
            a miss).

        Returns
        -------
        rows : (m,) intp
            Rays that ended on a light.
        emitted : (m, 3) float
            The radiance each of them sees.
        lights : (m,) intp
            Which light (index into :attr:`visible`) each met.
        """
        nearest = hits.t
        which = None
        for index, light in enumerate(self.visible):
            t = light.intersect(origins, directions)
            closer = (t < np.inf) & (t <= nearest * _FLUSH_MARGIN)
            if closer.any():
                nearest = np.where(closer, t, nearest)
                which = np.where(closer, index, -1 if which is None else which)
        if which is None:
            return np.zeros(0, dtype=np.intp), np.zeros((0, 3)), np.zeros(0, dtype=np.intp)
        rows = np.flatnonzero(which >= 0)
        hits.t = nearest
        hits.prim = np.where(which >= 0, -2, hits.prim).astype(hits.prim.dtype)
        radiance = np.stack([light.radiance for light in self.visible])
        return rows, radiance[which[rows]], which[rows]

    def pdf_of_visible(self, lights, origins, directions, t):
        """Solid-angle density of light sampling toward points on the visible lights that
        rays met (:meth:`intersect`), (m,): each light's :meth:`QuadLight.pdf`."""
        pdf = np.empty(len(lights))
        for index in np.unique(lights):
            rows = np.flatnonzero(lights == index)
            pdf[rows] = self.visible[index].pdf(origins[rows], directions[rows], t[rows])
        return pdf

    def pdf_of_emitters(self, origins, prim, points):
        """Solid-angle density of light sampling toward ``points`` on the emissive scene
        triangles ``prim``, from ``origins``, (k,) (0 for triangles that are not emitters)."""
        pdf = np.zeros(len(prim))
        if self.emitters is None:
            return pdf
        faces = self.emitters.scene_faces[prim]
        rows = np.flatnonzero(faces >= 0)
        if len(rows):
            pdf[rows] = self.emitters.pdf(take_rows(origins, rows), faces[rows], take_rows(points, rows))
        return pdf
