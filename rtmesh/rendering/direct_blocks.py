"""The steps of one block of the fused direct-lighting stage, compiled.

A block is :data:`BLOCK` film samples, four packets of 16 lanes side by side (sample ``b``
is lane ``b % 16`` of packet ``b // 16``, at the words
:func:`rtmesh.geometry.embree_packets.lane_word` gives for ``b``).  Each step works on the
block's scratch arrays: the camera step (positions, then pinhole or thin-lens rays), the surface
step (gathered face rows, then the arithmetic of
:func:`rtmesh.shading.surfaces.surface_records`), the light step
(the arithmetic of :func:`rtmesh.shading.direct_light.light_samples` for one light), the
Blinn-Phong sum of one light at one sample, and the radiance step (each sample's radiance,
into the chunk's rows or its pixel's film sums).  :func:`rtmesh.rendering.direct_stage.direct_samples`
calls them in order; their loops have no branches, gathers or calls where LLVM is to
vectorise them, and outputs of the block's constant size (see :func:`light_block`).

The larger steps (:func:`block_scratch`, :func:`camera_block` or :func:`lens_camera_block`,
:func:`surface_block`, :func:`light_block`, :func:`write_rays`, :func:`radiance_block`) are
kernels, each cached on disk apart from the stage, so that a first run compiles them in two processes
(:data:`rtmesh.rendering.direct_stage.FUSED_KERNELS`); called once per block, like rows,
they cost the stage nothing measurable (peer scene, 1 and 16 spp, 1 thread;
:func:`block_scratch` runs once per chunk).
"""

import numpy as np

from rtmesh.core.compiled import inline_row, kernel, row
from rtmesh.geometry import embree_packets as ep
from rtmesh.lights.point_light_rows import KIND, POINT, illuminate_row, point_row
from rtmesh.materials.blinn_phong import blinn_phong_row
from rtmesh.rendering.film_sums import pixel_sums, store_pixel
from rtmesh.sampling.pixel_samples import sample_positions
from rtmesh.scene.camera_rays import pinhole_xyz, thin_lens_xyz
from rtmesh.shading.direct_light import light_sample
from rtmesh.shading.surfaces import surface_from_rows_inlined

LANES = ep.LANES
# samples per block: four packets, so the arithmetic of a block's samples runs in vector
# loops long enough for AVX-512, while the block's records stay in L1
PACKETS = 4
BLOCK = PACKETS * LANES


@kernel
def block_scratch(position, flags):
    """The scratch arrays of :func:`rtmesh.rendering.direct_stage.direct_samples`, for one chunk.

    A kernel of its own, cached apart from the fused stage, so that a first run compiles
    its allocations in the other process (:mod:`rtmesh.core.compile_ahead`).

    Parameters
    ----------
    position : (3,) float64
        The camera's position: the camera rays' origin, written into the packets here with
        every lane field that no query changes (the blocks write only directions, ``tfar``,
        the shadow rays' origins and the hit ids).
    flags : int
        Query flags.

    Returns
    -------
    rays, words, valid, args
        The block's ``RTCRayHit16`` packets (:func:`rtmesh.geometry.embree_packets.packet_buffers`).
    shadow, shadow_words, shadow_valid
        Its ``RTCRay16`` packets.
    barycentrics : (2, BLOCK) float64
    face, normal_row : (BLOCK,) intp
        The face hit and its row of vertex normals (:func:`surface_block`).
    interpolate : (BLOCK,) bool
    mat : (BLOCK,) intp
        Material.
    hit : (BLOCK,) bool
    xy, d : (2, BLOCK), (3, BLOCK) float64
        Positions in the pixels and camera ray directions (:func:`camera_block`).
    sample : (BLOCK,) uint64
    sequence : (2, BLOCK) uint64
    column, line : (BLOCK,) float64
        Each sample's index, and its pixel's sequence keys, column and row.
    cosine : (BLOCK,) float64
    raised : (BLOCK,) bool
    power : (BLOCK,) float64, zeros
    reaches : (BLOCK,) bool, False
        For the light being added: the highlight cosine, whether it is raised, the raised
        cosine (0 without a highlight), whether the light reaches the sample.
    receives : (BLOCK,) bool
    shininess, highlight_from : (BLOCK,) float64
        Whether lights count (a shaded surface), the material's shininess and smallest
        highlight cosine.
    direct : (3, BLOCK) float64
        The sum of the lights' terms.
    """
    rays, words, valid, args = ep.packet_buffers(np.int64(PACKETS), flags)
    shadow, shadow_words, shadow_valid, _ = ep.packet_buffers(np.int64(PACKETS), flags)
    # (a loop over len(valid), not the constant BLOCK: LLVM would unroll it, which costs
    # compile time and saves nothing in a loop run once per chunk; sample b is lane b of
    # the packets side by side, rtmesh.geometry.embree_packets.lane_word)
    for b in range(len(valid)):
        ep.set_lane(rays, words, b, position[0], position[1], position[2], 0.0, 0.0, 1.0, ep.DEFAULT_TFAR)
        ep.set_lane(shadow, shadow_words, b, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, np.float32(0.0))
    return (rays, words, valid, args, shadow, shadow_words, shadow_valid, np.empty((2, BLOCK)),
            np.empty(BLOCK, np.intp), np.empty(BLOCK, np.intp), np.empty(BLOCK, np.bool_), np.empty(BLOCK, np.intp),
            np.empty(BLOCK, np.bool_), np.empty((2, BLOCK)), np.empty((3, BLOCK)), np.empty(BLOCK, np.uint64),
            np.empty((2, BLOCK), np.uint64), np.empty(BLOCK), np.empty(BLOCK), np.empty(BLOCK),
            np.empty(BLOCK, np.bool_), np.zeros(BLOCK), np.zeros(BLOCK, np.bool_), np.empty(BLOCK, np.bool_),
            np.empty(BLOCK), np.empty(BLOCK), np.empty((3, BLOCK)))


