"""The wavefront Whitted integrator.

Each chunk of pixel samples is rendered as a sequence of named stages, every stage working
on whole ray batches (no per-ray Python loop)::

    camera rays -> [intersect -> misses -> absorption -> surfaces -> local shading
                    (ambient/AO, lights with shadow rays) -> spawn reflection and
                    refraction rays] repeated until max depth or no ray is left
                -> film

Rays carry the index of the sample they belong to and their throughput; contributions go
back to the sample by scattering.  Chunks run on a thread pool (Embree, NumPy and the
compiled kernels of :mod:`rtmesh.shading.kernels` release the GIL).  Every random number is a
function of (seed, pixel, sample, dimension), each pixel is rendered whole inside one
chunk, and the chunks do not depend on the thread count (see :mod:`rtmesh.rendering.scheduler`), so
the image is bit-identical whatever the thread count.

Before rendering, :class:`Integrator` looks at the scene and the settings and enables only
the stages that can contribute (see :attr:`Integrator.plan`).  Building and running it
changes no process-wide state: the tuning for rendering processes (allocator, GIL switch
interval, kept thread pools) is :mod:`rtmesh.core.runtime`'s, turned on by the programs that
own their process.
"""

import dataclasses
import logging
import time
from dataclasses import dataclass

import numpy as np

from rtmesh.core import runtime
from rtmesh.core.rays import RayBatch, component_major, repeated_row, take_rows
from rtmesh.core.vecmath import dot, fresnel_dielectric, fresnel_schlick, orthonormal_basis, reflect, refract
from rtmesh.geometry.accel import Accel, offset_ray_origins
from rtmesh.geometry.build_kernels import corner_rows, face_rows
from rtmesh.geometry.cutouts import CutoutAccel
from rtmesh.geometry.motion import MotionAccel, blurs, object_motions, scene_at_time, swept_bounds
from rtmesh.io.passes import DERIVED_PASSES, PassRecorder, derived_pass
from rtmesh.lights.area_lights import AreaLighting, emissive_mesh_light, is_area_light
from rtmesh.materials.blinn_phong import surface_reflectance
from rtmesh.materials.glossy import sample_glossy_directions
from rtmesh.materials.table import ALPHA_MODES
from rtmesh.rendering.adaptive import render_rounds
from rtmesh.rendering.direct_stage import DirectStage
from rtmesh.rendering.film import Film
from rtmesh.rendering.film_sums import add_rows
from rtmesh.rendering.media import Media
from rtmesh.rendering.render_plan import RenderPlan
from rtmesh.rendering.scheduler import pixel_chunks, run_on_threads
from rtmesh.rendering.stats import RenderStats
from rtmesh.rendering.surface_textures import SurfaceTextures
from rtmesh.sampling.sampler import Sampler
from rtmesh.sampling.warps import square_to_cosine_hemisphere
from rtmesh.scene.background import as_background
from rtmesh.shading.direct_light import SHADOW_SHORTEN, add_light, highlight_thresholds, light_samples
from rtmesh.shading.surfaces import face_viewer, surface_records

log = logging.getLogger(__name__)

# an empty (0, 3) array stands for "none" in the kernels' optional vector arguments
_NO_VECTORS = np.zeros((0, 3))
_UNIT_THROUGHPUT = np.ones(3)


@dataclass
class RenderResult:
    """Output of :func:`render`.

    Attributes
    ----------
    image : (height, width, 3) float32
        Linear radiance, row 0 at the top.
    passes : dict of str to (height, width, k) float32
        Requested extra passes (see :mod:`rtmesh.io.passes`).
    stats : RenderStats
    film : Film
        The accumulation buffers (sums, sums of squares) for error estimates.
    alpha : (height, width, 1) float32 or None
        Coverage, when the background is transparent (``image`` is then premultiplied).
    """

    image: np.ndarray
    passes: dict
    stats: RenderStats
    film: Film
    alpha: np.ndarray | None = None


class _Surfaces:
    """Shading records of the rays that hit something (one row per hit).

    ``p``, ``ng``, ``ns`` and ``d`` (the incoming ray direction; ``wo = -d`` is formed only
    where it is needed) are (k, 3) component-major arrays (see :mod:`rtmesh.core.rays`).
    ``ng`` and ``ns`` are flipped to the side the ray came from; ``front`` says whether
    that is the outer side of the triangle (counter-clockwise winding).  ``mat`` (intp) is
    the material, ``prim`` (int) the face hit, ``sample`` the pixel sample each hit
    contributes to, ``time`` (float, None without motion blur) the time of the ray (see
    :mod:`rtmesh.geometry.motion`).  ``tints`` (:class:`rtmesh.rendering.surface_textures.Tints` or None) holds the
    texture and vertex-colour multipliers of the material colours.
    """

    __slots__ = ("p", "ng", "ns", "d", "front", "mat", "prim", "sample", "time", "tints")


def _translated(obj, shift):
    """A copy of a camera or light moved by ``-shift`` (directions are unchanged)."""
    changes = {}
    for name in ("position", "look_at"):
        if hasattr(obj, name):
            changes[name] = getattr(obj, name) - shift
    return dataclasses.replace(obj, **changes) if changes else obj


