"""The physically based stage: hits on glTF metallic-roughness materials, lit by every light
and path traced.

Hits whose material has the ``metallic_roughness`` model
(:class:`rtmesh.materials.table.Material`) are shaded here with the glTF 2.0 BRDF of
:mod:`rtmesh.materials.metallic_roughness`, per texel:

- **Parameters.** ``base = base_color x base-colour texel x vertex colour``,
  ``metallic`` and ``roughness`` their factors times the metallic-roughness texture's blue
  and green channels (:meth:`rtmesh.rendering.surface_textures.SurfaceTextures.metallic_roughness`),
  ``alpha = roughness^2``.  The shading normal is the (normal-mapped) one of the surface
  stage.
- **Light sampling** (next-event estimation). Point-like lights: one shadow ray per
  (hit, light), ``f cos E``.  Area lights (quads, disks, emissive meshes): the
  :class:`rtmesh.lights.area_lighting.AreaLighting` estimator with ``f cos`` as its
  reflectance.  The environment (a background with ``lighting`` on): the
  :class:`rtmesh.lights.environment.EnvironmentLighting` estimator.  Area-light and
  environment samples are weighted for multiple importance sampling (below).
- **BSDF sampling.** Each hit above the last depth sends one ray drawn from the BRDF
  (GGX visible normals for the specular lobe, cosine for the diffuse one); its throughput
  is multiplied by ``f cos / pdf`` and it carries ``pdf`` (:attr:`rtmesh.core.rays.RayBatch.pdf`),
  so light reaching it later (the background where it leaves the scene, other surfaces'
  direct light where it hits) is weighed against light sampling.  This makes
  metallic-roughness surfaces a path tracer: they reflect each other and every other
  surface, up to the settings' ``max_depth``.

Multiple importance sampling
----------------------------
An area light or the environment is reached by two strategies: ``N = light_samples``
directions drawn by the light (solid-angle density ``p_l``: the environment's, or an area
light's area density turned to solid angle, ``d^2 / (|cos_l| A)``, or ``1 / omega`` for the
emissive triangles sampled in solid angle) and one direction drawn from the BRDF (``p_b``).
Each contribution is weighted by Veach's power heuristic (with the sample counts)::

    w_l(w) = (N p_l)^2 / ((N p_l)^2 + p_b^2)       w_b(w) = p_b^2 / ((N p_l)^2 + p_b^2)

:func:`bsdf_weight` is ``w_b``; ``w_l = 1 - w_b`` (1 at the last depth, where no
BSDF-sampled ray follows).  Light samples are weighted here (their
reflectance callback receives ``p_l``); a BSDF-sampled ray is weighted where it meets the
light: by the integrator where it leaves the scene (the environment) or ends on a quad or
disk light (:meth:`rtmesh.lights.area_lighting.AreaLighting.pdf_of_visible`), by the local
shading stage where it hits an emissive triangle
(:meth:`~rtmesh.lights.area_lighting.AreaLighting.pdf_of_emitters`).  The weights sum to 1
for every direction, so the estimate is unbiased whatever the roughness, while glossy
reflections of small bright lights come mostly from BSDF samples and diffuse light mostly
from light samples.  Rays of delta lobes (mirrors, smooth glass) carry an infinite density:
weight 1, as no light sampling could have produced them.

A background whose ``lighting`` is off lights no metallic-roughness surface: their
BSDF-sampled rays that leave the scene see black (the background is then only seen: by
camera rays and through the mirrors and glass of Blinn-Phong materials).
"""

import numpy as np

from rtmesh.core.rays import RayBatch, take_rows
from rtmesh.core.vecmath import dot
from rtmesh.geometry.accel import offset_ray_origins
from rtmesh.materials import metallic_roughness as brdf
from rtmesh.rendering.chunk_state import Stage, add_rows_or_all, rows_at
from rtmesh.shading.direct_light import SHADOW_SHORTEN