@kernel
def camera_block(code, keys, corners, size, spp, start, count, sample, sequence, column, line, camera, xy, d, rays):
    """Writes into ``d`` (3, BLOCK) and into the block's ``RTCRayHit16`` packets ``rays``
    the unit directions of the camera rays of samples ``start .. start + count - 1``
    (lanes past the end repeat sample ``start``), as
    :func:`rtmesh.scene.camera_rays.camera_rays` makes them for a pinhole.

    ``sample`` (BLOCK,) uint64 holds each sample's index, and what the caller formed once
    per pixel: ``sequence`` (2, BLOCK) uint64, the pixel's keys
    (:func:`rtmesh.sampling.pixel_samples.pixel_keys`), and ``column``,
    ``line`` (BLOCK,) float64, its column and row; ``b`` for sample ``start + b``.  The
    positions in the pixels come from the sampler (``code``, ``keys``, ``corners``, ``size``,
    ``spp``: the :class:`rtmesh.sampling.pixel_samples.PixelSampler`'s), by
    :func:`rtmesh.sampling.pixel_samples.sample_positions`.

    ``camera`` is the image-plane map and the camera frame as a tuple of 13 numbers
    (:func:`camera_numbers`): numba takes and releases a reference to every array argument
    of a compiled call (atomic instructions, shared between the render threads).  ``xy``
    (2, BLOCK) is scratch.  Each loop is branch-free over the block's arrays, so LLVM
    vectorises the hashing, the directions and the packet stores (with a call per sample
    and the packets' lanes written one by one, this step took about 45 cycles a sample at
    16 spp; integer divisions for the pixel's row and the stratum cost about 25 more at
    1 spp).
    """
    ax, bx, ay, by, fx, fy, fz, rx, ry, rz, ux, uy, uz = camera
    _film_positions(code, keys, corners, size, spp, count, sample, sequence, column, line, xy)
    # image_plane_xy, with the pixel's column and row formed by the caller
    for b in range(BLOCK):
        sx = (xy[0, b] + column[b]) * ax + bx
        sy = (xy[1, b] + line[b]) * ay + by
        d[0, b], d[1, b], d[2, b] = pinhole_xyz(sx, sy, fx, fy, fz, rx, ry, rz, ux, uy, uz)
    write_directions(d, rays)


@kernel
def lens_camera_block(code, keys, corners, size, spp, start, count, sample, sequence, column, line, camera, xy, d,
                      rays, lens, eye, o):
    """:func:`camera_block` for a thin lens: ``lens`` (n, 2) float64 holds each of the
    chunk's samples' point on the aperture (scene units along right and up,
    :meth:`rtmesh.scene.camera.Camera.lens_disk`), and the rays leave those points for the
    plane of focus (:func:`rtmesh.scene.camera_rays.thin_lens_xyz`; ``eye`` is the camera's
    position and focus distance), their origins written into the packets too (``o``
    (3, BLOCK) scratch).  A kernel of its own, so that the pinhole's step stays as it is."""
    ax, bx, ay, by, fx, fy, fz, rx, ry, rz, ux, uy, uz = camera
    ex, ey, ez, focus = eye
    _film_positions(code, keys, corners, size, spp, count, sample, sequence, column, line, xy)
    for b in range(BLOCK):
        sx = (xy[0, b] + column[b]) * ax + bx
        sy = (xy[1, b] + line[b]) * ay + by
        k = start + (b if b < count else 0)
        o[0, b], o[1, b], o[2, b], d[0, b], d[1, b], d[2, b] = thin_lens_xyz(
            sx, sy, lens[k, 0], lens[k, 1], ex, ey, ez, fx, fy, fz, rx, ry, rz, ux, uy, uz, focus)
    write_origins(o, rays)
    write_directions(d, rays)


