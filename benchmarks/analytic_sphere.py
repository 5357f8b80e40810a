"""An exact renderer for one sphere, independent of rtmesh's mesh path.

It renders what rtmesh renders for a scene holding a single sphere (Blinn-Phong with point
lights and hard shadows, mirror reflection, a smooth dielectric with Fresnel, total internal
reflection and Beer absorption, a constant background), but intersects the true sphere in
closed form and uses its exact normal.  Comparing an icosphere rendered by rtmesh with this
image measures the tessellation error alone; the speed-versus-error study and the tests use it.

Only the pixel centres are traced (compare with rtmesh's ``sampler="regular", spp=1``).
"""

from dataclasses import dataclass

import numpy as np

from rtmesh.core.vecmath import dot, fresnel_dielectric, fresnel_schlick, normalize, reflect, refract
from rtmesh.materials.blinn_phong import blinn_phong
from rtmesh.materials.table import Material


@dataclass
class AnalyticSphere:
    """A sphere, its material and the light around it.

    Attributes
    ----------
    centre : (3,) float
    radius : float
    material : Material
    lights : list of PointLight or DirectionalLight
    ambient : (3,) float
    background : (3,) float
    """

    centre: np.ndarray
    radius: float
    material: Material
    lights: list
    ambient: np.ndarray
    background: np.ndarray


def intersect_sphere(origins, directions, centre, radius):
    """Nearest positive hit distance of unit-direction rays with a sphere.

    Parameters
    ----------
    origins, directions : (n, 3) float
    centre : (3,) float
    radius : float

    Returns
    -------
    (n,) float
        Distance to the nearest intersection in front of the origin; ``inf`` for misses.

    Notes
    -----
    Uses the numerically stable form of the quadratic (no cancellation between ``-b`` and
    the square root): ``q = -(b + sign(b) sqrt(disc))``, roots ``q`` and ``c / q``.
    """
    oc = origins - centre
    b = dot(oc, directions)
    c = dot(oc, oc) - radius * radius
    disc = b * b - c
    hit = disc >= 0.0
    root = np.sqrt(np.where(hit, disc, 0.0))
    q = -(b + np.where(b >= 0.0, root, -root))
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = q, c / q
    near, far = np.minimum(t0, t1), np.maximum(t0, t1)
    # a tiny relative epsilon skips the surface a secondary ray starts on
    eps = 1e-9 * max(radius, 1.0)
    t = np.where(near > eps, near, np.where(far > eps, far, np.inf))
    return np.where(hit, t, np.inf)


def render_analytic(sphere, origins, directions, max_depth=5, fresnel="schlick", cutoff=1e-3):
    """Radiance along each camera ray for a scene holding only ``sphere``.

    Parameters
    ----------
    sphere : AnalyticSphere
    origins, directions : (n, 3) float
        Camera rays (unit directions).
    max_depth : int
        Reflection/refraction bounces after the camera ray, as in rtmesh.
    fresnel : {"schlick", "exact"}
    cutoff : float
        Paths whose largest throughput channel falls below this stop, as in rtmesh.

    Returns
    -------
    (n, 3) float
    """
    m = sphere.material
    fresnel_fn = fresnel_dielectric if fresnel == "exact" else fresnel_schlick
    n = len(origins)
    radiance = np.zeros((n, 3))
    index = np.arange(n)
    throughput = np.ones((n, 3))
    inside = np.zeros(n, dtype=bool)
    for depth in range(max_depth + 1):
        if not len(index):
            break
        t = intersect_sphere(origins, directions, sphere.centre, sphere.radius)
        hit = np.isfinite(t)
        # Beer absorption over the distance travelled inside
        if inside.any():
            sigma = m.absorption[None, :]
            att = np.where(sigma > 0, np.exp(-sigma * np.where(hit, t, np.inf)[:, None]), 1.0)
            throughput = np.where(inside[:, None], throughput * att, throughput)
        np.add.at(radiance, index[~hit], throughput[~hit] * sphere.background)
        origins, directions, throughput, index, inside, t = (
            a[hit] for a in (origins, directions, throughput, index, inside, t))
        p = origins + t[:, None] * directions
        outward = (p - sphere.centre) / sphere.radius
        front = dot(directions, outward) < 0.0
        normal = np.where(front[:, None], outward, -outward)
        wo = -directions

        # local shading: ambient + lights with hard shadows.  Seen from outside, a convex
        # sphere shadows a point only where n.wi <= 0; seen from inside, the sphere itself
        # blocks every light (rtmesh's shadow rays hit the glass), so inside hits are unlit.
        local = m.emission + m.ambient * sphere.ambient + np.zeros((len(t), 3))
        for light in sphere.lights:
            wi, distance, incident = light.illuminate(p)
            lit = front & (dot(wi, normal) > 0.0)
            shade = blinn_phong(normal, wo, wi, np.broadcast_to(m.diffuse, (len(t), 3)),
                                np.broadcast_to(m.specular, (len(t), 3)), np.full(len(t), m.shininess))
            local += np.where(lit[:, None], shade * incident, 0.0)
        np.add.at(radiance, index, throughput * local)
        if depth == max_depth:
            break

        # spawn: mirror + Fresnel reflection, refraction
        reflect_weight = np.broadcast_to(m.mirror, (len(t), 3)).copy()
        new = []
        if (m.transmission > 0).any():
            eta = np.where(front, 1.0 / m.ior, m.ior)
            cos_i = np.clip(dot(wo, normal), 0.0, 1.0)
            f = fresnel_fn(cos_i, eta)
            wt, tir = refract(wo, normal, eta)
            reflect_weight += np.where(tir, 1.0, f)[:, None] * m.transmission
            beta_t = throughput * (1.0 - f)[:, None] * m.transmission
            keep = ~tir & (beta_t.max(axis=1) >= cutoff)
            new.append((p[keep], wt[keep], beta_t[keep], index[keep], front[keep]))
        beta_r = throughput * reflect_weight
        keep = beta_r.max(axis=1) >= cutoff
        new.append((p[keep], reflect(wo, normal)[keep], beta_r[keep], index[keep], inside[keep]))
        origins, directions, throughput, index, inside = (np.concatenate(x) for x in zip(*new))
        directions = normalize(directions)
    return radiance


def render_analytic_image(sphere, camera, width, height, **options):
    """Render the pixel centres of a ``width`` x ``height`` image.

    Returns
    -------
    (height, width, 3) float32
    """
    ys, xs = np.mgrid[0:height, 0:width]
    film = np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], axis=1).astype(np.float64)
    origins, directions = camera.generate_rays(film, width, height)
    return render_analytic(sphere, origins, directions, **options).reshape(height, width, 3).astype(np.float32)
