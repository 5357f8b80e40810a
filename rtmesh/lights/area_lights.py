"""Area lights: quads and disks (emissive meshes are in :mod:`rtmesh.lights.mesh_lights`, the
soft shadows they all cast in :mod:`rtmesh.lights.area_lighting`).

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

Visibility
----------
Quad and disk lights are not Embree geometry: like the area lamps of Blender's Cycles they
cast no shadows and do not block ambient occlusion.  Unless ``visible`` is false, camera,
reflection and refraction rays that meet one from its emitting side before any surface
end there and see ``L`` (:meth:`rtmesh.lights.area_lighting.AreaLighting.intersect`), so a light shows in the image and
in mirrors; from behind it is invisible.  Emissive meshes are ordinary geometry: they are
seen, occlude and cast shadows like any surface.
"""

from dataclasses import dataclass

import numpy as np

from rtmesh.core.rays import component_major
from rtmesh.core.vecmath import dot, orthonormal_basis
from rtmesh.lights.interface import AreaLight
from rtmesh.lights.light_types import LightType, aim
from rtmesh.materials.table import as_colour
from rtmesh.sampling.warps import square_to_uniform_disk_concentric


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
            two triangles uniformly in solid angle (as :class:`rtmesh.lights.mesh_lights.MeshLight` does) lowered the
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
