"""One view of a built scene, rendered: the integrator.

:class:`Integrator` renders a view (camera, lights, background, passes) of a
:class:`~rtmesh.rendering.built_scene.BuiltScene` (the scene's Embree scene and tables,
built once; :meth:`Integrator.with_view` renders another view of the same build).  A render
is one or more rounds (:mod:`~rtmesh.rendering.adaptive`) of chunks of whole pixels on
threads (:mod:`~rtmesh.rendering.scheduler`); each chunk goes to one of three stages:

- the path kernel (:mod:`~rtmesh.rendering.path_stage`, :mod:`~rtmesh.rendering.path_kernel`):
  every ``integrator = "path"`` render, and every Whitted render the fused stage does not
  take, in the kernel's Whitted configuration (:mod:`~rtmesh.rendering.whitted_rows`);
- the fused direct-lighting stage (:mod:`~rtmesh.rendering.direct_stage`): Whitted scenes
  that need only direct light from point-like lights;
- a reference stage (:data:`REFERENCE_STAGE`): the tests' NumPy wavefront
  (``tests/wavefront``), which renders Whitted scenes a depth level at a time as the
  kernel's reference.  What the kernel cannot render (without Embree's packet queries,
  lights without compiled rows) is refused in one line.

Every random number is a function of (seed, pixel, sample, dimension), each pixel is
rendered whole inside one chunk, and the chunks do not depend on the thread count (see
:mod:`rtmesh.rendering.scheduler`), so the image is bit-identical whatever the thread count.

Before rendering, :class:`Integrator` looks at the scene and the settings and enables only
the stages that can contribute (see :attr:`Integrator.plan`).  Building and running it
changes no process-wide state: the tuning for rendering processes (allocator, GIL switch
interval, kept thread pools) is :mod:`rtmesh.core.runtime`'s, turned on by the programs that
own their process.
"""

import dataclasses
import logging
import time

import numpy as np

from rtmesh.core import runtime
from rtmesh.core.rays import kernel_input
from rtmesh.geometry.motion import object_motions
from rtmesh.io import denoising
from rtmesh.io.passes import DERIVED_PASSES, PassRecorder, derived_pass
from rtmesh.lights.area_lights import is_area_light
from rtmesh.rendering.adaptive import render_rounds
from rtmesh.rendering.built_scene import BuiltScene
from rtmesh.rendering.centre_rays import centre_passes
from rtmesh.rendering.chunk_state import Clock
from rtmesh.rendering.direct_stage import DirectStage
from rtmesh.rendering.film import Film
from rtmesh.rendering.media import Media
from rtmesh.rendering.path_stage import PathStage, unsupported_lights
from rtmesh.rendering.render_plan import RenderPlan
from rtmesh.rendering.render_result import RenderResult
from rtmesh.rendering.scheduler import pixel_chunks, run_on_threads, sample_indices
from rtmesh.rendering.stats import RenderStats
from rtmesh.rendering.surface_stage import SurfaceStage
from rtmesh.sampling.pixel_samples import PixelSampler, pixel_positions
from rtmesh.sampling.sampler import Sampler
from rtmesh.scene import instances
from rtmesh.scene.background import as_background

log = logging.getLogger(__name__)


# Whitted renders that the fused stage does not take go through the path kernel configured as
# the Whitted integrator (rtmesh.rendering.whitted_rows).  Tests set this to a stage of their
# own (``REFERENCE_STAGE(integrator)`` -> an object whose ``render`` takes a chunk's samples as
# Integrator.render_chunk hands them over): the NumPy wavefront of tests/wavefront, the
# kernel's reference (its images within noise of the kernel's: tests/rendering/test_whitted_kernel.py).
REFERENCE_STAGE = None


def _translated(obj, shift):
    """A copy of a camera or light moved by ``-shift`` (directions are unchanged)."""
    changes = {}
    for name in ("position", "look_at"):
        if hasattr(obj, name):
            changes[name] = getattr(obj, name) - shift
    return dataclasses.replace(obj, **changes) if changes else obj


