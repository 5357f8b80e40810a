"""The secondary-ray stage: mirror, glossy and refracted rays leaving a depth level's hits.

Smooth dielectrics split into a reflected and a refracted ray weighted by Fresnel (total
internal reflection sends everything into the reflection), with the media beyond taken from
the ray's medium stack (:mod:`rtmesh.rendering.media`); rough materials sample their
reflection in a lobe around the mirror direction (:mod:`rtmesh.materials.glossy`).  Rays
whose throughput falls below the settings' ``cutoff`` are not spawned.
"""

import numpy as np

from rtmesh.core.rays import RayBatch, take_rows
from rtmesh.core.vecmath import dot, fresnel_dielectric, fresnel_schlick, reflect, refract
from rtmesh.geometry.accel import offset_ray_origins
from rtmesh.materials.glossy import sample_glossy_directions


def fresnel_exact_or_schlick(mode):
    """The Fresnel function for a ``fresnel`` setting."""
    return fresnel_dielectric if mode == "exact" else fresnel_schlick


class SecondaryRays:
    """Reflection and refraction rays for one integrator's scene.

    Parameters
    ----------
    integrator : rtmesh.rendering.integrator.Integrator
        After its tables are formed; the stage reads them.
    """

    def __init__(self, integrator):
        self.it = integrator
        self.fresnel = fresnel_exact_or_schlick(integrator.settings.fresnel)

    def spawn(self, srf, rays, depth, chunk):
        """Mirror (or glossy) reflection and refraction rays with their throughput weights."""
        it = self.it
        m = it.scene.materials
        reflective = it._reflective[srf.mat]
        if not reflective.any():
            return RayBatch.empty()
        idx = np.flatnonzero(reflective)
        mat = srf.mat[idx]
        wo, ng, ns = -srf.d[idx], srf.ng[idx], srf.ns[idx]
        beta = rays.throughput[idx]
        reflect_weight = m.mirror[mat]
        if srf.tints is not None and srf.tints.mirror is not None:
            reflect_weight = reflect_weight * srf.tints.mirror[idx]
        batches = []

        refract_batch = None
        if it.plan.refraction:
            trans = it._transmissive[mat]
            j = np.flatnonzero(trans)
            if len(j):
                mat_j = mat[j]
                # the index ratio and the media beyond come from the ray's medium stack
                eta, beyond = it.media.cross(rays.medium[idx[j]], srf.prim[idx[j]],
                                               srf.front[idx[j]])
                cos_i = np.clip(dot(wo[j], ns[j]), 0.0, 1.0)
                fresnel = self.fresnel(cos_i, eta)
                wt, tir = refract(wo[j], ns[j], eta)
                # a shading normal can bend the refracted ray back to the incoming side of
                # the real surface; such rays cannot go through and are dropped
                ok = ~tir & (dot(wt, ng[j]) < 0.0)
                transmission = m.transmission[mat_j]
                reflect_weight = reflect_weight.copy()
                reflect_weight[j] += np.where(tir, 1.0, fresnel)[:, None] * transmission
                w_t = (1.0 - fresnel)[:, None] * transmission
                keep = ok & ((beta[j] * w_t).max(axis=1) >= it.settings.cutoff)
                jk = j[keep]
                if len(jk):
                    refract_batch = RayBatch(
                        offset_ray_origins(srf.p[idx[jk]], -ng[jk], scale=it.offset_scale,
                                           directions=wt[keep]),
                        wt[keep],
                        rays.sample[idx[jk]],
                        beta[jk] * w_t[keep],
                        beyond[keep],
                    )
                    chunk.stats.rays["refraction"] += len(jk)

        beta_r = beta * reflect_weight
        keep = beta_r.max(axis=1) >= it.settings.cutoff
        if keep.any():
            wr = reflect(wo[keep], ns[keep])
            # a shading normal can send the mirror direction under the real surface:
            # fall back to the geometric mirror direction there
            below = dot(wr, ng[keep]) <= 0.0
            if below.any():
                wr[below] = reflect(wo[keep][below], ng[keep][below])
            if it.plan.glossy:
                wr = self.glossy(wr, ng[keep], mat[keep], srf.sample[idx[keep]], depth, chunk.keys)
            batches.append(RayBatch(
                offset_ray_origins(srf.p[idx[keep]], ng[keep], scale=it.offset_scale, directions=wr),
                wr,
                rays.sample[idx[keep]],
                beta_r[keep],
                rays.medium[idx[keep]],
            ))
            chunk.stats.rays["reflection"] += int(keep.sum())
        if refract_batch is not None:
            batches.append(refract_batch)
        return RayBatch.concatenate(batches)

    def glossy(self, mirror, ng, mat, sample, depth, keys):
        """Reflection directions of rough materials, sampled in a lobe around the mirror.

        Parameters
        ----------
        mirror : (k, 3) float
            Mirror directions (above the surface); the rows of smooth materials are kept.
        ng : (k, 3) float
            Geometric normals on the side the rays leave toward.
        mat : (k,) intp
        sample : (k,) int
            Pixel sample of each ray (within the chunk), keying its random numbers.
        depth : int
            Depth of the hit (the sampler's glossy dimensions of that depth).
        keys : (pixel, sample_in_pixel)

        Returns
        -------
        (k, 3) float
            Weight unchanged (see :mod:`rtmesh.materials.glossy`).
        """
        it = self.it
        roughness = it.scene.materials.roughness.take(mat)
        rough = np.flatnonzero(roughness > 0.0)
        if not len(rough):
            return mirror
        pixel, sample_in_pixel = keys
        key_rows = sample.take(rough)
        u = it.sampler.glossy(pixel.take(key_rows), sample_in_pixel.take(key_rows), depth)
        mirror[rough] = sample_glossy_directions(take_rows(mirror, rough), take_rows(ng, rough),
                                                 roughness.take(rough), u)
        return mirror