class Integrator:
    """Renders one scene with one set of settings.

    Parameters
    ----------
    scene : Scene
    settings : RenderSettings

    Attributes
    ----------
    plan : RenderPlan
        Which optional stages this scene and these settings need.
    """

    def __init__(self, scene, settings):
        self.settings = settings.validate()
        self.sampler = Sampler.for_settings(self.settings)
        if object_motions(scene) and not blurs(scene):
            # an instantaneous shutter: moving objects stand still where the shutter finds them
            scene = scene_at_time(scene, scene.camera.shutter[0])
        self.scene = scene
        # Re-centre the scene on the origin before it meets float32: float32 resolution is
        # relative to the size of the coordinates, so a model 1e6 units from the origin would
        # otherwise be traced on a grid of 1/16 unit.  Shading sees the same shifted frame.
        scene_bounds = scene.bounds  # a pass over every vertex: formed once
        self.shift = scene_bounds.mean(axis=0)
        # moving objects get Embree scenes of their own, traced at each ray's time
        self.motion = None
        if blurs(scene):
            motions = {k: m.shifted(self.shift) for k, m in object_motions(scene).items()}
            self.motion = MotionAccel(scene.vertices - self.shift, scene.faces, scene.object_id,
                                      motions, scene.camera.shutter)
        self.accel = self.motion or Accel(scene.vertices - self.shift, scene.faces)
        # the scene's size in the re-centred frame bounds the triangles' size, which sets
        # part of the origin offset (see offset_ray_origins); it cannot be zero for a scene
        # that renders.  With motion,
        # the size of the space the objects sweep during the shutter.
        bounds = swept_bounds(scene) if self.motion else scene_bounds
        self.offset_scale = max(float(np.abs(bounds - self.shift).max()), 1e-30)
        m = scene.materials
        # textures and vertex colours, looked up per hit only where the scene has them
        self.textures = SurfaceTextures(scene)
        self.cutouts = None
        if m.any_cutout:
            # every query (camera, secondary, shadow, area-light, AO rays) sees the cut-outs,
            # at each ray's time when objects move
            self.cutouts = CutoutAccel(self.accel, scene.face_normals, scene.material_id, m.cutout,
                                       m.alpha_mode == ALPHA_MODES.index("blend"), m.alpha_cutoff,
                                       self.textures, self.offset_scale, settings.seed)
            self.accel = self.cutouts
        self.camera = _translated(scene.camera, self.shift)
        # formed once (and failing early on a degenerate camera), not for every chunk
        self._camera_frame = self.camera.frame()
        lights = [_translated(light, self.shift) for light in scene.lights if not light.is_black]
        self.lights = [light for light in lights if not is_area_light(light)]
        area_lights = [light for light in lights if is_area_light(light)]
        if m.any_emission:
            tint = mean_tint = None
            if self.textures.emission_textured:
                material_id = scene.material_id

                def tint(prim, u, v):
                    return self.textures.emission_tints(prim, u, v, material_id[prim])

                mean_tint = self.textures.mean_emission_tints()[material_id]
            emitters = emissive_mesh_light(self.accel.triangles, scene.face_normals,
                                           m.emission[scene.material_id], tint, mean_tint)
            area_lights += [emitters] if emitters is not None else []
        self.area_lighting = (AreaLighting(area_lights, self.accel, self.settings, self.offset_scale)
                              if area_lights else None)
        lit = ~m.unlit[:, None]
        shaded_any = bool((((m.diffuse > 0) | (m.specular > 0)) & lit).any())
        self.ao_distance = settings.ao_distance or 0.2 * float(np.linalg.norm(np.ptp(scene_bounds, axis=0)))
        ambient_on = bool((scene.ambient > 0).any() and (m.ambient > 0).any())
        self.background = as_background(scene.background)
        # only the passes asked for are computed; a transparent background needs coverage
        self.passes = PassRecorder(scene, tuple(settings.passes) + ("alpha",) * self.background.transparent,
                                   self.camera, self.shift)
        # the AO pass alone asks for 16 rays per camera hit unless ao_samples says otherwise
        self.ao_samples = settings.ao_samples or (16 if "ao" in settings.passes else 0)
        self.plan = RenderPlan(
            emission=m.any_emission,
            ambient=ambient_on,
            lights=bool(self.lights) and shaded_any,
            area_lights=self.area_lighting is not None and shaded_any,
            area_light_visibility=self.area_lighting is not None and bool(self.area_lighting.visible),
            specular=m.any_specular,
            smooth_normals=scene.vertex_normals is not None,
            textures=bool(self.textures),
            normal_maps=self.textures.tangents is not None,
            cutouts=self.cutouts is not None,
            unlit=m.any_unlit,
            reflection=settings.max_depth > 0 and (m.any_mirror or m.any_transmission),
            glossy=settings.max_depth > 0 and m.any_glossy,
            refraction=settings.max_depth > 0 and m.any_transmission,
            absorption=m.any_absorption,
            background=not self.background.is_black,
            passes=bool(self.passes),
            ao=self.ao_samples > 0 and (ambient_on or "ao" in settings.passes),
            lens=self.camera.aperture > 0.0,
            motion=self.motion is not None,
        )
        # per-material flags, looked up per hit
        self._reflective = (m.mirror > 0).any(axis=1) | (m.transmission > 0).any(axis=1)
        self._transmissive = (m.transmission > 0).any(axis=1)
        self._shaded = ((m.diffuse > 0).any(axis=1) | (m.specular > 0).any(axis=1)) & ~m.unlit
        self._all_shaded = bool(self._shaded.all())  # then no per-hit lookup is needed
        self._init_media(scene)
        self._fresnel = fresnel_exact_or_schlick(settings.fresnel)
        self._has_specular = (m.specular > 0).any(axis=1)
        # per-material colours, component-major so that gathering them per hit keeps the
        # fast layout; the ambient term is the product of two constants, formed once
        self._diffuse = component_major(m.diffuse.T)
        self._specular = component_major(m.specular.T)
        self._emission = component_major(m.emission.T)
        self._ambient_light = component_major((m.ambient * scene.ambient).T)
        # the highlight's exponent per material; negative: no highlight
        self._highlight_exponent = np.where(self._has_specular, m.shininess, -1.0)
        self._highlight_from = highlight_thresholds(self._highlight_exponent)
        self._offset_scale32 = np.float32(self.offset_scale)
        self._faces, self._vertex_normals = self._face_tables()
        self._smooth = (np.zeros(len(scene.faces), dtype=bool) if scene.smooth is None
                        else np.ascontiguousarray(scene.smooth, dtype=bool))
        # gathers with int32 indices are ~10x slower in NumPy than with intp ones
        self._material_id = scene.material_id.astype(np.intp)
        # scenes that need only direct light take one compiled stage per chunk
        self.direct_stage = DirectStage.plan(self)
        self.plan = dataclasses.replace(self.plan, fused_direct=self.direct_stage is not None)

    def _init_media(self, scene):
        """Medium stacks (see :mod:`rtmesh.rendering.media`), only for scenes that refract.

        Sets ``media`` (None without transmissive materials), ``_camera_medium`` (the
        camera's stack, ``(STACK_DEPTH,)``; ``(0,)`` without media), ``_camera_absorbs``
        (camera rays lose light before their first hit, so their throughput is not 1) and
        ``_absorbing_medium`` (bool by medium id, the last entry, -1, for the outside).
        """
        m = scene.materials
        self.media = None
        self._camera_medium = np.zeros(0, dtype=np.int32)
        self._camera_absorbs = False
        self._absorbing_medium = np.zeros(1, dtype=bool)
        if not m.any_transmission:
            return
        self.media = Media(m, scene.material_id, scene.vertices, scene.faces,
                           scene.face_normals)
        self._absorbing_medium = (self.media.absorption > 0).any(axis=1)
        trace, to_rest = self.accel.intersect, None
        if self.motion is not None:
            # the camera's media when the shutter opens
            def at_open(n):
                return np.full(n, self.camera.shutter[0])

            def trace(origins, directions):
                return self.accel.intersect(origins, directions, at_open(len(origins)))

            def to_rest(prim, directions):
                return self.motion.directions_to_rest(prim, at_open(len(prim)), directions)
        self._camera_medium = self.media.camera_stack(trace, self.camera.position, self.offset_scale,
                                                      to_rest)
        self._camera_absorbs = bool((self.media.absorption[self._camera_medium[0]] > 0).any())

    def _face_tables(self):
        """What shading reads per hit triangle, packed so that one row holds it.

        Returns
        -------
        faces : (F, 12) float64
            Row-major (the surface kernel reads whole rows): the triangle
            ``[v0, v1 - v0, v2 - v0]`` as Embree saw it (:attr:`Accel.triangles`) and the
            unit geometric normal.
        vertex_normals : (F, 9) float64
            Row-major ``[n0, n1 - n0, n2 - n0]`` of each face's vertex normals; ``(0, 9)``
            without smooth shading.
        """
        sc = self.scene
        # compiled passes writing the rows directly (filling the columns of a row-major
        # table from component-major ones took NumPy ~0.5 s on a million faces)
        faces = face_rows(self.accel.triangles, sc.face_normals)
        if not self.plan.smooth_normals:
            return faces, np.zeros((0, 9))
        return faces, corner_rows(sc.vertex_normals, sc.faces)

    # ---------------------------------------------------------------- whole image
    def render(self, progress=None, pool=None):
        """Render the image: at ``spp`` samples per pixel, or adaptively in rounds when the
        settings ask for it (see :mod:`rtmesh.rendering.adaptive`).

        Parameters
        ----------
        progress : callable, optional
            Called as ``progress(chunks_done, chunks_total)`` from the calling thread
            (per round, for an adaptive render).
        pool : concurrent.futures.ThreadPoolExecutor, optional
            Workers that render alongside the calling thread when ``thread_count`` is
            above 1 (left running).  Without one, the render makes ``thread_count``
            workers and joins them at the end, or, in a process tuned by
            :func:`rtmesh.core.runtime.tune_process`, uses the process's kept pool.  The image
            does not depend on the pool.

        Returns
        -------
        RenderResult
        """
        s = self.settings
        start = time.perf_counter()
        # the first round renders every pixel (rtmesh.rendering.adaptive): the sums need no clearing;
        # without later rounds every pixel is added once, and its image value with it
        film = Film(s.width, s.height, self.passes.film_passes(), zeroed=False, one_pass=not s.adaptive)
        stats = RenderStats(threads=s.thread_count, pixels=s.width * s.height)
        stats.stages_enabled = self.plan.enabled()
        # threads of its own and the caller's switch interval, unless the process is tuned
        # for rendering (rtmesh.core.runtime): then its kept pool and a short interval
        with runtime.render_pool(s.thread_count, pool) as workers, runtime.gil_handoff(s.thread_count):
            render_rounds(self, film, stats, progress, workers)
            image = film.image(workers)
        if self.cutouts is not None:
            stats.rays["cutout"] += self.cutouts.layers_traced
        stats.wall_seconds = time.perf_counter() - start
        stats.samples = sum(r.samples for r in stats.rounds)
        stats.relative_error = film.relative_error()
        passes = {name: film.pass_image(name) for name in film.pass_sums if name in s.passes}
        passes.update({name: derived_pass(name, film) for name in s.passes if name in DERIVED_PASSES})
        passes = {name: passes[name] for name in s.passes if name in passes}  # order asked for
        alpha = film.pass_image("alpha") if self.background.transparent else None
        return RenderResult(image, passes, stats, film, alpha)

    def render_samples(self, film, pixels, first_sample, spp, stats, progress=None, pool=None):
        """Render samples of a set of pixels into ``film``, in chunks on the threads.

        Parameters
        ----------
        film : Film
        pixels : (m,) int array or range
            Linear pixel indices, distinct and ascending.
        first_sample : int or (m,) int array
            Global index of each pixel's first new sample (its sample count so far).
        spp : int or (m,) int array
            New samples per pixel: a number for all (a uniform render, or an adaptive
            round's first), or one per pixel (a later adaptive round, where pixels at
            different counts each double theirs).  Either way the round is one batch,
            cut into chunks of at most about ``chunk_samples`` samples (smaller towards
            the end on several threads, see :func:`rtmesh.rendering.scheduler.chunk_starts`); a chunk never splits a
            pixel's samples, so each pixel's sum is formed in sample order whatever the
            chunking and thread count.
        stats : RenderStats
            Ray counts and stage times are added to it.
        progress : callable, optional
            ``progress(chunks_done, chunks_total)``, called on the calling thread between
            the chunks it renders itself (keep it quick: the other threads do not wait for
            it, but that thread does).
        pool : concurrent.futures.ThreadPoolExecutor, optional
            Workers that render alongside the calling thread (if not given, those of
            :func:`rtmesh.core.runtime.render_pool` for this call).
        """
        s = self.settings
        uniform = np.ndim(spp) == 0 and np.ndim(first_sample) == 0
        # pixels may be a range (a whole uniform image): each chunk takes its slice of it, so
        # no index array of the whole image is made
        if not uniform:
            pixels = np.asarray(pixels, dtype=np.int64)
            counts = np.broadcast_to(np.asarray(spp, dtype=np.int64), pixels.shape)
            first = np.broadcast_to(np.asarray(first_sample, dtype=np.int64), pixels.shape)
        bounds = pixel_chunks(spp if uniform else counts, len(pixels), s.chunk_samples)
        n_chunks = len(bounds)

        def render_and_add(a, b):
            """Render the pixels ``a .. b - 1`` of the call and add them to the film, on
            the thread that rendered them: the chunks of a call never share a pixel, so
            each pixel's sum is formed by one thread, in sample order."""
            if uniform:
                chunk = (pixels[a:b], first_sample, spp)
            else:
                chunk = (pixels[a:b], first[a:b], counts[a:b])
            radiance, passes, chunk_stats = self.render_chunk(*chunk)
            t0 = time.perf_counter()
            if uniform:
                # a run of consecutive pixels (every chunk of a whole image) is a slice:
                # cheaper to add into than a gather-scatter through an index array
                px = chunk[0]
                contiguous = px[-1] - px[0] == len(px) - 1
                film.add_tile(slice(px[0], px[-1] + 1) if contiguous else px, radiance, passes)
            else:
                film.add_samples(chunk[0], chunk[2], radiance, passes)
            chunk_stats.stage_seconds["film"] += time.perf_counter() - t0
            return chunk_stats

        if s.thread_count == 1 or n_chunks == 1:
            for i, (a, b) in enumerate(bounds):
                stats.merge(render_and_add(a, b))
                if progress is not None:
                    progress(i + 1, n_chunks)
            return
        with runtime.render_pool(s.thread_count, pool) as workers:
            run_on_threads(render_and_add, bounds, s.thread_count, workers, stats, progress)

    # ---------------------------------------------------------------- one chunk
    def render_chunk(self, pixels, first_sample, spp):
        """Render the samples ``first_sample .. first_sample + spp - 1`` of some pixels.

        Sample indices are global to the pixel across adaptive rounds, so the samples a
        later round adds continue the same sequences (stratified in sets of the settings'
        ``spp``; Sobol prefixes stay well distributed) instead of repeating the first ones.
        Every sample point is a function of (seed, pixel, global sample index, dimension)
        only, so a sample's radiance is the same whatever chunk or round takes it.

        Parameters
        ----------
        pixels : (m,) int array or range
            Linear pixel indices (``row * width + column``).
        first_sample : int or (m,) int array
            Index of the first sample to take in each pixel (one for all, or per pixel).
        spp : int or (m,) int array
            Samples to take in each pixel (one for all, or per pixel).

        Returns
        -------
        radiance : (m, spp, 3) float64, or (sum(spp), 3) with per-pixel ``spp``
            Radiance of every sample, pixel by pixel in sample order (with per-pixel
            counts the samples of pixel ``i`` are rows ``sum(spp[:i]) ..``).
        passes : dict of str to (m, spp, k) float64 (or (sum(spp), k)), or None
        stats : RenderStats
            Ray counts and stage times of this chunk.
        """
        s = self.settings
        stats = RenderStats()
        clock = _Clock(stats.stage_seconds)
        if isinstance(pixels, range):
            pixels = np.arange(pixels.start, pixels.stop, pixels.step, dtype=np.int64)
        pixels = np.asarray(pixels, dtype=np.int64)
        m = len(pixels)
        # (isinstance, not np.ndim: this runs per chunk with the GIL held)
        ragged = isinstance(spp, np.ndarray) or isinstance(first_sample, np.ndarray)

        # camera: one ray per pixel sample
        if ragged:
            counts = np.broadcast_to(np.asarray(spp, dtype=np.int64), pixels.shape)
            first = np.broadcast_to(np.asarray(first_sample, dtype=np.int64), pixels.shape)
            n = int(counts.sum())
            pixel = np.repeat(pixels, counts)
            # global index: the pixel's first sample plus the position in its run of rows
            row_start = np.cumsum(counts) - counts
            sample_in_pixel = np.repeat(first - row_start, counts) + np.arange(n, dtype=np.int64)
        else:
            n = m * spp
            pixel = np.repeat(pixels, spp) if spp > 1 else pixels
            sample_in_pixel = (np.full(m, first_sample, dtype=np.int64) if spp == 1 else
                               np.tile(np.arange(first_sample, first_sample + spp, dtype=np.int64), m))
        if self.direct_stage is not None:
            # the stage forms the sample positions itself (see rtmesh.sampling.pixel_samples)
            clock.lap("camera")
            radiance = self.direct_stage.render(pixel, sample_in_pixel, stats)
            clock.lap("direct")
            return (radiance, None, stats) if ragged else (radiance.reshape(m, spp, 3), None, stats)
        # every dimension is stratified in sets of the settings' spp, whatever the round
        in_pixel = self.sampler.pixel(pixel, sample_in_pixel)
        lens_uv = None
        if self.plan.lens:
            lens_uv = self.sampler.lens(pixel, sample_in_pixel)
        sample_time = None
        if self.plan.motion:
            # one time per camera sample, stratified per pixel; its rays all inherit it
            t_open, t_close = self.camera.shutter
            u = self.sampler.time(pixel, sample_in_pixel)
            sample_time = t_open + (t_close - t_open) * u
        origins, directions = self.camera.generate_rays(in_pixel, s.width, s.height, lens_uv, pixel,
                                                        self._camera_frame)
        # camera rays have unit throughput: a read-only repeated row costs nothing; _shade
        # does not multiply by it at depth 0 and absorbs only on rows in an absorbing
        # medium (inside one, camera rays lose light on the way: then a real array)
        throughput = (np.ones((n, 3), order="F") if self._camera_absorbs
                      else repeated_row(_UNIT_THROUGHPUT, n))
        rays = RayBatch(origins, directions, np.arange(n, dtype=np.int64), throughput,
                        repeated_row(self._camera_medium, n))
        radiance = np.zeros((n, 3), order="F")
        aov = self.passes.buffers(n)
        stats.rays["camera"] += n
        clock.lap("camera")

        keys = (pixel, sample_in_pixel)
        for depth in range(s.max_depth + 1):
            if not len(rays):
                break
            hits = self.accel.intersect(rays.origins, rays.directions,
                                        None if sample_time is None else sample_time[rays.sample])
            clock.lap("intersect")
            rays = self._shade(rays, hits, depth, radiance, aov, keys, stats, clock, sample_time)

        if ragged:
            return radiance, self.passes.per_sample(aov, n) or None, stats
        passes = self.passes.per_pixel(aov, m, spp) or None
        return radiance.reshape(m, spp, 3), passes, stats

    # ---------------------------------------------------------------- stages
    def _shade(self, rays, hits, depth, radiance, aov, keys, stats, clock, sample_time=None):
        """Shade one depth level; returns the rays of the next level."""
        m = self.scene.materials
        # camera rays (depth 0) are one per sample, in sample order, with unit throughput
        # unless the camera sits in an absorbing medium
        primary = depth == 0
        unit_throughput = primary and not self._camera_absorbs

        # area lights seen directly: rays meeting one before any surface end there
        on_light = None
        if self.plan.area_light_visibility:
            on_light = self.area_lighting.intersect(rays.origins, rays.directions, hits)
        hit = hits.prim >= 0

        # absorption: rays inside an absorbing medium lose light over the distance they
        # travelled.  Only those rows are written: the others would be multiplied by 1.0
        # (no change), and camera rays in a clear medium share the read-only unit row.
        if self.plan.absorption:
            medium = rays.medium[:, 0]
            # -1 (outside every medium) maps to the last entry, which is False
            absorbing = np.flatnonzero(self._absorbing_medium[medium])
            if len(absorbing):
                sigma = m.absorption[medium[absorbing]]
                t = hits.t[absorbing][:, None]
                # exp(-0 * inf) would be NaN for a channel that does not absorb, on a ray
                # that left the medium through a hole
                with np.errstate(invalid="ignore"):
                    rays.throughput[absorbing] *= np.where(sigma > 0, np.exp(-sigma * t), 1.0)

        if on_light is not None and len(on_light[0]):
            ended, emitted = on_light
            _scatter_add(radiance, rays.sample[ended], take_rows(rays.throughput, ended) * emitted,
                         unique=primary)

        # misses: rays leaving the scene see the background
        n_hit = int(np.count_nonzero(hit))
        if self.plan.background and n_hit < len(hit):
            miss = np.flatnonzero(hits.prim == -1)  # -2: ended on an area light
            seen = self.background.radiance(take_rows(rays.directions, miss))
            _scatter_add(radiance, rays.sample[miss], take_rows(rays.throughput, miss) * seen,
                         unique=primary)

        if not n_hit:
            return RayBatch.empty()
        # the rows of the rays that hit; None when all did (no gathers needed)
        rows = None if n_hit == len(hit) else np.flatnonzero(hit)
        srf = self._surfaces(rays, hits, rows, sample_time)
        clock.lap("shade")
        if primary and self.plan.passes:
            self.passes.record(aov, srf, hits, rows)
            clock.lap("passes")

        local = self._local_shading(srf, depth, aov.get("ao"), keys, stats, clock)
        if local is not None:
            if not unit_throughput:
                local = local * take_rows(rays.throughput, rows)
            _scatter_add(radiance, None if primary and rows is None else srf.sample, local,
                         unique=primary)
        clock.lap("shade")

        if depth >= self.settings.max_depth or not self.plan.reflection:
            return RayBatch.empty()
        next_rays = self._spawn(srf, rays.subset(rows), depth, keys, stats)
        clock.lap("spawn")
        return next_rays

    def _surfaces(self, rays, hits, rows, sample_time=None):
        """Hit points, normals facing the incoming ray, and material ids of the hit ``rows``
        (see :func:`rtmesh.shading.kernels.surface_records`).

        With motion blur, points and normals are formed on the rest pose of the object hit
        and moved to the ray's time at the end (see :mod:`rtmesh.geometry.motion`).
        """
        srf = _Surfaces()
        srf.sample = take_rows(rays.sample, rows)
        srf.time = None if sample_time is None else sample_time[srf.sample]
        srf.d = take_rows(rays.directions, rows)
        srf.prim = take_rows(hits.prim, rows)
        view = _NO_VECTORS
        if srf.time is not None:
            view = self.motion.directions_to_rest(srf.prim.astype(np.intp), srf.time, srf.d)
        normal_maps = self.plan.normal_maps
        # the shading-normal terminator fix (see face_viewer) runs in the kernel unless
        # normal maps, applied below, change the normals after it
        srf.p, srf.ng, srf.ns, srf.front, srf.mat = surface_records(
            hits.prim, hits.u, hits.v, np.arange(len(hits)) if rows is None else rows, rays.directions,
            view, self._faces, self._vertex_normals, self._smooth, self._material_id,
            self.plan.smooth_normals and not normal_maps)
        srf.tints = None
        if self.plan.textures:
            u, v = take_rows(hits.u, rows), take_rows(hits.v, rows)
            srf.tints = self.textures.tints(srf.prim, u, v, srf.mat)
            if normal_maps:
                flip = np.where(srf.front, 1.0, -1.0)
                srf.ns = self.textures.normal_mapped(srf.ns, srf.prim, u, v, srf.mat, flip)
                # in the rest frame, like ns and ng
                srf.ns = face_viewer(srf.ns, srf.ng, srf.d if srf.time is None else view)
        if srf.time is not None:
            srf.p, srf.ng, srf.ns = self.motion.surfaces_to_world(srf.prim, srf.time, srf.p, srf.ng,
                                                                  srf.ns)
        return srf

    def _local_shading(self, srf, depth, ao_pass, keys, stats, clock):
        """Emission, ambient (with AO) and direct light with shadows; (k, 3) or None."""
        st = self.plan
        local = None
        if st.emission:
            local = take_rows(self._emission, srf.mat)
            if srf.tints is not None and srf.tints.emission is not None:
                local = local * srf.tints.emission
        tint = None if srf.tints is None else srf.tints.diffuse
        if st.unlit:
            # unlit materials show their (textured) colour as is
            unlit = self.scene.materials.unlit.take(srf.mat)
            if unlit.any():
                shown = np.where(unlit[:, None], take_rows(self._diffuse, srf.mat), 0.0)
                shown = shown if tint is None else shown * tint
                local = shown if local is None else local + shown

        ao = None
        if st.ao and (st.ambient or (depth == 0 and ao_pass is not None)):
            ao = self._ambient_occlusion(srf, depth, keys, stats)
            if depth == 0 and ao_pass is not None:
                ao_pass[srf.sample, 0] = ao
            clock.lap("ao")
        if st.ambient:
            amb = take_rows(self._ambient_light, srf.mat)
            if tint is not None:
                amb = amb * tint
            if ao is not None:
                amb = amb * ao[:, None]
            local = amb if local is None else local + amb

        if st.lights or st.area_lights:
            direct = self._direct_light(srf, depth, keys, stats, clock)
            if direct is not None:
                local = direct if local is None else local + direct
        return local

    def _direct_light(self, srf, depth, keys, stats, clock):
        """Blinn-Phong light from every light: one shadow ray per lit (hit, point-like light)
        (see :mod:`rtmesh.lights.interface`, :func:`rtmesh.shading.direct_light.light_samples`), ``light_samples`` per (hit, area light)
        (see :mod:`rtmesh.lights.area_lights`).

        Returns
        -------
        (k, 3) float64 or None
            Component-major; None when no hit has a material that reflects light.
        """
        rows = None if self._all_shaded else np.flatnonzero(self._shaded[srf.mat])
        if rows is not None and not len(rows):
            return None
        tints = srf.tints
        tint_d, tint_s = (_NO_VECTORS if t is None else take_rows(t, rows)
                          for t in ((None, None) if tints is None else (tints.diffuse, tints.specular)))
        materials = (take_rows(srf.mat, rows), self._diffuse, tint_d, self._specular, tint_s,
                     self._highlight_exponent)
        p, ng, ns, d = (take_rows(a, rows) for a in (srf.p, srf.ng, srf.ns, srf.d))
        total = None
        for light in self.lights:
            wi, distance, incident = light.illuminate(p)
            (lit, origins, directions, t_max, cos_i, incident, highlight_rows, highlight,
             power_exponent) = light_samples(wi, distance, incident, p, ng, ns, d, materials[0],
                                             self._highlight_exponent, self._highlight_from, self._offset_scale32,
                                             SHADOW_SHORTEN)
            if not len(lit):
                continue
            target = take_rows(rows, lit) if rows is not None else lit
            clock.lap("shade")
            occluded = self.accel.occluded(origins, directions, t_max, time=_time_rows(srf.time, target))
            stats.rays["shadow"] += len(lit)
            clock.lap("shadow")
            if total is None:
                total = np.zeros((len(srf.mat), 3), order="F")
            power = np.power(highlight, power_exponent, out=highlight)  # NumPy's pow is vectorised
            add_light(total, target, lit, occluded, cos_i, incident, highlight_rows, power, *materials[:5])
        if self.plan.area_lights:

            def reflectance(wi, lit):
                """Blinn-Phong factor toward unit directions ``wi``; highlights only where ``lit``."""
                return surface_reflectance(ns, d, wi, lit, *materials)

            pixel, sample_in_pixel = keys
            sample = take_rows(srf.sample, rows)
            area = self.area_lighting.direct(p, ng, reflectance, pixel[sample], sample_in_pixel[sample], depth,
                                             stats, clock, _time_rows(srf.time, rows))
            if area is not None:
                if total is None:
                    total = np.zeros((len(srf.mat), 3), order="F")
                _add_rows(total, rows, area)
        return total

    def _ambient_occlusion(self, srf, depth, keys, stats):
        """Fraction of cosine-weighted hemisphere rays that escape within ``ao_distance``."""
        pixel, sample_in_pixel = keys
        k = len(srf.mat)
        n_ao = self.ao_samples
        t, b = orthonormal_basis(srf.ng)
        px, sp = pixel[srf.sample], sample_in_pixel[srf.sample]
        free = np.zeros(k)
        # the spp * n_ao rays of a pixel's samples are one stratified set of the render's
        # sampler, and the n_ao of each hit are stratified among themselves
        for i in range(n_ao):
            u = self.sampler.ambient_occlusion(px, sp, depth, i, n_ao)
            w = square_to_cosine_hemisphere(u)
            d = t * w[:, :1] + b * w[:, 1:2] + srf.ng * w[:, 2:3]
            origins = offset_ray_origins(srf.p, srf.ng, np.float32, self.offset_scale, d)
            free += ~self.accel.occluded(origins, d, np.full(k, self.ao_distance), time=srf.time)
        stats.rays["ao"] += k * n_ao
        return free / n_ao

    def _spawn(self, srf, rays, depth, keys, stats):
        """Mirror (or glossy) reflection and refraction rays with their throughput weights."""
        m = self.scene.materials
        reflective = self._reflective[srf.mat]
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
        if self.plan.refraction:
            trans = self._transmissive[mat]
            j = np.flatnonzero(trans)
            if len(j):
                mat_j = mat[j]
                # the index ratio and the media beyond come from the ray's medium stack
                eta, beyond = self.media.cross(rays.medium[idx[j]], srf.prim[idx[j]],
                                               srf.front[idx[j]])
                cos_i = np.clip(dot(wo[j], ns[j]), 0.0, 1.0)
                fresnel = self._fresnel(cos_i, eta)
                wt, tir = refract(wo[j], ns[j], eta)
                # a shading normal can bend the refracted ray back to the incoming side of
                # the real surface; such rays cannot go through and are dropped
                ok = ~tir & (dot(wt, ng[j]) < 0.0)
                transmission = m.transmission[mat_j]
                reflect_weight = reflect_weight.copy()
                reflect_weight[j] += np.where(tir, 1.0, fresnel)[:, None] * transmission
                w_t = (1.0 - fresnel)[:, None] * transmission
                keep = ok & ((beta[j] * w_t).max(axis=1) >= self.settings.cutoff)
                jk = j[keep]
                if len(jk):
                    refract_batch = RayBatch(
                        offset_ray_origins(srf.p[idx[jk]], -ng[jk], scale=self.offset_scale,
                                           directions=wt[keep]),
                        wt[keep],
                        rays.sample[idx[jk]],
                        beta[jk] * w_t[keep],
                        beyond[keep],
                    )
                    stats.rays["refraction"] += len(jk)

        beta_r = beta * reflect_weight
        keep = beta_r.max(axis=1) >= self.settings.cutoff
        if keep.any():
            wr = reflect(wo[keep], ns[keep])
            # a shading normal can send the mirror direction under the real surface:
            # fall back to the geometric mirror direction there
            below = dot(wr, ng[keep]) <= 0.0
            if below.any():
                wr[below] = reflect(wo[keep][below], ng[keep][below])
            if self.plan.glossy:
                wr = self._glossy(wr, ng[keep], mat[keep], srf.sample[idx[keep]], depth, keys)
            batches.append(RayBatch(
                offset_ray_origins(srf.p[idx[keep]], ng[keep], scale=self.offset_scale, directions=wr),
                wr,
                rays.sample[idx[keep]],
                beta_r[keep],
                rays.medium[idx[keep]],
            ))
            stats.rays["reflection"] += int(keep.sum())
        if refract_batch is not None:
            batches.append(refract_batch)
        return RayBatch.concatenate(batches)

    def _glossy(self, mirror, ng, mat, sample, depth, keys):
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
        roughness = self.scene.materials.roughness.take(mat)
        rough = np.flatnonzero(roughness > 0.0)
        if not len(rough):
            return mirror
        pixel, sample_in_pixel = keys
        key_rows = sample.take(rough)
        u = self.sampler.glossy(pixel.take(key_rows), sample_in_pixel.take(key_rows), depth)
        mirror[rough] = sample_glossy_directions(take_rows(mirror, rough), take_rows(ng, rough),
                                                 roughness.take(rough), u)
        return mirror


