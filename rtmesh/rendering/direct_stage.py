"""The fused direct-lighting stage: from film samples to radiance in compiled code.

For scenes that need nothing but camera rays, surfaces, emission, ambient light and
point-like lights with hard shadows (the common case of asset thumbnails and of the peer
benchmark), the general wavefront (one NumPy call or kernel per stage and chunk, with the
rays and surface records written out between them) spends most of its non-tracing time
moving those records through memory.  Here one kernel does a whole chunk, in blocks of
64 samples (four 16-wide packets): sample positions, camera rays, ``rtcIntersect16``,
surface records, and for each light the shadow rays of the lit samples through
``rtcOccluded16``; the rays and records of a block never leave the kernel's scratch arrays.

The arithmetic is the general path's, row for row: the same row helpers
(:mod:`rtmesh.scene.camera_rays`, :mod:`rtmesh.shading.surfaces`,
:mod:`rtmesh.lights.point_light_rows`, :mod:`rtmesh.materials.blinn_phong`,
:mod:`rtmesh.geometry.float32_rays` for the origin offset) and those of
:mod:`rtmesh.geometry.embree_packets` (lanes of a packet), in the same order, so the images are
bit-identical to the general path's (tested).  Highlight cosines are raised with the one
pow both paths call (:func:`rtmesh.materials.blinn_phong.raise_highlight`).

:meth:`DirectStage.plan` decides whether a render can use the stage; everything it does not
handle (textures, passes, reflection and refraction, media, area lights, ambient
occlusion, depth of field, motion blur, cut-outs, environment backgrounds, single-ray
tracing) keeps the general path.

A chunk is described by its pixels and their sample counts, not by per-sample index arrays:
the kernel forms each block's pixel and sample indices itself, and with a film
(:meth:`DirectStage.render`) adds each sample to its pixel's sums as it is formed
(:func:`rtmesh.rendering.film_sums.pixel_sums` and :func:`~rtmesh.rendering.film_sums.store_pixel`:
the sums :meth:`Film.add_tile` forms, in sample order) instead of returning the samples for
a separate pass.
"""

import numpy as np
from numba import types

from rtmesh.core.compile_ahead import KernelGroup, compile_for
from rtmesh.core.compiled import kernel
from rtmesh.core.rays import kernel_input
from rtmesh.core.row_vectors import floor_quotient
from rtmesh.geometry import embree_packets as ep
from rtmesh.geometry.embree_library import packet_library
from rtmesh.geometry.accel import Accel
from rtmesh.lights.point_light_rows import ROW
from rtmesh.rendering.direct_blocks import (BLOCK, LANES, add_light_row, block_scratch, camera_block,
                                            camera_numbers, lens_camera_block, light_block, radiance_block,
                                            surface_block, write_rays)
from rtmesh.materials.blinn_phong import raise_highlight
from rtmesh.rendering.film_sums import pixel_errors
from rtmesh.sampling.pixel_samples import PixelSampler, pixel_keys
from rtmesh.scene.background import SolidBackground
from rtmesh.shading.direct_light import SHADOW_SHORTEN, highlight_to_raise

# "no film": direct_samples returns the radiance without adding it anywhere
_NO_SUMS = np.zeros((3, 0))
_NO_COUNT = np.zeros(0, dtype=np.int64)
_NO_IMAGE = np.zeros((0, 3), dtype=np.float32)
# "the chunk's pixels are a run from first_pixel" for direct_samples
_NO_PIXELS = np.zeros(0, dtype=np.int64)
_NO_LENS = np.zeros((0, 2))  # a pinhole camera
# float64 words of a light row
ROW_WORDS = ROW.itemsize // 8


_F64, _F64_2D, _I64 = types.float64[::1], types.float64[:, ::1], types.int64[::1]
_CAMERA_BLOCK = (types.int64, types.uint64[::1], _F64_2D, _F64, types.int64, types.int64, types.int64,
                 types.uint64[::1], types.uint64[:, ::1], _F64, _F64, types.UniTuple(types.float64, 13), _F64_2D,
                 _F64_2D, types.float32[::1])
# the steps direct_samples calls, each a kernel of its own (cached apart from it, so that a
# first run can compile them in two processes, see rtmesh.core.compile_ahead)
# What the fused stage renders (RenderPlan's names): camera rays from a pinhole or a thin
# lens, over surfaces flat or smooth, lit by ambient light, emission seen and point-like
# lights with hard shadows, Blinn-Phong highlights, over a solid background; every other
# render is the path kernel's (the same Whitted model in its Whitted configuration).
# DirectStage.plan checks the rest of what a render needs that no plan flag names (the
# camera, the background, the lights' compiled rows, the traversal).
FUSED_CAN_RENDER = frozenset({"emission", "ambient", "lights", "specular", "smooth_normals", "background", "lens"})

