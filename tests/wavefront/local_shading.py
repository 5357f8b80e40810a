"""The local shading stage: what a hit sends back toward the ray without a new bounce.

Emission, unlit colours, ambient light (with ambient occlusion), and direct light: every
point-like light through its :meth:`~rtmesh.lights.interface.PointLikeLight.illuminate`,
one shadow ray per lit hit (:func:`rtmesh.shading.direct_light.light_samples`), and the
area lights (:mod:`rtmesh.lights.area_lighting`), for Blinn-Phong materials; metallic-roughness
materials take their direct light from :mod:`wavefront.physical_shading`.
"""

import numpy as np

from rtmesh.core.compiled import by_component
from rtmesh.core.rays import NO_VECTORS, take_rows
from rtmesh.core.vecmath import orthonormal_basis
from rtmesh.geometry.accel import offset_ray_origins
from rtmesh.materials.blinn_phong import raise_highlights, surface_reflectance
from rtmesh.rendering.chunk_state import Stage, add_rows_or_all, rows_at
from wavefront.physical_shading import bsdf_weight
from rtmesh.sampling.warps import square_to_cosine_hemisphere
from rtmesh.shading.direct_light import SHADOW_SHORTEN, add_light, light_samples


class LocalShading(Stage):
    """Local shading for one integrator's scene (its lights, material tables, sampler)."""

    def shade(self, srf, depth, chunk):
        """Emission, ambient (with AO) and direct light with shadows; (k, 3) or None."""
        it = self.it
        ao_pass = depth == 0 and chunk.passes.wants("ao")
        st = it.plan
        local = None
        if st.emission:
            local = take_rows(it.tables.emission, srf.mat)
            if srf.tints is not None and srf.tints.emission is not None:
                local = local * srf.tints.emission
            if srf.pdf is not None and it.area_lighting is not None:
                # emissive triangles are area lights: what BSDF-sampled rays see of them is
                # weighed against light sampling (see wavefront.physical_shading)
                local = local * self._emission_weight(srf)[:, None]
        tint = None if srf.tints is None else srf.tints.diffuse
        if st.unlit:
            # unlit materials show their (textured) colour as is
            unlit = it.scene.materials.unlit.take(srf.mat)
            if unlit.any():
                shown = np.where(unlit[:, None], take_rows(it.tables.diffuse, srf.mat), 0.0)
                shown = shown if tint is None else shown * tint
                local = shown if local is None else local + shown

        ao = None
        if st.ao and (st.ambient or ao_pass):
            ao = self.ambient_occlusion(srf, depth, chunk)
            if ao_pass:
                chunk.passes.write("ao", srf.sample, ao)
            chunk.clock.lap("ao")
        if st.ambient:
            amb = take_rows(it.tables.ambient_light, srf.mat)
            if tint is not None:
                amb = amb * tint
            if ao is not None:
                amb = amb * ao[:, None]
            if srf.tints is not None and srf.tints.metallic_roughness is not None:
                amb = amb * srf.tints.metallic_roughness[:, 2:3]  # baked occlusion
            local = amb if local is None else local + amb

        if st.lights or st.area_lights or st.environment_lighting:
            direct = self.direct_light(srf, depth, chunk)
            if direct is not None:
                local = direct if local is None else local + direct
            if st.physical:
                direct = it.physical_shading.direct(srf, depth, chunk)
                if direct is not None:
                    local = direct if local is None else local + direct
        return local

    def direct_light(self, srf, depth, chunk):
        """Blinn-Phong light from every light: one shadow ray per lit (hit, point-like light)
        (see :mod:`rtmesh.lights.interface`, :func:`rtmesh.shading.direct_light.light_samples`), ``light_samples`` per (hit, area light)
        (see :mod:`rtmesh.lights.area_lighting`).

        Returns
        -------
        (k, 3) float64 or None
            Component-major; None when no hit has a material that reflects light.
        """
        it = self.it
        rows = None if it.tables.all_shaded else np.flatnonzero(it.tables.shaded[srf.mat])
        if rows is not None and not len(rows):
            return None
        tints = srf.tints
        tint_d, tint_s = (NO_VECTORS if t is None else take_rows(t, rows)
                          for t in ((None, None) if tints is None else (tints.diffuse, tints.specular)))
        materials = (take_rows(srf.mat, rows), it.tables.diffuse, tint_d, it.tables.specular, tint_s,
                     it.tables.highlight_exponent)
        p, ng, ns, d = (take_rows(a, rows) for a in (srf.p, srf.ng, srf.ns, srf.d))
        records = [by_component(a) for a in (p, ng, ns, d)]
        total = None
        for light in it.lights:
            wi, distance, incident = light.illuminate(p)
            (lit, origins, directions, t_max, cos_i, incident, highlight_rows, highlight,
             power_exponent) = light_samples(by_component(wi), distance, by_component(incident), *records, materials[0],
                                             it.tables.highlight_exponent, it.tables.highlight_from, it.tables.offset_scale32,
                                             SHADOW_SHORTEN)
            if not len(lit):
                continue
            target = take_rows(rows, lit) if rows is not None else lit
            chunk.clock.lap("shade")
            occluded = it.accel.occluded(origins, directions, t_max, time=rows_at(srf.time, target))
            chunk.stats.rays["shadow"] += len(lit)
            chunk.clock.lap("shadow")
            if total is None:
                total = np.zeros((len(srf.mat), 3), order="F")
            power = raise_highlights(highlight, power_exponent)
            add_light(by_component(total), target, lit, occluded, cos_i, incident, highlight_rows, power,
                      *materials[:5])
        sampled = [lighting for lighting, on in ((it.area_lighting, it.plan.area_lights),
                                                 (it.environment_lighting, it.plan.environment_lighting)) if on]
        if sampled:

            def reflectance(wi, lit, pdf=None):
                """Blinn-Phong factor toward unit directions ``wi``; highlights only where ``lit``
                (the samples' density does not matter: no MIS for Blinn-Phong)."""
                return surface_reflectance(ns, d, wi, lit, *materials)

            pixel, sample_in_pixel = chunk.keys
            sample = take_rows(srf.sample, rows)
            for lighting in sampled:
                light = lighting.direct(p, ng, reflectance, pixel[sample], sample_in_pixel[sample], depth,
                                        chunk.stats, chunk.clock, rows_at(srf.time, rows))
                if light is not None:
                    if total is None:
                        total = np.zeros((len(srf.mat), 3), order="F")
                    add_rows_or_all(total, rows, light)
        return total

    def _emission_weight(self, srf):
        """(k,) MIS weight of the emission that the hits' incoming rays see: 1 for camera
        rays and delta lobes, :func:`wavefront.physical_shading.bsdf_weight` against
        the emitters' light sampling for BSDF-sampled rays."""
        lighting = self.it.area_lighting
        weight = np.ones(len(srf.pdf))
        sampled = np.flatnonzero(np.isfinite(srf.pdf))
        if len(sampled):
            light_pdf = lighting.pdf_of_emitters(take_rows(srf.origin, sampled), srf.prim[sampled],
                                                 take_rows(srf.p, sampled))
            weight[sampled] = bsdf_weight(srf.pdf[sampled], light_pdf, lighting.samples)
        return weight

    def ambient_occlusion(self, srf, depth, chunk):
        """Fraction of cosine-weighted hemisphere rays that escape within ``ao_distance``."""
        it = self.it
        pixel, sample_in_pixel = chunk.keys
        k = len(srf.mat)
        n_ao = it.ao_samples
        t, b = orthonormal_basis(srf.ng)
        px, sp = pixel[srf.sample], sample_in_pixel[srf.sample]
        free = np.zeros(k)
        # the spp * n_ao rays of a pixel's samples are one stratified set of the render's
        # sampler, and the n_ao of each hit are stratified among themselves
        for i in range(n_ao):
            u = it.sampler.ambient_occlusion(px, sp, depth, i, n_ao)
            w = square_to_cosine_hemisphere(u)
            d = t * w[:, :1] + b * w[:, 1:2] + srf.ng * w[:, 2:3]
            origins = offset_ray_origins(srf.p, srf.ng, np.float32, it.offset_scale, d)
            free += ~it.accel.occluded(origins, d, np.full(k, it.ao_distance), time=srf.time)
        chunk.stats.rays["ao"] += k * n_ao
        return free / n_ao