class Integrator:
    """Renders one view of a scene with one set of settings.

    Parameters
    ----------
    scene : Scene
    settings : RenderSettings
    built : BuiltScene, optional
        The scene as built for another view (:meth:`with_view`): ``scene`` is then that
        build's scene with this view's camera, lights and background.  Default: built here.

    Attributes
    ----------
    plan : RenderPlan
        Which optional stages this scene and these settings need.
    scene_bounds : (2, 3) float
        ``scene.bounds`` (world units), formed once for the built scene and its views.
    """

    def __init__(self, scene, settings, built=None):
        self.settings = settings.validate()
        self.sampler = Sampler.for_settings(self.settings)
        self.pixel_sampler = PixelSampler.for_settings(self.settings)
        if built is None:
            built = BuiltScene(scene, self.settings, self.sampler, self._flattening_reasons(scene))
            scene = built.scene
        self.built = built
        # the build's tables, read by the stages as the integrator's own
        self.scene = scene
        self.scene_bounds, self.shift, self.motion, self.instances = (built.scene_bounds, built.shift, built.motion,
                                                                      built.instances)
        self.accel, self.offset_scale, self.textures, self.cutouts = (built.accel, built.offset_scale, built.textures,
                                                                      built.cutouts)
        self.ao_distance, self.ao_samples, self.tables = built.ao_distance, built.ao_samples, built.tables
        self._set_background(scene.background)
        self._set_view()

    def _flattening_reasons(self, scene):
        """Why ``scene``'s placements cannot be traced as Embree instances under these
        settings (phrases; empty when they can be, or when there are none)."""
        if scene.instances is None:
            return []
        missing = instances.unsupported(scene, self.settings)
        if self.settings.integrator == "whitted":
            # Whitted renders trace instances through the path kernel's Whitted configuration
            if REFERENCE_STAGE is not None:
                missing.append("integrator 'whitted' through the reference wavefront")
            missing.extend(unsupported_lights(scene.lights))
        return missing

    def _set_background(self, background):
        """The background rays see and, when it lights the scene, its light sampler (the
        build's, :meth:`BuiltScene.environment_lighting`)."""
        self.background = as_background(background)
        self.environment_lighting = self.built.environment_lighting(self.background, background)

    def with_view(self, camera, lights=None, background=None):
        """The same built scene seen from another camera (and lit by other lights).

        The Embree scene, textures, per-face tables and everything else that depends only
        on the geometry and materials are shared with this integrator; only what depends on
        the camera and the lights (rays, passes, light tables, the camera's media, the
        stages) is formed again, so N views of one asset cost one build and N renders.  The
        image is the one ``Integrator(scene with that camera and lights, settings)`` renders.

        Parameters
        ----------
        camera : Camera
            In the scene's own (world) frame.
        lights : list, optional
            Default: the scene's lights.
        background : background object, optional
            Default: the scene's background (and its light sampler) is kept.

        Returns
        -------
        Integrator

        Raises
        ------
        ValueError
            The scene has moving objects and ``camera``'s shutter differs from the built
            one's (the built geometry depends on the shutter).
        """
        if object_motions(self.scene) and tuple(camera.shutter) != tuple(self.scene.camera.shutter):
            raise ValueError("with_view: a scene with moving objects needs the built camera's shutter")
        scene = self.built.scene
        view = dataclasses.replace(scene, camera=camera, lights=list(self.scene.lights if lights is None else lights),
                                   background=self.scene.background if background is None else background)
        return Integrator(view, self.settings, self.built)

    def _set_view(self):
        """Form what depends on the camera and the lights (after the geometry's tables)."""
        scene, settings, m = self.scene, self.settings, self.scene.materials
        self.camera = _translated(scene.camera, self.shift)
        # formed once (and failing early on a degenerate camera), not for every chunk
        self.camera_frame = self.camera.frame()
        lights = [_translated(light, self.shift) for light in scene.lights if not light.is_black]
        self.view_lights = lights
        self.lights = [light for light in lights if not is_area_light(light)]
        self.area_lights = [light for light in lights if is_area_light(light)]
        shaded_any = self.built.shaded_any
        # only the passes asked for are computed; a transparent background needs coverage;
        # the denoiser's guides are computed even when they are not written
        guides = ("albedo", "normal") if settings.denoise else ()
        self.passes = PassRecorder(scene, tuple(settings.passes) + ("alpha",) * self.background.transparent
                                   + guides, self.camera, self.shift)
        self.plan = RenderPlan(
            emission=m.any_emission,
            ambient=self.built.ambient_on,
            lights=bool(self.lights) and shaded_any,
            area_lights=(bool(self.area_lights) or self.built.emits) and shaded_any,
            area_light_visibility=any(light.visible for light in self.area_lights),
            environment_lighting=self.environment_lighting is not None and shaded_any,
            specular=m.any_specular,
            smooth_normals=scene.vertex_normals is not None,
            textures=bool(self.textures),
            normal_maps=self.textures.tangents is not None,
            cutouts=self.cutouts is not None,
            unlit=m.any_unlit,
            physical=m.any_physical,
            reflection=settings.max_depth > 0 and (m.any_mirror or m.any_transmission or m.any_physical),
            glossy=settings.max_depth > 0 and m.any_glossy,
            refraction=settings.max_depth > 0 and m.any_transmission,
            absorption=m.any_absorption,
            background=not self.background.is_black,
            passes=bool(self.passes),
            ao=self.ao_samples > 0 and (self.built.ambient_on or "ao" in settings.passes),
            lens=self.camera.aperture > 0.0,
            motion=self.motion is not None,
        )
        self._init_media()
        # surface records of the centre passes' rays (and of the general wavefront's hits)
        self.surface_stage = SurfaceStage(self)
        # the path integrator: one compiled kernel per chunk (rtmesh.rendering.path_stage)
        self.path_stage = PathStage(self) if settings.integrator == "path" else None
        # scenes that need only direct light take one compiled stage per chunk
        self.direct_stage = DirectStage.plan(self) if self.path_stage is None else None
        self.wavefront = None
        if self.direct_stage is None and self.path_stage is None:
            if REFERENCE_STAGE is None:
                # the others the path kernel, configured as the Whitted integrator (a
                # SceneError for what it cannot render)
                self.path_stage = PathStage(self)
            else:
                self.wavefront = REFERENCE_STAGE(self)  # the kernel's test reference
        self.plan = dataclasses.replace(self.plan, fused_direct=self.direct_stage is not None)

    def _init_media(self):
        """Medium stacks (see :mod:`rtmesh.rendering.media`), only for scenes that refract.

        Sets ``media`` (None without transmissive materials), ``_camera_medium`` (the
        camera's stack, ``(STACK_DEPTH,)``; ``(0,)`` without media), ``_camera_absorbs``
        (camera rays lose light before their first hit, so their throughput is not 1) and
        ``_absorbing_medium`` (bool by medium id, the last entry, -1, for the outside).
        """
        self.media = self.built.media  # the build's: they depend on the geometry alone
        self._camera_medium = np.zeros(0, dtype=np.int32)
        self._camera_absorbs = False
        self._absorbing_medium = np.zeros(1, dtype=bool)
        if self.media is None:
            return
        self._absorbing_medium = (self.media.absorption > 0).any(axis=1)
        self._camera_medium = self._camera_stack(self.media)
        self._camera_absorbs = bool((self.media.absorption[self._camera_medium[0]] > 0).any())

    def media_of(self, refracts):
        """The medium tables (:class:`rtmesh.rendering.media.Media`) counting as media the
        materials ``refracts`` marks (the path integrator's transmissive models, which
        include some without a Whitted transmission colour): Whitted's own ``media`` when
        they are the same materials, else tables built once for them.

        Parameters
        ----------
        refracts : (M,) bool

        Returns
        -------
        Media
        """
        groups = np.flatnonzero(refracts)
        if self.media is not None and np.array_equal(self.media.group_material, groups):
            return self.media
        if self.built.path_media is None or not np.array_equal(self.built.path_media.group_material, groups):
            scene = self.scene
            self.built.path_media = Media(scene.materials, scene.material_id, scene.vertices, scene.faces,
                                          scene.face_normals, refracts, self.instances)
        return self.built.path_media

    def camera_media(self, refracts):
        """The media the camera sits in, counting as media the materials ``refracts`` marks
        (:meth:`media_of`).

        Parameters
        ----------
        refracts : (M,) bool

        Returns
        -------
        (STACK_DEPTH,) int32
            Material ids, innermost first, -1 padded.
        """
        media = self.media_of(refracts)
        if media is self.media:
            return self._camera_medium  # the same media as Whitted's: their stack, probed once
        return self._camera_stack(media)

    def _camera_stack(self, media):
        """``media.camera_stack`` from the camera's position, probing the scene as it is when
        the shutter opens."""
        if self.motion is None:
            return media.camera_stack(self.accel.intersect, self.camera.position, self.offset_scale, None)

        def at_open(n):
            return np.full(n, self.camera.shutter[0])

        def trace(origins, directions):
            return self.accel.intersect(origins, directions, at_open(len(origins)))

        def to_rest(prim, directions):
            return self.motion.directions_to_rest(prim, at_open(len(prim)), directions)

        return media.camera_stack(trace, self.camera.position, self.offset_scale, to_rest)

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
        # without later rounds every pixel is added once, and its image value with it
        film = Film(s.width, s.height, self.passes.film_passes(), one_pass=not (s.adaptive or self._photon_passes))
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
        # a uniform render gives every pixel spp samples: below two there is no estimate,
        # and the film need not be scanned for its smallest count to say so
        stats.relative_error = (float("nan") if not s.adaptive and s.spp < 2 else film.relative_error())
        passes = {name: film.pass_image(name) for name in film.pass_sums if name in s.passes}
        passes.update({name: derived_pass(name, film) for name in s.passes if name in DERIVED_PASSES})
        passes.update(centre_passes(self, s.passes))  # exact labels: one pixel-centre ray each
        passes = {name: passes[name] for name in s.passes if name in passes}  # order asked for
        alpha = film.pass_image("alpha") if self.background.transparent else None
        noisy = None
        if s.denoise:
            noisy = image
            # the guides average each pixel's camera hits: noise-free unless those are random
            clean = not (self.plan.lens or self.plan.motion or self.built.stochastic_coverage)
            image = denoising.denoise(image, film.pass_image("albedo"), film.pass_image("normal"), clean)
            stats.wall_seconds = time.perf_counter() - start
        return RenderResult(image, passes, stats, film, alpha, noisy, self.settings)

    @property
    def _photon_passes(self):
        """Whether the render runs photon passes (caustics, :mod:`rtmesh.rendering.caustics`)."""
        return self.path_stage is not None and self.path_stage.caustics.enabled

    def render_samples(self, film, pixels, first_sample, spp, stats, progress=None, pool=None):
        """Render samples of a set of pixels into ``film``, in chunks on the threads (with photon
        passes, one pass a sample index: see :meth:`_render_photon_passes`).

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
        if self._photon_passes:
            self._render_photon_passes(film, pixels, first_sample, spp, stats, progress, pool)
            return
        self._render_batch(film, pixels, first_sample, spp, stats, progress, pool)

    def _render_photon_passes(self, film, pixels, first_sample, spp, stats, progress, pool):
        """:meth:`render_samples` with photon passes: sample index ``k`` of every pixel is
        rendered with pass ``k``'s photons, pass after pass (so each pixel's samples still
        reach the film in order, and one pass's photons exist at a time)."""
        caustics = self.path_stage.caustics
        if np.ndim(spp) == 0 and np.ndim(first_sample) == 0:
            passes = range(first_sample, first_sample + spp)
            chosen = None
        else:
            pixels = np.asarray(pixels, dtype=np.int64)
            first = np.broadcast_to(np.asarray(first_sample, dtype=np.int64), pixels.shape)
            end = first + np.broadcast_to(np.asarray(spp, dtype=np.int64), pixels.shape)
            passes = range(int(first.min()), int(end.max())) if len(pixels) else range(0)
            chosen = (first, end)
        with runtime.render_pool(self.settings.thread_count, pool) as workers:
            for k in passes:
                self.path_stage.photon_map = caustics.photon_map(k, stats, workers)
                these = pixels if chosen is None else pixels[(chosen[0] <= k) & (k < chosen[1])]
                if len(these):
                    self._render_batch(film, these, k, 1, stats, progress, workers)

    def _render_batch(self, film, pixels, first_sample, spp, stats, progress=None, pool=None):
        """:meth:`render_samples` as one batch of chunks."""
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
            radiance, passes, chunk_stats = self.render_chunk(*chunk, film=film)
            if radiance is None:  # the fused stage added the samples itself
                return chunk_stats
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
    def render_chunk(self, pixels, first_sample, spp, film=None):
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
        film : Film, optional
            The fused direct-lighting stage adds the samples to it itself, pixel by pixel
            while they are in the cache, and returns no radiance; the general path ignores
            it (the caller adds what it returns).

        Returns
        -------
        radiance : (m, spp, 3) float64, or (sum(spp), 3) with per-pixel ``spp``, or None
            Radiance of every sample, pixel by pixel in sample order (with per-pixel
            counts the samples of pixel ``i`` are rows ``sum(spp[:i]) ..``); None when
            the samples were added to ``film``.
        passes : dict of str to (m, spp, k) float64 (or (sum(spp), k)), or None
        stats : RenderStats
            Ray counts and stage times of this chunk.
        """
        stats = RenderStats()
        clock = Clock(stats.stage_seconds)
        m = len(pixels)
        # (isinstance, not np.ndim: this runs per chunk with the GIL held)
        ragged = isinstance(spp, np.ndarray) or isinstance(first_sample, np.ndarray)
        if self.direct_stage is not None:
            # the stage forms the pixel and sample index of each sample and its position itself
            # (see rtmesh.sampling.pixel_samples); a thin lens's aperture points come from here
            lens = self._aperture_points(*sample_indices(pixels, first_sample, spp)) if self.plan.lens else None
            clock.lap("camera")
            radiance = self.direct_stage.render(pixels, first_sample, spp, stats, film, lens)
            clock.lap("direct")
            if radiance is None or ragged:
                return radiance, None, stats
            return radiance.reshape(m, spp, 3), None, stats

        # camera: one ray per pixel sample
        pixel, sample_in_pixel = sample_indices(pixels, first_sample, spp)
        if self.path_stage is not None:
            return self._render_paths(pixel, sample_in_pixel, m, spp, ragged, stats, clock)
        return self.wavefront.render(pixel, sample_in_pixel, m, spp, ragged, stats, clock)

    def _camera_rays(self, pixel, sample_in_pixel):
        """Camera rays of the samples ``(pixel, sample_in_pixel)`` ((n,) each), in the re-centred
        frame, and their times in the shutter (None without moving objects).

        Returns
        -------
        origins, directions : (n, 3) float64
        sample_time : (n,) float64 or None
        """
        s = self.settings
        # every dimension is stratified in sets of the settings' spp, whatever the round; the
        # positions in the pixels by the compiled twin of Sampler.pixel (the same numbers)
        ps = self.pixel_sampler
        in_pixel = pixel_positions(ps.code, ps.keys, ps.corners, ps.size, ps.spp, kernel_input(pixel, np.int64),
                                   kernel_input(sample_in_pixel, np.int64))
        origins, directions = self.camera.generate_rays(in_pixel, s.width, s.height,
                                                        self._lens_points(pixel, sample_in_pixel), pixel,
                                                        self.camera_frame)
        return origins, directions, self._sample_times(pixel, sample_in_pixel)

    def _lens_points(self, pixel, sample_in_pixel):
        """Each camera sample's point of the sampler's lens dimension ((n, 2) in [0, 1)^2,
        before the aperture's disk warp), or None for a pinhole camera."""
        return self.sampler.lens(pixel, sample_in_pixel) if self.plan.lens else None

    def _aperture_points(self, pixel, sample_in_pixel):
        """Each camera sample's point on a thin lens's aperture ((n, 2) float64, scene units
        along the camera's right and up: :meth:`rtmesh.scene.camera.Camera.lens_disk` of
        :meth:`_lens_points`), or None for a pinhole camera."""
        lens_uv = self._lens_points(pixel, sample_in_pixel)
        return None if lens_uv is None else self.camera.lens_disk(lens_uv)

    def _sample_times(self, pixel, sample_in_pixel):
        """Each camera sample's time in the shutter ((n,) float64; one per sample, stratified
        per pixel, and its rays all inherit it), or None without moving objects."""
        if not self.plan.motion:
            return None
        t_open, t_close = self.camera.shutter
        return t_open + (t_close - t_open) * self.sampler.time(pixel, sample_in_pixel)

    def _render_paths(self, pixel, sample_in_pixel, m, spp, ragged, stats, clock):
        """:meth:`render_chunk` under the path integrator (and the Whitted configuration of
        its kernel): camera rays, then the path kernel, which writes the passes too."""
        origins = directions = lens = None
        if self.path_stage.camera_in_kernel:
            times = self._sample_times(pixel, sample_in_pixel)
            lens = self._aperture_points(pixel, sample_in_pixel)
        else:
            origins, directions, times = self._camera_rays(pixel, sample_in_pixel)
        n = len(pixel)
        clock.lap("camera")
        buffers = self.passes.buffers(n) if self.plan.passes else None
        radiance = self.path_stage.render(origins, directions, pixel, sample_in_pixel, stats, buffers, times, lens)
        clock.lap("direct")
        if ragged:
            return radiance, (self.passes.per_sample(buffers, n) or None) if buffers is not None else None, stats
        passes = (self.passes.per_pixel(buffers, m, spp) or None) if buffers is not None else None
        return radiance.reshape(m, spp, 3), passes, stats

def render(scene, settings, progress=None):
    """Render ``scene`` with ``settings``; see :meth:`Integrator.render`."""
    return Integrator(scene, settings).render(progress)