def bsdf_weight(bsdf_pdf, light_pdf, samples):
    """Power-heuristic weight of BSDF-sampled directions against light sampling.

    Parameters
    ----------
    bsdf_pdf : (k,) float
        Solid-angle density of the BSDF sample; ``inf`` for a delta lobe (weight 1).
    light_pdf : (k,) float
        The light's solid-angle density of the same directions (``inf`` at an environment's
        pole; 0 where light sampling cannot reach them: weight 1).
    samples : int
        Light samples per hit, ``N``.

    Returns
    -------
    (k,) float64
        ``p_b^2 / (p_b^2 + (N p_l)^2)``.
    """
    light = samples * light_pdf
    # rows with a zero or infinite density on either side are settled by the wheres
    ordinary = np.isfinite(bsdf_pdf) & (bsdf_pdf > 0.0) & np.isfinite(light)
    with np.errstate(over="ignore"):  # a ratio beyond float64 is inf, and its weight 0
        ratio = np.minimum(light / np.where(ordinary, bsdf_pdf, 1.0), 1e150)  # no overflow in the square
    w = 1.0 / (1.0 + np.where(ordinary, ratio, 0.0) ** 2)
    return np.where(ordinary, w, np.where(np.isinf(bsdf_pdf), 1.0, 0.0))