def _time_rows(time, *row_sets):
    """``time`` gathered by successive row selections (None rows: all); None stays None."""
    if time is None:
        return None
    for rows in row_sets:
        time = take_rows(time, rows)
    return time


def fresnel_exact_or_schlick(mode):
    """The Fresnel function for a ``fresnel`` setting."""
    return fresnel_dielectric if mode == "exact" else fresnel_schlick


def _scatter_add(target, index, values, unique=False):
    """``target[index] += values`` with repeated indices accumulating, in index order.

    Parameters
    ----------
    target : (n, 3) float
    index : (k,) int or None
        Rows of ``target``; None means all rows in order (``k == n``).
    values : (k, 3) float
    unique : bool
        The caller guarantees no repeated index (e.g. camera rays, one per sample), so a
        plain fancy-index add gives the same sums as the much slower ``np.add.at``.
    """
    if index is None:
        target += values
    elif unique:
        _add_rows(target, index, values)
    else:
        for c in range(target.shape[1]):
            np.add.at(target[:, c], index, values[:, c])


def _add_rows(target, rows, values):
    """``target[rows] += values`` for distinct ``rows`` (None: all rows); returns ``target``.

    Column by column, so a component-major ``target`` is updated along contiguous columns.
    """
    if rows is None:
        target += values
    else:
        # one pass without temporaries (a NumPy fancy-index add gathers, adds and
        # scatters each column)
        add_rows(target, rows, values)
    return target


class _Clock:
    """Adds the time since the previous lap to a named stage."""

    __slots__ = ("seconds", "last")

    def __init__(self, seconds):
        self.seconds = seconds
        self.last = time.perf_counter()

    def lap(self, stage):
        now = time.perf_counter()
        self.seconds[stage] += now - self.last
        self.last = now


def render(scene, settings, progress=None):
    """Render ``scene`` with ``settings``; see :meth:`Integrator.render`."""
    return Integrator(scene, settings).render(progress)