FUSED_KERNELS = KernelGroup(__name__, "fused direct", [
    (block_scratch, (_F64, types.int64)),
    (camera_block, _CAMERA_BLOCK),
    (lens_camera_block, _CAMERA_BLOCK + (_F64_2D, types.UniTuple(types.float64, 4), _F64_2D)),
    (surface_block, (_F64_2D, _I64, _I64, _F64_2D, _F64_2D, types.boolean[::1], _F64_2D, types.int64,
                     types.boolean)),
    (light_block, (_F64, _F64_2D, _F64_2D, types.int64, types.float32, types.float64, types.boolean)),
    (write_rays, (types.float32[:, ::1], types.float32[::1])),
    (radiance_block, (_F64_2D, types.int64, types.int64, _F64_2D, _F64, _I64, types.boolean[::1], _F64_2D, _I64,
                      types.boolean[::1], _I64, types.int64, _I64, _F64_2D, _F64_2D, _I64, types.float32[:, ::1],
                      _F64, _I64)),
    # the per-pixel error of the film, after the chunks
    (pixel_errors, (types.float64[::1, :], types.float64[::1, :], _I64, types.int64, types.int64, types.float64,
                    types.boolean)),
])


class DirectStage:
    """The tables the fused kernel reads, formed once per render.

    Build it with :meth:`plan`.
    """

    def __init__(self, integrator):
        FUSED_KERNELS.prepare()
        # the kinds of call (with or without a film) direct_samples is ready for
        self._compiled = set()
        it = integrator
        accel = it.accel
        m = it.scene.materials
        library = packet_library()
        self._queries = (library.intersect, library.occluded, accel._shared.handle,
                         ep.RTC_RAY_QUERY_FLAG_COHERENT)
        camera, s = it.camera, it.settings
        forward, right, up = it.camera_frame
        position = np.ascontiguousarray(camera.position, dtype=np.float64)
        self._camera = (s.width, camera.image_plane(s.width, s.height), position, forward, right, up)
        self._focus = float(camera.focus)
        st = it.plan
        self._surfaces = (it.tables.faces, it.tables.vertex_normals, it.tables.smooth, it.tables.material_id,
                          st.smooth_normals and not st.normal_maps)
        # emission + ambient per material, as the general path adds them per hit
        base = np.zeros((len(m.diffuse), 3))
        if st.emission:
            base = np.ascontiguousarray(m.emission, dtype=np.float64)
        if st.ambient:
            ambient = np.ascontiguousarray(it.tables.ambient_light)
            base = ambient if not st.emission else base + ambient
        self._base = kernel_input(base, np.float64)
        rows = [light.kernel_row() for light in it.lights] if st.lights else []
        self._lights = np.array(rows, dtype=np.float64).reshape(len(rows), ROW_WORDS)
        self._materials = (np.ascontiguousarray(it.tables.shaded), np.ascontiguousarray(it.tables.diffuse),
                           np.ascontiguousarray(it.tables.specular), it.tables.highlight_exponent, it.tables.highlight_from)
        # no material with a highlight: the light step forms no highlight cosines
        self._highlights = bool((it.tables.shaded & (it.tables.highlight_exponent >= 0.0)).any())
        background = it.background
        self._background = kernel_input(background.colour, np.float64) if st.background else np.zeros(3)
        self._offset_scale = it.tables.offset_scale32
        # the sample positions are formed in the kernel
        sampler = PixelSampler.for_settings(s)
        self._sampler_arrays = (sampler.code, sampler.keys, sampler.corners, sampler.size, sampler.spp)

    @classmethod
    def plan(cls, integrator):
        """The stage for this render, or None where the general path must run.

        Parameters
        ----------
        integrator : rtmesh.rendering.integrator.Integrator
            After its tables and stages are formed.

        Returns
        -------
        DirectStage or None
        """
        it = integrator
        st = it.plan
        # what the scene needs beyond what the stage can render (a plan flag added later
        # for a new feature is beyond it until the stage learns it)
        if st.needs() - FUSED_CAN_RENDER:
            return None
        if type(it.accel) is not Accel or not it.accel.packets or it.media is not None or it.instances is not None:
            return None
        if it.camera.orthographic:  # the fused camera step forms pinhole or thin-lens rays
            return None
        # lights without a compiled row are evaluated by the general path
        if st.lights and any(light.kernel_row() is None for light in it.lights):
            return None
        background = it.background
        if st.background and not (isinstance(background, SolidBackground) and not background.transparent):
            return None
        return cls(integrator)

    def render(self, pixels, first_sample, spp, stats, film=None, lens=None):
        """Radiance of the samples of a chunk of pixels, or those samples added to a film.

        Parameters
        ----------
        pixels : range or (m,) int array
            Linear pixel indices (a range of step 1: a run of consecutive pixels).
        first_sample : int or (m,) int array
            Index of each pixel's first sample (global across adaptive rounds).
        spp : int or (m,) int array
            Samples of each pixel (one for all, or per pixel).
        stats : RenderStats
            Camera and shadow ray counts are added to it.
        film : Film, optional
            Without passes.  The kernel adds each pixel's samples to it (sums in sample
            order, count, and the image of a ``one_pass`` film) as it finishes the pixel,
            while they are in the cache, instead of a pass over the chunk's radiance after
            it (:meth:`Film.add_tile`, :meth:`Film.add_samples` form the same sums).
        lens : (n, 2) float64, optional
            A thin lens's point on the aperture for each sample, pixel by pixel in sample
            order (:meth:`rtmesh.scene.camera.Camera.lens_disk`); None for a pinhole.

        Returns
        -------
        (n, 3) float64 or None
            Radiance of every sample, pixel by pixel in sample order, row-major; None when
            added to ``film``.
        """
        if isinstance(pixels, range) and pixels.step == 1:
            pixel_list, first_pixel, m = _NO_PIXELS, pixels.start, len(pixels)
        else:
            pixel_list = kernel_input(pixels, np.int64)
            first_pixel, m = 0, len(pixel_list)
        # one number for all pixels travels as an array of one
        # (writeable arrays, as the kernel was compiled for: kernel_input)
        first = kernel_input(np.atleast_1d(first_sample), np.int64)
        counts = kernel_input(np.atleast_1d(spp), np.int64)
        n = m * int(counts[0]) if len(counts) == 1 else int(counts.sum())
        sums = (_NO_SUMS, _NO_SUMS, _NO_COUNT, _NO_IMAGE) if film is None else film.kernel_arrays()
        args = (*self._queries, *self._sampler_arrays, pixel_list, first_pixel, first, counts, n, *sums,
                *self._camera, _NO_LENS if lens is None else kernel_input(lens, np.float64), self._focus,
                *self._surfaces, self._base, self._background, self._lights, *self._materials,
                self._offset_scale, SHADOW_SHORTEN, self._highlights)
        if (film is None) not in self._compiled:
            # its steps are FUSED_KERNELS; the kernel around them is compiled (or loaded) under
            # its lock file too, once per process and kind of call
            compile_for(direct_samples, args)
            self._compiled.add(film is None)
        radiance, shadow_rays = direct_samples(*args)
        stats.rays["camera"] += n
        stats.rays["shadow"] += shadow_rays
        return None if film is not None else radiance