class PhysicalShading(Stage):
    """Direct light and BSDF-sampled rays of metallic-roughness hits (see the module notes)."""

    def __init__(self, integrator):
        super().__init__(integrator)
        m = integrator.scene.materials
        self.physical = m.physical
        self.base_color = m.base_color
        self.metallic = m.metallic
        self.roughness = m.perceptual_roughness
        self.transmission = m.transmission_factor

    def hits(self, srf):
        """``(rows, (wo, ns, base, metallic, alpha, transmission))`` of a depth level's
        metallic-roughness hits (see the module notes); ``rows`` empty (and no parameters)
        when there are none.  Formed once per depth level and kept on ``srf`` for the
        bounce after the direct light."""
        if srf.physical is None:
            rows = np.flatnonzero(self.physical[srf.mat])
            srf.physical = (rows, self._parameters(srf, rows) if len(rows) else None)
        return srf.physical

    def _parameters(self, srf, rows):
        """The BRDF parameters of the hits ``rows``."""
        mat = srf.mat[rows]
        base = self.base_color[mat]
        metallic = self.metallic[mat]
        roughness = self.roughness[mat]
        tints = srf.tints
        if tints is not None:
            if tints.diffuse is not None:
                base = base * take_rows(tints.diffuse, rows)
            if tints.metallic_roughness is not None:
                factors = take_rows(tints.metallic_roughness, rows)
                roughness = roughness * factors[:, 0]
                metallic = metallic * factors[:, 1]
        wo = -take_rows(srf.d, rows)
        ns = take_rows(srf.ns, rows)
        return (wo, ns, base, np.clip(metallic, 0.0, 1.0), brdf.alpha_from_roughness(np.clip(roughness, 0.0, 1.0)),
                self.transmission[mat])

    def direct(self, srf, depth, chunk):
        """Light reaching the metallic-roughness hits directly, toward the viewer.

        Returns
        -------
        (k, 3) float64 or None
            Per hit of ``srf`` (zero on the other hits); None when there are no
            metallic-roughness hits or no light reached them.
        """
        it = self.it
        rows, parameters = self.hits(srf)
        if not len(rows):
            return None
        wo, ns, base, metallic, alpha, transmission = parameters
        p, ng = take_rows(srf.p, rows), take_rows(srf.ng, rows)
        time = rows_at(srf.time, rows)
        total = None
        for light in it.lights if it.plan.lights else ():
            wi, distance, incident = light.illuminate(p)
            lit = np.flatnonzero((dot(wi, ng) > 0.0) & (incident > 0.0).any(axis=1))
            if not len(lit):
                continue
            directions = take_rows(wi, lit)
            origins = offset_ray_origins(take_rows(p, lit), take_rows(ng, lit), np.float32, it.offset_scale,
                                         directions)
            chunk.clock.lap("shade")
            occluded = it.accel.occluded(origins, directions, distance[lit] * SHADOW_SHORTEN,
                                         time=rows_at(time, lit))
            chunk.stats.rays["shadow"] += len(lit)
            chunk.clock.lap("shadow")
            seen = lit[~occluded]
            if not len(seen):
                continue
            value = brdf.evaluate(take_rows(wo, seen), take_rows(ns, seen), take_rows(wi, seen), base[seen],
                                  metallic[seen], alpha[seen], transmission[seen]) * take_rows(incident, seen)
            if total is None:
                total = np.zeros((len(rows), 3))
            total[seen] += value

        pixel, sample_in_pixel = chunk.keys
        sample = srf.sample[rows]
        environment = it.environment_lighting if it.plan.environment_lighting else None
        area = it.area_lighting if it.plan.area_lights else None
        # at the last depth no BSDF-sampled ray follows: light sampling is the only strategy
        # and takes the whole weight
        bounces = depth < it.settings.max_depth
        for lighting in (area, environment):
            if lighting is None:
                continue

            def reflectance(wi, lit, light_pdf, samples=lighting.samples):
                """``f cos`` toward ``wi`` times the light sample's MIS weight; 0 off ``lit``."""
                if not bounces:
                    value = brdf.evaluate(wo, ns, wi, base, metallic, alpha, transmission)
                else:
                    value, bsdf_pdf = brdf.evaluate_and_pdf(wo, ns, wi, base, metallic, alpha, transmission)
                    value *= (1.0 - bsdf_weight(bsdf_pdf, light_pdf, samples))[:, None]
                value[~lit] = 0.0
                return value

            light = lighting.direct(p, ng, reflectance, pixel[sample], sample_in_pixel[sample], depth,
                                    chunk.stats, chunk.clock, time)
            if light is not None:
                total = light if total is None else total + light
        if total is None:
            return None
        return add_rows_or_all(np.zeros((len(srf.mat), 3), order="F"), rows, total)

    def spawn(self, srf, rays, depth, chunk):
        """One BSDF-sampled ray per metallic-roughness hit (see the module notes).

        Parameters
        ----------
        srf : SurfaceRecords
        rays : RayBatch
            The rays that made the hits (row for row with ``srf``).
        depth : int
        chunk : ChunkState

        Returns
        -------
        RayBatch
            With ``pdf`` set; rays whose sample fell below the geometric surface or whose
            weight is 0 are dropped.
        """
        it = self.it
        rows, parameters = self.hits(srf)
        if not len(rows):
            return RayBatch.empty()
        wo, ns, base, metallic, alpha, transmission = parameters
        pixel, sample_in_pixel = chunk.keys
        sample = srf.sample[rows]
        u = it.sampler.bsdf(pixel[sample], sample_in_pixel[sample], depth)
        wi, weight, pdf = brdf.sample(wo, ns, u, base, metallic, alpha, transmission)
        ng = take_rows(srf.ng, rows)
        # a direction above the shading normal but below the geometric one would enter the
        # surface: that sample is lost (the usual shading-normal energy loss)
        beta = take_rows(rays.throughput, rows) * weight
        kept = np.flatnonzero((pdf > 0.0) & (dot(wi, ng) > 0.0) & (beta > 0.0).any(axis=1))
        if not len(kept):
            return RayBatch.empty()
        directions = take_rows(wi, kept)
        hits = rows[kept]
        chunk.stats.rays["bsdf"] += len(kept)
        return RayBatch(offset_ray_origins(take_rows(srf.p, hits), take_rows(ng, kept), scale=it.offset_scale,
                                           directions=directions),
                        directions, take_rows(rays.sample, hits), take_rows(beta, kept),
                        take_rows(rays.medium, hits), pdf[kept])
