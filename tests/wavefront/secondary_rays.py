"""The secondary-ray stage: mirror, glossy and refracted rays leaving a depth level's hits.

The materials say where the rays go and with what weight
(:class:`rtmesh.materials.specular.SpecularScattering`); this stage adds what belongs to the
render: the media on either side of a refracting surface (from the ray's medium stack,
:mod:`rtmesh.rendering.media`), the sampler's glossy dimensions, the origin offsets, and the
settings' ``cutoff`` below which a ray's throughput is not worth following.
"""

import numpy as np

from rtmesh.core.rays import RayBatch
from rtmesh.geometry.accel import offset_ray_origins
from rtmesh.materials.specular import SpecularScattering
from rtmesh.rendering.chunk_state import Stage


class SecondaryRays(Stage):
    """Reflection and refraction rays for one integrator's scene."""

    def __init__(self, integrator):
        super().__init__(integrator)
        self.scattering = SpecularScattering(integrator.scene.materials, integrator.settings.fresnel)

    def spawn(self, srf, rays, depth, chunk):
        """Mirror (or glossy) reflection and refraction rays with their throughput weights."""
        it = self.it
        scattering = self.scattering
        reflective = scattering.reflective[srf.mat]
        if not reflective.any():
            return RayBatch.empty()
        idx = np.flatnonzero(reflective)
        mat = srf.mat[idx]
        wo, ng, ns = -srf.d[idx], srf.ng[idx], srf.ns[idx]
        beta = rays.throughput[idx]
        cutoff = it.settings.cutoff

        def follow(rows, weight):
            """Rays whose throughput stays at or above the cutoff."""
            return ((beta if rows is None else beta[rows]) * weight).max(axis=1) >= cutoff

        refracting = beyond = None
        if it.plan.refraction:
            j = np.flatnonzero(scattering.transmissive[mat])
            if len(j):
                # the index ratio and the media beyond come from the ray's medium stack
                eta, beyond = it.media.cross(rays.medium[idx[j]], srf.prim[idx[j]], srf.front[idx[j]])
                refracting = (j, eta)
        glossy_points = self._glossy_points(srf.sample.take(idx), depth, chunk) if it.plan.glossy else None
        mirror_tint = None
        if srf.tints is not None and srf.tints.mirror is not None:
            mirror_tint = srf.tints.mirror[idx]
        reflection, refraction = scattering.sample(wo, ns, ng, mat, mirror_tint, refracting, follow, glossy_points)

        batches = []
        if len(reflection.rows):
            r = reflection.rows
            batches.append(RayBatch(
                offset_ray_origins(srf.p[idx[r]], ng[r], scale=it.offset_scale, directions=reflection.directions),
                reflection.directions,
                rays.sample[idx[r]],
                beta[r] * reflection.weight,
                rays.medium[idx[r]],
            ))
            chunk.stats.rays["reflection"] += len(r)
        if refraction is not None and len(refraction.rows):
            r = refraction.rows
            batches.append(RayBatch(
                offset_ray_origins(srf.p[idx[r]], -ng[r], scale=it.offset_scale, directions=refraction.directions),
                refraction.directions,
                rays.sample[idx[r]],
                beta[r] * refraction.weight,
                beyond[refraction.kept],
            ))
            chunk.stats.rays["refraction"] += len(r)
        return RayBatch.concatenate(batches)

    def _glossy_points(self, sample, depth, chunk):
        """``points(rows) -> (r, 2)``: the sampler's glossy points of depth ``depth`` for the
        hits ``rows``, whose samples (rows of the chunk) are ``sample[rows]``."""
        pixel, sample_in_pixel = chunk.keys
        sampler = self.it.sampler

        def points(rows):
            key_rows = sample.take(rows)
            return sampler.glossy(pixel.take(key_rows), sample_in_pixel.take(key_rows), depth)

        return points