@kernel
def direct_samples(intersect, occluded, scene, flags, sampler, keys, corners, size, spp,
                   pixel_list, first_pixel, first, counts, n, total, total_sq, film_count, image,
                   width, image_plane, position, forward, right, up, lens, focus, faces, vertex_normals, smooth,
                   material_id, fix_terminator, base, background, lights, shaded, diffuse, specular, exponent,
                   visible_from, scale, shorten, highlights):
    """Radiance of the camera samples of a chunk of pixels with direct light, in blocks of
    :data:`BLOCK` samples, added to the film pixel by pixel where one is given.

    Parameters
    ----------
    intersect, occluded : ctypes function objects
    scene : int
        The committed ``RTCScene``.
    flags : int
        Query flags (coherent).
    sampler, keys, corners, size, spp
        The :class:`rtmesh.sampling.pixel_samples.PixelSampler` arrays.
    pixel_list : (m,) int64 or (0,)
        The chunk's ``m`` pixels; empty: a run of pixels from ``first_pixel`` on (as many as
        ``counts`` and ``n`` take).
    first_pixel : int
        The first pixel of a run.
    first, counts : (m,) int64 or (1,)
        Index of each pixel's first sample and its number of samples (one entry: the same
        for every pixel).  The samples are taken pixel by pixel in sample order, so each
        pixel's samples are ``n`` consecutive rows; no per-sample pixel and sample index
        arrays are made (the block's are formed here).
    n : int
        Samples in all.
    total, total_sq, film_count, image
        The film's arrays (:meth:`rtmesh.rendering.film.Film.kernel_arrays`), or empty
        ((3, 0), (3, 0), (0,), (0, 3)): no film.  With a film, each sample is added to
        its pixel's sums (:func:`rtmesh.rendering.film_sums.pixel_sums`), which are stored
        (:func:`rtmesh.rendering.film_sums.store_pixel`) when the pixel's last sample is in.
    width : int
    image_plane : (4,) float64
    position, forward, right, up : (3,) float64
        The camera (see :func:`rtmesh.scene.camera_rays.camera_rays`).
    lens : (n, 2) float64 or (0, 2)
        A thin lens's point on the aperture for each of the ``n`` samples, in their order
        (:meth:`rtmesh.scene.camera.Camera.lens_disk`); empty for a pinhole.
    focus : float
        The focus distance (a thin lens's rays, :func:`rtmesh.rendering.direct_blocks.lens_camera_block`).
    faces, vertex_normals, smooth, material_id, fix_terminator
        As for :func:`rtmesh.shading.surfaces.surface_records`.
    base : (M, 3) float64
        Emission plus ambient light per material.
    background : (3,) float64
        Radiance of rays that miss.
    lights : (L, 12) float64
        Point-like lights' rows (:func:`rtmesh.lights.point_light_rows.pack_row`).
    shaded : (M,) bool
        Materials that reflect light.
    diffuse, specular : (M, 3) float64
    exponent, visible_from : (M,) float64
        Shininess (negative: no highlight) and the smallest highlight cosine kept.
    scale : float32
        Scene size, for the origin offset.
    shorten : float
        Shadow rays end this fraction of the way to the light.
    highlights : bool
        Whether a material has a highlight (``shaded`` and ``exponent >= 0``); without,
        no highlight cosine is formed.

    Returns
    -------
    radiance : (n, 3) or, with a film, (0, 3) float64
        Row-major.
    shadow_rays : int

    Notes
    -----
    Misses are computed on face 0 and ignored, so the steps of a block loop over its samples
    without early exits.  LLVM vectorises the hashing and arithmetic of the camera rays,
    the surface records with their table reads, the light samples, the stores into the
    packets and the Blinn-Phong sums (:func:`camera_block`, :func:`surface_block`,
    :func:`light_block`, :func:`write_rays`); what is formed once per pixel, the hit ids
    read back from the packets and the highlight powers (libm's pow) stay scalar.  The
    packets of a block lie side by side in one buffer (each 64-byte aligned), and sample
    ``b`` of the block is lane ``b % 16`` of packet ``b // 16``.
    """
    n_lights = len(lights)
    adding = len(film_count) > 0
    has_smooth = len(vertex_normals) > 0
    # row-major, so that the integrator's (pixels, spp, 3) view of it is not a copy
    # (no rows when the samples go to the film)
    radiance = np.empty((0 if adding else n, 3))
    # the packets (their constant lanes written) and the per-sample scratch of a block
    (rays, words, valid, args, shadow, shadow_words, shadow_valid, barycentrics, face, normal_row, interpolate,
     mat, hit, xy, d, sample, sequence, column, line, cosine, raised, power, reaches, receives, shininess,
     highlight_from, direct) = block_scratch(position, flags)
    normals = vertex_normals if has_smooth else np.zeros((1, 9))
    # (per-pixel arrays are indexed here, not through a row helper: numba would take and
    # release a reference to the array on every call, two atomic instructions per sample)
    one_count, one_first, listed = len(counts) == 1, len(first) == 1, len(pixel_list) > 0
    # the pixel being taken (its place in the chunk, index, next sample, samples left)
    current, px, px_sample, left = -1, 0, 0, 0
    sequence0 = sequence1 = np.uint64(0)
    px_column = px_line = 0.0
    inverse_width = 1.0 / width
    # each sample's pixel (its place in the chunk) and whether it is the pixel's last; the
    # pixel being added to the film across blocks (radiance_block)
    owner, last = np.empty(BLOCK, np.int64), np.empty(BLOCK, np.bool_)
    sums, state = np.zeros(6), np.full(2, -1, np.int64)
    shadow_rays = 0
    camera = camera_numbers(image_plane, forward, right, up)
    origins = np.empty((3, BLOCK))  # a thin lens's, per block
    eye = (position[0], position[1], position[2], focus)
    for start in range(0, n, BLOCK):
        count = min(BLOCK, n - start)
        # the block's samples, pixel by pixel in sample order
        b = 0
        while b < count:
            if left == 0:  # the next pixel with samples
                current += 1
                left = counts[0] if one_count else counts[current]
                px_sample = first[0] if one_first else first[current]
                px = pixel_list[current] if listed else first_pixel + current
                sequence0, sequence1 = pixel_keys(sampler, keys, px)
                px_row = floor_quotient(px, width, inverse_width)
                px_column, px_line = np.float64(px - px_row * width), np.float64(px_row)
                continue
            run = min(left, count - b)
            for j in range(run):
                owner[b + j], last[b + j] = current, j == left - 1
                sample[b + j] = np.uint64(px_sample + j)
                sequence[0, b + j], sequence[1, b + j] = sequence0, sequence1
                column[b + j], line[b + j] = px_column, px_line
            px_sample += run
            left -= run
            b += run
        # camera rays (rtmesh.scene.camera_rays.camera_rays, pinhole or thin lens) into the
        # packets; lanes past the end repeat sample 0
        if len(lens):
            lens_camera_block(sampler, keys, corners, size, spp, start, count, sample, sequence, column, line,
                              camera, xy, d, rays, lens, eye, origins)
        else:
            camera_block(sampler, keys, corners, size, spp, start, count, sample, sequence, column, line, camera,
                         xy, d, rays)
        for b in range(BLOCK):
            valid[b] = -1 if b < count else 0
        for b in range(BLOCK):
            ep.clear_hit(words, b)
        for q in range((count + LANES - 1) // LANES):
            ep.query_packet(intersect, scene, valid, rays, args, q)
        # surface records (rtmesh.shading.surfaces.surface_records): the rows of the faces hit (misses use
        # face 0) are gathered first, then one loop does the arithmetic (surface_block)
        for b in range(count):
            hit[b] = words[ep.lane_word(ep.GEOM_ID, b)] != -1
            f = np.intp(words[ep.lane_word(ep.PRIM_ID, b)]) if hit[b] else np.intp(0)
            mat[b] = material_id[f]
            receives[b] = hit[b] and shaded[mat[b]]
            shininess[b], highlight_from[b] = exponent[mat[b]], visible_from[mat[b]]
            interpolate[b] = has_smooth and smooth[f]
            barycentrics[0, b] = np.float64(rays[ep.lane_word(ep.U, b)])
            barycentrics[1, b] = np.float64(rays[ep.lane_word(ep.V, b)])
            face[b], normal_row[b] = f, f if has_smooth else 0
        srf = surface_block(barycentrics, face, normal_row, faces, normals, interpolate, d, count, fix_terminator)
        # each light in turn: its samples (rtmesh.shading.direct_light.light_samples), the shadow
        # packets, and its term added to the direct light (add_light's order: light by light)
        for b in range(BLOCK):
            direct[0, b] = direct[1, b] = direct[2, b] = 0.0
        for k in range(n_lights):
            lit, values, shadow_ray = light_block(lights[k], srf, d, count, scale, shorten, highlights)
            write_rays(shadow_ray, shadow)
            # branch-free, so that LLVM vectorises it: what the light is not on for is
            # formed but never added
            for b in range(BLOCK):
                on = (b < count) & receives[b] & lit[b]
                shadow_valid[b] = -np.int32(on)
                cosine[b], raise_it = highlight_to_raise(shininess[b], values[4, b], highlight_from[b])
                raised[b] = on & raise_it
            for q in range((count + LANES - 1) // LANES):
                ep.query_packet(occluded, scene, shadow_valid, shadow, args, q)
            for group in range(BLOCK // ep.GROUP):
                at = group * ep.GROUP_WORDS + ep.TFAR * ep.GROUP
                for lane in range(ep.GROUP):
                    b = group * ep.GROUP + lane
                    on = shadow_valid[b] != 0
                    shadow_rays += on
                    # Embree marks an occluded ray by setting its tfar to -inf
                    reaches[b] = on & (shadow[at + lane] != -np.inf)
            # the highlights (pow is a call of libm's: a loop of its own, over the few samples
            # that have one; the general path raises them with the same pow)
            if highlights:
                for b in range(count):
                    power[b] = raise_highlight(cosine[b], shininess[b]) if reaches[b] and raised[b] else 0.0
            for b in range(count):
                mat_b = mat[b]
                d0, d1, d2 = add_light_row(direct[0, b], direct[1, b], direct[2, b], diffuse[mat_b, 0],
                                           diffuse[mat_b, 1], diffuse[mat_b, 2], specular[mat_b, 0], specular[mat_b, 1],
                                           specular[mat_b, 2], values[0, b], power[b], values[1, b], values[2, b],
                                           values[3, b])
                if reaches[b]:
                    direct[0, b], direct[1, b], direct[2, b] = d0, d1, d2
        # emission and ambient light plus the direct light, into the radiance rows or the film
        radiance_block(radiance, start, count, base, background, mat, hit, direct, owner, last, pixel_list,
                       first_pixel, counts, total, total_sq, film_count, image, sums, state)
    return radiance, shadow_rays