@inline_row
def _film_positions(code, keys, corners, size, spp, count, sample, sequence, column, line, xy):
    """The block's samples' positions in their pixels into ``xy`` (2, BLOCK), the inactive
    lanes of the last packet given the first sample's position and pixel (a copy of the
    first ray keeps their words finite)."""
    sample_positions(code, keys, corners, size, spp, sample, sequence, count, xy)
    for b in range(count, BLOCK):
        xy[0, b], xy[1, b], column[b], line[b] = xy[0, 0], xy[1, 0], column[0], line[0]


@row
def write_origins(o, rays):
    """Ray origins ``o`` (rows 0-2 of (k, BLOCK)) into the block's packets ``rays``, rounded to float32 as
    :func:`rtmesh.geometry.embree_packets.set_lane` writes them; a branch-free loop over the
    lanes of each group and field, as :func:`write_directions`."""
    for group in range(BLOCK // ep.GROUP):
        base, first = group * ep.GROUP_WORDS, group * ep.GROUP
        for c in range(3):
            at = base + (ep.ORG + c) * ep.GROUP
            for lane in range(ep.GROUP):
                rays[at + lane] = np.float32(o[c, first + lane])


@row
def write_directions(d, rays):
    """Camera ray directions ``d`` (3, BLOCK) and the default ``tfar`` into the block's
    packets ``rays`` (:func:`rtmesh.geometry.embree_packets.packet_direction`); one
    branch-free loop over the lanes of each group of the packets (``GROUP`` lanes of one
    field side by side) and field, which LLVM vectorises."""
    far = np.float32(ep.DEFAULT_TFAR)
    for group in range(BLOCK // ep.GROUP):
        base, first = group * ep.GROUP_WORDS, group * ep.GROUP
        for c in range(3):
            at = base + (ep.DIR + c) * ep.GROUP
            for lane in range(ep.GROUP):
                rays[at + lane] = ep.packet_direction(d[c, first + lane])
        at = base + ep.TFAR * ep.GROUP
        for lane in range(ep.GROUP):
            rays[at + lane] = far


@kernel
def write_rays(ray, rays):
    """Shadow rays ``ray`` (7, BLOCK) float32 (origin, direction, length: see
    :func:`light_block`) into the block's packets ``rays``, as
    :func:`rtmesh.geometry.embree_packets.set_lane` writes one lane, in branch-free loops over
    the lanes of each group that LLVM vectorises."""
    write_origins(ray, rays)  # rows 0-2, float32 already
    for group in range(BLOCK // ep.GROUP):
        base, first = group * ep.GROUP_WORDS, group * ep.GROUP
        for c in range(3):
            at = base + (ep.DIR + c) * ep.GROUP
            for lane in range(ep.GROUP):
                rays[at + lane] = ep.packet_direction(ray[3 + c, first + lane])
        at = base + ep.TFAR * ep.GROUP
        for lane in range(ep.GROUP):
            rays[at + lane] = ray[6, first + lane]


@row
def camera_numbers(image_plane, forward, right, up):
    """The image-plane map and the camera frame as one tuple of numbers, for :func:`camera_block`."""
    return (image_plane[0], image_plane[1], image_plane[2], image_plane[3], forward[0], forward[1], forward[2],
            right[0], right[1], right[2], up[0], up[1], up[2])


@kernel
def surface_block(barycentrics, face, normal_row, faces, normals, interpolate, d, count, fix_terminator):
    """Surface records of the first ``count`` samples of a block (the arithmetic of
    :func:`rtmesh.shading.surfaces.surface_records`).

    Parameters
    ----------
    barycentrics : (2, BLOCK) float64
        Per sample: ``u, v`` of the hit.
    face, normal_row : (BLOCK,) intp
        Per sample: the face hit (face 0 for a miss) and its row of ``normals``.
    faces : (F, 12) float64
        Per face ``[v0, v1 - v0, v2 - v0, unit normal]`` (``ShadingTables.faces``).
    normals : (F, 9) or (1, 9) float64
        Per face the vertex normals ``[n0, n1 - n0, n2 - n0]``; one row of zeros in a
        scene without smooth faces (``normal_row`` is then 0).  A flat face's row is
        read but not used.
    interpolate : (BLOCK,) bool
        Samples whose shading normal interpolates the vertex normals.
    d : (3, BLOCK) float64
        Unit ray directions.
    count : int
    fix_terminator : bool

    Returns
    -------
    (9, BLOCK) float64
        Hit point, geometric and shading normal (facing the ray's side).

    Notes
    -----
    The loop reads the tables directly and calls only number-to-number rows (inlined), and
    its output has the block's constant size (see :func:`light_block`): LLVM vectorises
    it, the table reads as gathers.  Gathering the 21 numbers of each sample's rows into
    block arrays first, in a scalar loop, cost about 10 cycles a sample more at 16 spp.
    A row called per sample with the tables as arguments would take and release a
    reference to each (atomic instructions, about a fifth of the stage's time once).
    """
    srf = np.empty((9, BLOCK))
    r = barycentrics
    for b in range(count):
        f, g = face[b], normal_row[b]
        (srf[0, b], srf[1, b], srf[2, b], srf[3, b], srf[4, b], srf[5, b], srf[6, b], srf[7, b], srf[8, b],
         _) = surface_from_rows_inlined(r[0, b], r[1, b], d[0, b], d[1, b], d[2, b], faces[f, 0], faces[f, 1],
                                         faces[f, 2], faces[f, 3], faces[f, 4], faces[f, 5], faces[f, 6],
                                         faces[f, 7], faces[f, 8], faces[f, 9], faces[f, 10], faces[f, 11],
                                         interpolate[b], normals[g, 0], normals[g, 1], normals[g, 2],
                                         normals[g, 3], normals[g, 4], normals[g, 5], normals[g, 6],
                                         normals[g, 7], normals[g, 8], fix_terminator)
    return srf


@kernel
def light_block(light, srf, d, count, scale, shorten, highlights):
    """One light at the first ``count`` surface records of a block (the arithmetic of
    :func:`rtmesh.shading.direct_light.light_samples`).

    ``highlights``: whether any material of the scene has a highlight; without, the
    highlight cosines are not formed (0: they would be read by no one).

    Returns
    -------
    lit : (BLOCK,) bool
        The light reaches the point (it is on the side the ray came from, its term is not 0).
    values : (5, BLOCK) float64
        ``ns . wi``, the incident term (3 rows) and the highlight cosine.
    shadow_ray : (7, BLOCK) float32
        Offset origin, float32 direction and length of the shadow ray.

    Notes
    -----
    The loops have no branches, gathers or calls, and their outputs are made here with the
    constant size of a block: only then does LLVM vectorise them (with output arrays passed
    in, or sized at run time, they stay scalar, about twice as slow).  A point light has a
    loop of its own (:func:`rtmesh.lights.point_light_rows.point_row`), without the
    selects that form every kind of light (:func:`_light_loop` makes both).
    """
    if light[KIND] == POINT:
        return _point_light_loop(light, srf, d, count, scale, shorten, highlights)
    return _any_light_loop(light, srf, d, count, scale, shorten, highlights)


def _light_loop(illuminate):
    """:func:`light_block`'s loop for lights whose direction, distance and incident term
    ``illuminate(light, px, py, pz)`` forms (one compiled loop per function, so that each
    stays branch-free)."""

    @row
    def loop(light, srf, d, count, scale, shorten, highlights):
        lit = np.empty(BLOCK, np.bool_)
        values = np.empty((5, BLOCK))
        shadow_ray = np.empty((7, BLOCK), np.float32)
        for b in range(count):
            wx, wy, wz, distance, er, eg, eb = illuminate(light, srf[0, b], srf[1, b], srf[2, b])
            (lit[b], values[0, b], values[1, b], values[2, b], values[3, b], values[4, b], shadow_ray[0, b],
             shadow_ray[1, b], shadow_ray[2, b], shadow_ray[3, b], shadow_ray[4, b], shadow_ray[5, b],
             shadow_ray[6, b]) = light_sample(srf[0, b], srf[1, b], srf[2, b], srf[3, b], srf[4, b], srf[5, b],
                                              srf[6, b], srf[7, b], srf[8, b], d[0, b], d[1, b], d[2, b], wx, wy,
                                              wz, distance, er, eg, eb, scale, shorten, highlights)
        return lit, values, shadow_ray

    return loop


_point_light_loop = _light_loop(point_row)
_any_light_loop = _light_loop(illuminate_row)


@kernel
def radiance_block(radiance, start, count, base, background, mat, hit, direct, owner, last, pixel_list, first_pixel,
                   counts, total, total_sq, film_count, image, sums, state):
    """The radiance of the first ``count`` samples of a block: emission and ambient light
    plus the direct light, added to 0 as the general path adds a hit's local shading to its
    radiance; written to rows ``start ..`` of ``radiance`` or, with a film, added to the
    sums of the sample's pixel in sample order (as ``Film.add_tile`` adds them), each pixel
    stored when its last sample is in.

    Parameters
    ----------
    radiance : (n, 3) float64
        The chunk's samples, row-major; (0, 3) with a film.
    start, count : int
    base : (M, 3) float64
        Emission plus ambient light per material.
    background : (3,) float64
    mat : (BLOCK,) intp
    hit : (BLOCK,) bool
    direct : (3, BLOCK) float64
    owner : (BLOCK,) int64
        Each sample's pixel (its place in the chunk).
    last : (BLOCK,) bool
        Whether the sample is its pixel's last (a chunk holds every sample of its pixels).
    pixel_list, first_pixel, counts
        The chunk's pixels and their sample counts (see
        :func:`rtmesh.rendering.direct_stage.direct_samples`).
    total, total_sq, film_count, image
        The film's arrays, or empty: no film.
    sums : (6,) float64
    state : (2,) int64
        The pixel being added across blocks: its sums
        (:func:`rtmesh.rendering.film_sums.pixel_sums`), its
        place in the chunk (-1 before the first) and its index.

    Notes
    -----
    A kernel of its own, like the other steps, so that a first run compiles it in the other
    process (:mod:`rtmesh.core.compile_ahead`).
    """
    adding, one_count, listed = len(film_count) > 0, len(counts) == 1, len(pixel_list) > 0
    adding_to, adding_px = state[0], state[1]
    sum_r, sum_g, sum_b, square_r, square_g, square_b = sums[0], sums[1], sums[2], sums[3], sums[4], sums[5]
    for b in range(count):
        mat_b = mat[b]
        r0 = 0.0 + (base[mat_b, 0] + direct[0, b]) if hit[b] else 0.0 + background[0]
        r1 = 0.0 + (base[mat_b, 1] + direct[1, b]) if hit[b] else 0.0 + background[1]
        r2 = 0.0 + (base[mat_b, 2] + direct[2, b]) if hit[b] else 0.0 + background[2]
        if not adding:
            radiance[start + b, 0], radiance[start + b, 1], radiance[start + b, 2] = r0, r1, r2
            continue
        if owner[b] != adding_to:  # the first sample of the next pixel
            adding_to = owner[b]
            adding_px = pixel_list[adding_to] if listed else first_pixel + adding_to
            sum_r, sum_g, sum_b, square_r, square_g, square_b = pixel_sums(total, total_sq, film_count, adding_px)
        sum_r, sum_g, sum_b = sum_r + r0, sum_g + r1, sum_b + r2
        square_r, square_g, square_b = square_r + r0 * r0, square_g + r1 * r1, square_b + r2 * r2
        if last[b]:
            n = film_count[adding_px] + (counts[0] if one_count else counts[adding_to])
            store_pixel(total, total_sq, image, adding_px, n, sum_r, sum_g, sum_b, square_r, square_g, square_b)
            film_count[adding_px] = n
    state[0], state[1] = adding_to, adding_px
    sums[0], sums[1], sums[2], sums[3], sums[4], sums[5] = sum_r, sum_g, sum_b, square_r, square_g, square_b


@row
def add_light_row(d0, d1, d2, kd0, kd1, kd2, ks0, ks1, ks2, cos_i, power, e0, e1, e2):
    """The direct light ``(d0, d1, d2)`` plus one light's Blinn-Phong term for a material
    with colours ``kd``, ``ks`` (``power``: the raised highlight cosine, 0 without one;
    ``e``: its incident term), as :func:`rtmesh.shading.direct_light.add_light` adds it.
    Numbers only: a row called per sample with array arguments takes and releases a
    reference to each (atomic instructions)."""
    f0, f1, f2 = blinn_phong_row(kd0, kd1, kd2, ks0, ks1, ks2, cos_i, power)
    return d0 + f0 * e0, d1 + f1 * e1, d2 + f2 * e2

