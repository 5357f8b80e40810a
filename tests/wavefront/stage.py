"""The general wavefront: a chunk's samples one depth level at a time, as NumPy batches and
compiled passes (rtmesh.rendering.surface_stage, local_shading, physical_shading,
secondary_rays): the tests' reference of the path kernel's Whitted configuration (see
this package's ``attach``).
"""

import numpy as np

from rtmesh.core.rays import RayBatch, repeated_row, take_rows
from rtmesh.rendering.chunk_state import ChunkState, Stage, scatter_add
from wavefront.physical_shading import bsdf_weight

# a camera ray's throughput, shared read-only by the rays of a chunk
UNIT_THROUGHPUT = np.ones(3)


class Wavefront(Stage):
    """The general wavefront of one integrator's view (its stages and tables)."""

    def render(self, pixel, sample_in_pixel, m, spp, ragged, stats, clock):
        """:meth:`rtmesh.rendering.integrator.Integrator.render_chunk` for the samples
        ``(pixel, sample_in_pixel)`` of ``m`` pixels: camera rays, then one depth level at a
        time up to ``max_depth``; returns the chunk's radiance and passes as render_chunk does."""
        it = self.it
        n = len(pixel)
        origins, directions, sample_time = it._camera_rays(pixel, sample_in_pixel)
        # camera rays have unit throughput: a read-only repeated row costs nothing; _shade
        # does not multiply by it at depth 0 and absorbs only on rows in an absorbing
        # medium (inside one, camera rays lose light on the way: then a real array)
        throughput = (np.ones((n, 3), order="F") if it._camera_absorbs
                      else repeated_row(UNIT_THROUGHPUT, n))
        rays = RayBatch(origins, directions, np.arange(n, dtype=np.int64), throughput,
                        repeated_row(it._camera_medium, n))
        chunk = ChunkState(np.zeros((n, 3), order="F"), it.passes.buffers(n), pixel, sample_in_pixel, stats,
                           clock, sample_time)
        stats.rays["camera"] += n
        clock.lap("camera")

        for depth in range(it.settings.max_depth + 1):
            if not len(rays):
                break
            hits = it.accel.intersect(rays.origins, rays.directions,
                                      None if sample_time is None else sample_time[rays.sample])
            clock.lap("intersect")
            rays = self.shade(rays, hits, depth, chunk)

        if ragged:
            return chunk.radiance, it.passes.per_sample(chunk.passes, n) or None, stats
        passes = it.passes.per_pixel(chunk.passes, m, spp) or None
        return chunk.radiance.reshape(m, spp, 3), passes, stats

    def shade(self, rays, hits, depth, chunk):
        """Shade one depth level; returns the rays of the next level."""
        it = self.it
        radiance = chunk.radiance
        m = it.scene.materials
        # camera rays (depth 0) are one per sample, in sample order, with unit throughput
        # unless the camera sits in an absorbing medium
        primary = depth == 0
        unit_throughput = primary and not it._camera_absorbs

        # area lights seen directly: rays meeting one before any surface end there
        on_light = None
        if it.plan.area_light_visibility:
            on_light = it.area_lighting.intersect(rays.origins, rays.directions, hits)
        hit = hits.prim >= 0

        # absorption: rays inside an absorbing medium lose light over the distance they
        # travelled.  Only those rows are written: the others would be multiplied by 1.0
        # (no change), and camera rays in a clear medium share the read-only unit row.
        if it.plan.absorption:
            medium = rays.medium[:, 0]
            # -1 (outside every medium) maps to the last entry, which is False
            absorbing = np.flatnonzero(it._absorbing_medium[medium])
            if len(absorbing):
                sigma = m.absorption[medium[absorbing]]
                t = hits.t[absorbing][:, None]
                # exp(-0 * inf) would be NaN for a channel that does not absorb, on a ray
                # that left the medium through a hole
                with np.errstate(invalid="ignore"):
                    rays.throughput[absorbing] *= np.where(sigma > 0, np.exp(-sigma * t), 1.0)

        if on_light is not None and len(on_light[0]):
            ended, emitted, lights = on_light
            if rays.pdf is not None:
                # BSDF-sampled rays weigh the light against light sampling (see physical_shading)
                light_pdf = it.area_lighting.pdf_of_visible(lights, take_rows(rays.origins, ended),
                                                              take_rows(rays.directions, ended), hits.t[ended])
                emitted = emitted * bsdf_weight(rays.pdf[ended], light_pdf, it.area_lighting.samples)[:, None]
            scatter_add(radiance, rays.sample[ended], take_rows(rays.throughput, ended) * emitted,
                         unique=primary)

        # misses: rays leaving the scene see the background
        n_hit = int(np.count_nonzero(hit))
        if it.plan.background and n_hit < len(hit):
            miss = np.flatnonzero(hits.prim == -1)  # -2: ended on an area light
            directions = take_rows(rays.directions, miss)
            seen = it.background.radiance(directions)
            if rays.pdf is not None:
                seen = seen * self.background_weight(rays.pdf[miss], directions)[:, None]
            scatter_add(radiance, rays.sample[miss], take_rows(rays.throughput, miss) * seen,
                         unique=primary)

        if not n_hit:
            return RayBatch.empty()
        # the rows of the rays that hit; None when all did (no gathers needed)
        rows = None if n_hit == len(hit) else np.flatnonzero(hit)
        srf = it.surface_stage.records(rays, hits, rows, chunk.sample_time)
        chunk.clock.lap("shade")
        if primary and it.plan.passes:
            it.passes.record(chunk.passes, srf, hits, rows)
            chunk.clock.lap("passes")

        local = it.local_shading.shade(srf, depth, chunk)
        if local is not None:
            if not unit_throughput:
                local = local * take_rows(rays.throughput, rows)
            scatter_add(radiance, None if primary and rows is None else srf.sample, local,
                         unique=primary)
        chunk.clock.lap("shade")

        if depth >= it.settings.max_depth or not it.plan.reflection:
            return RayBatch.empty()
        hit_rays = rays.subset(rows)
        next_rays = it.secondary_rays.spawn(srf, hit_rays, depth, chunk)
        if it.plan.physical:
            next_rays = RayBatch.concatenate([next_rays, it.physical_shading.spawn(srf, hit_rays, depth, chunk)])
        chunk.clock.lap("spawn")
        return next_rays

    def background_weight(self, pdf, directions):
        """Weight of the background seen by rays that left the scene, from the density of
        their BSDF samples ((k,) -> (k,)): 1 for camera rays and delta lobes; the MIS
        weight against environment light sampling where the background lights the scene,
        else 0 (see :mod:`wavefront.physical_shading`)."""
        it = self.it
        lighting = it.environment_lighting if it.plan.environment_lighting else None
        if lighting is None:
            return np.isinf(pdf).astype(np.float64)
        return bsdf_weight(pdf, lighting.pdf(directions), lighting.samples)
