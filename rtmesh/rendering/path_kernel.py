"""The path integrator's compiled kernel: unidirectional path tracing with next-event
estimation and multiple importance sampling, over Embree packets.

Each block of 256 camera samples (:data:`rtmesh.rendering.path_vertices.WIDTH`) is sixteen
16-wide packets: the camera rays are traced with the coherent flag, every later segment of
the paths as one incoherent packet of each packet's lanes still alive, and each round's
shadow rays as one occlusion packet per light sample and packet.  Between the queries the
vertex's stages run over the 256 lanes (kernels of their own: ``meet`` and
``sample_lights`` of :mod:`rtmesh.rendering.path_vertices`, ``scatter`` of
:mod:`rtmesh.rendering.path_scatter`; the queries are :mod:`rtmesh.rendering.path_rays`'
stages).  Per lane and vertex:

1. the ray meets a visible quad or disk light, a surface or nothing (the background);
   emission found there is weighted against light sampling by the power heuristic
   (weight 1 after a camera ray or a delta lobe); a cut-out surface the ray passes
   (alpha mask or blend) continues it from there, with the same depth;
2. at a surface: textures and normal maps (:mod:`rtmesh.rendering.path_surfaces`), then a
   light chosen by power (alias table, :mod:`rtmesh.sampling.alias`), a point or direction on
   it (:func:`sample_li`), the BSDF toward it (:func:`rtmesh.materials.models.evaluate`),
   weighted against BSDF sampling (delta lights: weight 1), its shadow ray into the packet;
   at the path's first vertex with a non-delta part (reached through delta lobes only)
   ``light_samples`` such estimates, each light and point drawn independently, each
   weighted by the power heuristic with the strategies' sample counts (``light_samples``
   light samples, one BSDF sample: Veach 1997, 9.2.2), their sum divided by
   ``light_samples``, and their shadow rays in one packet per light sample (emission a
   BSDF sample of that vertex meets is weighted with the same counts);
3. a BSDF sample continues the path (:func:`rtmesh.materials.models.sample`); after
   ``rr_depth`` vertices Russian roulette on the throughput's largest channel ends it (the
   throughput without the radiance scaling of the refractions so far, pbrt-v4's ``etaScale``;
   a path survives with at most ``path_scatter.SURVIVAL`` = 0.95, Mitsuba's rule, so that it ends).

The packet queries (nearest hits, shadow rays, moving objects, placements, cut-out layers)
are :mod:`rtmesh.rendering.path_packets`' rows, the light rows :mod:`rtmesh.rendering.path_lights`',
the sums and the light-path passes :mod:`rtmesh.rendering.path_sums`', the Whitted
configuration's :mod:`rtmesh.rendering.whitted_rows`; the kernel's compile-ahead group and
signature are in :mod:`rtmesh.rendering.path_signatures`.

``max_depth`` counts segments after the camera ray (1: direct light only; -1: unlimited,
Russian roulette ends paths).  Every random number is :func:`rtmesh.sampling.hashing.uniform`
of the sample's key and a dimension (:data:`DIMENSIONS_PER_VERTEX` per vertex), so the image
does not depend on chunks or threads.

Records (tuples of arrays, built once by :class:`rtmesh.rendering.path_stage.PathStage`):
``geometry`` and ``surface`` as :mod:`rtmesh.rendering.path_surfaces` describes them;
``lights = (rows, probability, alias, pmf, face_light, analytic, environment, texels,
descriptors, placement_light)`` (:class:`rtmesh.lights.light_table.LightTable`, ``texels``
and ``descriptors`` its projectors' images); ``env = (pixels, marginal, conditional,
func, mean, cos_rotation, sin_rotation)`` (:class:`rtmesh.lights.environment_table.EnvironmentTables`);
``options = (max_depth, rr_depth, clamp, offset_scale, background_seen, cutouts, split,
camera_media, light_samples, light_block, record_hits, ao_pass, pass_albedo)``:
``record_hits`` whether to record the camera-hit passes' surfaces, ``ao_pass`` whether to
cast the ``ao`` pass's rays there (the ``whitted`` record's ``ao_samples`` of them),
``pass_albedo`` (M, 3) each material's albedo for the pass
(:mod:`rtmesh.rendering.path_camera_hits`); ``camera_media`` the media the camera sits in
(``STACK_DEPTH`` material ids, innermost first, -1 padded;
:class:`rtmesh.rendering.media.Media`), ``light_samples`` the next-event estimates at a
path's first vertex and ``light_block`` :func:`rtmesh.sampling.zsobol.block_bits` of the
spp and ``light_samples`` (the first vertex's light points are point ``sample *
light_samples + k`` of the pixel's Sobol set: :func:`rtmesh.sampling.zsobol.sequence_ray_pair`).

Nested media: each lane carries a stack of the transmissive materials it is inside
(innermost first), as the Whitted path's :mod:`rtmesh.rendering.media` does: entering a
transmissive surface (its front) pushes the material, leaving it pops it; the interface's
index ratio is the material's index over that of the medium on the other side (so glass in
water refracts with 1.5 / 1.33), set in the hit's parameter row (the model's ``ior`` slot);
Beer-Lambert absorption is the innermost medium's.  Touching media (coincident "twin"
faces) are crossed together, as the Whitted path does (:func:`rtmesh.rendering.path_media.twin_material`).
``motion = (static, static_faces, movers, face_maps, face_offsets, moves, face_mover)``:
whether the static scene exists (the packet queries' ``scene`` is its handle), its faces'
global indices (empty: the identity), the moving objects' Embree scenes (k,) int64, their
faces' global indices (concatenated, with offsets (k + 1,)), their motions ``moves``
(k, 10): translation per unit time, unit axis, radians per unit time, centre, and each
face's mover (-1: static).  A ray then meets the static scene and every mover, each traced
in its rest pose at the lane's time (rigid motions keep distances), the nearest hit wins,
and its point and normals are carried to the lane's time (as
:class:`rtmesh.geometry.motion.MotionAccel`).  The light table holds emissive triangles in
their rest pose: next-event estimation toward one of a moving object, and the density a
BSDF sample meeting it is weighted with, take its row carried to the lane's time
(:func:`light_at`).
``instances = (face_offset, to_world, normal_to_world)``: meshes placed by an Embree
instance array (:mod:`rtmesh.scene.instances`; a hit's ``instPrimID`` is the placement):
``face_offset`` (k,) each placement's first face in the per-face tables (its prototype's),
``to_world`` (k, 12) its model-to-world transform (the linear part row by row, then the
translation) and ``normal_to_world`` (k, 9) the inverse transpose of the linear part.  A hit
on placement ``j`` is face ``face_offset[j] + primID``; its point is formed on the
prototype's float32 triangle and carried to the world in float64, its normals by the
inverse transpose and normalised again (a mirroring transform needs no flip: the copies'
reversed winding gives the same direction).  Empty arrays: no instances.

With ``split``, every contribution is also added to one of the light-path passes
(:data:`rtmesh.io.passes.LIGHT_PATH_PASSES`, which sum to the image): what the camera ray
meets itself (``emission``); light from a light after the first vertex, by the part of the
BSDF it came through (``direct_*``: next-event estimation at the first vertex is split by
:func:`rtmesh.materials.models.parts`, emission met by the first BSDF sample goes with that
sample's lobe); everything after more vertices by the first vertex's sampled lobe
(``indirect_*``).
"""

import numpy as np

from rtmesh.core.compiled import borrowed, call_at, keep_alive, kernel
from rtmesh.geometry.embree_packets import (LANES, RTC_RAY_QUERY_FLAG_COHERENT, RTC_RAY_QUERY_FLAG_INCOHERENT,
                                            packet_buffers, query_arguments)
from rtmesh.lights import light_table as lt
from rtmesh.materials import lobes
from rtmesh.rendering.path_camera import camera_lanes
from rtmesh.rendering.path_camera_hits import CAMERA_HIT_WORDS, FIRST_HIT_WORDS
from rtmesh.rendering.path_packets import BOUNCE, CAMERA, REFLECTION, SHADOW
from rtmesh.rendering.path_surfaces import textured_materials
from rtmesh.rendering.path_sums import GLOSSY_PATH, LIGHT_PATHS
from rtmesh.rendering.path_vertices import CHAIN_START, VERTEX_IDS, VERTEX_WORDS, WIDTH
from rtmesh.rendering.whitted_rows import BRANCH_WORDS, pop_branch


@kernel
def trace_paths(intersect, occluded, scene, camera, origins, directions, keys, pixels, samples, sobol_keys, times,
                geometry, surface, lights, env, options, whitted, motion, instances, photon_map, stages, radiance,
                light_paths, camera_hits, counts):
    """Trace one path per camera ray and write its radiance.

    Parameters
    ----------
    intersect, occluded : ctypes function objects
        Embree's packet queries (:class:`rtmesh.geometry.embree_library.PacketLibrary`).
    scene : int
        The committed ``RTCScene``.
    camera : tuple
        The camera rays the kernel forms itself (:mod:`rtmesh.rendering.path_camera`),
        when its first item is true.
    origins, directions : (n, 3) float64, or (0, 3)
        Otherwise the camera rays in the re-centred frame (unit directions).
    keys : (n,) uint64
        Each sample's random key (:func:`rtmesh.sampling.hashing.path_key`).
    pixels, samples : (n,) int64, or (0,)
        Each ray's pixel and sample index: the first vertex's light, BSDF and (whitted) AO
        points are Sobol pairs of the pixel's sequences (``samples`` empty: hashed numbers
        throughout).
    sobol_keys : (8,) uint64
        Those sequences (sobol or zsobol) and their four dimension keys (light point, BSDF,
        AO, light choice)
        (:func:`rtmesh.sampling.zsobol.sequence_keys`).
    times : (n,) float64, or (0,)
        Each sample's time in the shutter (scenes with moving objects).
    geometry, surface, lights, env, options, whitted, motion, instances, photon_map : tuples
        The records described in the module notes.
    stages : (10,) int64
        The stages' entry points, :func:`rtmesh.rendering.path_signatures.stage_entries`.
    radiance : (n, 3) float64
        Output.
    light_paths : (n, LIGHT_PATHS, 3) float64, or (0, LIGHT_PATHS, 3)
        Output of the light-path passes, with ``split``.
    camera_hits : (n, CAMERA_HIT_WORDS) float64, or (0, CAMERA_HIT_WORDS)
        Output for the camera-hit passes, with ``options``' ``record_hits``: each camera
        ray's first shaded surface (:mod:`rtmesh.rendering.path_camera_hits`).
    counts : (len(COUNTER_NAMES),) int64
        Rays traced (active lanes only) by :data:`rtmesh.rendering.path_packets.COUNTER_NAMES`,
        added to: camera, bounce and shadow rays (whitted: camera, reflection, refraction,
        BSDF-sampled, cut-out, shadow, area-light shadow and environment shadow rays).

    Returns
    -------
    bool
        False if ``stages`` were compiled for other types than this kernel passes them (it
        then stops, its outputs incomplete).
    """
    # read through views that own nothing: no reference counts in the per-lane rows
    # (rtmesh.core.compiled.borrowed; the caller holds the arrays)
    geometry, surface, lights, env, options, whitted, motion, instances, photon_map = borrowed(
        (geometry, surface, lights, env, options, whitted, motion, instances, photon_map))
    camera, origins, directions, keys, pixels, samples, sobol_keys, times, stages, radiance, light_paths, \
        camera_hits, counts = borrowed((camera, origins, directions, keys, pixels, samples, sobol_keys, times, stages,
                                        radiance, light_paths, camera_hits, counts))
    n = keys.shape[0]
    camera_on = camera[0]
    absorption = surface[4]
    textured = textured_materials(surface, geometry)
    split, camera_media, light_samples, record_hits = options[6], options[7], options[8], options[10]
    media = len(camera_media)
    whitted_on, delta_rows, group_start, branch_depth, ao_samples = (whitted[0], whitted[1], whitted[2], whitted[11],
                                                                    whitted[12])
    # the light samples a vertex takes: one by power among all lights (path), or every delta
    # light once and light_samples of each other light (whitted: LightTable.light_groups)
    deltas = len(delta_rows) if whitted_on else 0
    area_rounds = light_samples * (len(group_start) - 1) if whitted_on else light_samples
    ray, words, valid, args_coherent = packet_buffers(np.int64(1), np.int64(RTC_RAY_QUERY_FLAG_COHERENT))
    args_incoherent = query_arguments(np.int64(RTC_RAY_QUERY_FLAG_INCOHERENT))
    shadow, shadow_words, shadow_valid, _ = packet_buffers(np.int64(1), np.int64(RTC_RAY_QUERY_FLAG_INCOHERENT))
    # a mover's packet (its rest frame), and the nearest hit of each lane over the scenes
    rest, rest_words, rest_valid, _ = packet_buffers(np.int64(1), np.int64(RTC_RAY_QUERY_FLAG_INCOHERENT))
    best_t = np.zeros(WIDTH)
    best_prim = np.zeros(WIDTH, np.int64)
    best_instance = np.full(WIDTH, -1, np.int64)
    best_u = np.zeros(WIDTH)
    best_v = np.zeros(WIDTH)
    # the shadow packet's rays in float64 (origins, directions) for the movers' rest frames
    segment = np.zeros((6, LANES))
    lane_time = np.zeros(WIDTH)
    # each lane's light row carried to its time (an emissive triangle of a moving object)
    moved = np.zeros((WIDTH, lt.WIDTH))
    scratch = np.zeros((WIDTH, lobes.PARAMETER_WIDTH))
    px = np.zeros(WIDTH)
    py = np.zeros(WIDTH)
    pz = np.zeros(WIDTH)
    dx = np.zeros(WIDTH)
    dy = np.zeros(WIDTH)
    dz = np.zeros(WIDTH)
    beta = np.zeros((WIDTH, 3))
    total = np.zeros((WIDTH, 3))
    # per light sample of a vertex (rtmesh.rendering.settings.RenderSettings.light_samples):
    # each lane's shadow ray (origin, direction, length) and the light it brings if free
    # (whitted: then ao_samples ambient-occlusion rays)
    light_slots = deltas + area_rounds + ao_samples
    shadow_rays = np.zeros((light_slots, WIDTH, 7))
    shadow_set = np.zeros((light_slots, WIDTH), np.bool_)
    shadow_count = np.zeros(light_slots, np.int64)
    shadow_kind = np.full(light_slots, SHADOW, np.int64)
    pending = np.zeros((light_slots, WIDTH, 3))
    paths = np.zeros((WIDTH, LIGHT_PATHS, 3))
    pending_paths = np.zeros((light_slots if split else 1, WIDTH, LIGHT_PATHS, 3))
    category = np.zeros(WIDTH, np.int64)
    stack = np.full((WIDTH, max(media, 1)), -1, np.int64)
    # whitted: the rays a lane's hits split off, followed when its current ray ends
    branch = np.zeros((WIDTH, branch_depth, BRANCH_WORDS))
    branch_media = np.full((WIDTH, branch_depth, max(media, 1)), -1, np.int64)
    branch_top = np.zeros(WIDTH, np.int64)
    sigma = np.zeros((WIDTH, 3))
    reach = np.zeros(WIDTH)
    alive = np.zeros(WIDTH, np.bool_)
    prev_pdf = np.zeros(WIDTH)
    prev_delta = np.zeros(WIDTH, np.bool_)
    # the product of eta'^2 over the path's crossings (undoes their radiance scaling)
    eta_scale = np.ones(WIDTH)
    # light samples taken at the path's last vertex (the light strategy's sample count in the
    # MIS weight of emission its BSDF sample meets)
    prev_count = np.ones(WIDTH)
    lane_depth = np.zeros(WIDTH, np.int64)
    layers = np.zeros(WIDTH, np.int64)
    # with photons: the path's last vertices (CHAIN_*), its length so far (the gather radius)
    chain = np.zeros(WIDTH, np.int64)
    travelled = np.zeros(WIDTH)
    # what each lane's ray is, for the counters (whitted)
    ray_kind = np.zeros(WIDTH, np.int64)
    # what meet leaves for the vertex's other stages (rtmesh.rendering.path_vertices)
    vertex = np.zeros((WIDTH, VERTEX_WORDS))
    vertex_ids = np.zeros((WIDTH, VERTEX_IDS), np.int64)
    shaded = np.zeros(WIDTH, np.bool_)
    # the camera-hit passes' record of each lane (rtmesh.rendering.path_camera_hits)
    first_hit = np.zeros((WIDTH, FIRST_HIT_WORDS))
    # the camera rays' pixel sequences, sample indices and positions in their pixels
    sequence = np.zeros((2, WIDTH), np.uint64)
    index = np.zeros(WIDTH, np.uint64)
    xy = np.zeros((2, WIDTH))
    # the scratch arrays too, through views that own nothing (owned stays alive to the end)
    owned = (ray, words, valid, args_coherent, args_incoherent, shadow, shadow_words, shadow_valid, rest, rest_words,
             rest_valid, best_t, best_prim, best_instance, best_u, best_v, segment, lane_time, moved, scratch, px,
             py, pz, dx, dy, dz, beta, total, shadow_rays, shadow_set, shadow_count, pending, paths, pending_paths,
             category, stack, branch, branch_media, branch_top, sigma, reach, alive, prev_pdf, prev_delta, eta_scale,
             prev_count, lane_depth, layers, chain, travelled, ray_kind, shadow_kind, vertex, vertex_ids, shaded,
             textured, first_hit, sequence, index, xy)
    (ray, words, valid, args_coherent, args_incoherent, shadow, shadow_words, shadow_valid, rest, rest_words,
     rest_valid, best_t, best_prim, best_instance, best_u, best_v, segment, lane_time, moved, scratch, px,
     py, pz, dx, dy, dz, beta, total, shadow_rays, shadow_set, shadow_count, pending, paths, pending_paths,
     category, stack, branch, branch_media, branch_top, sigma, reach, alive, prev_pdf, prev_delta, eta_scale,
     prev_count, lane_depth, layers, chain, travelled, ray_kind, shadow_kind, vertex, vertex_ids, shaded,
     textured, first_hit, sequence, index, xy) = borrowed(owned)
    lanes = (px, py, pz, dx, dy, dz, beta, total, paths, category, stack, sigma, alive, prev_pdf, prev_delta, eta_scale,
             prev_count, lane_depth, layers, chain, travelled, ray_kind, lane_time, moved, scratch, first_hit)
    hits = (best_t, best_prim, best_instance, best_u, best_v)
    vertices = (vertex, vertex_ids, shaded)
    shadows = (shadow_rays, shadow_set, shadow_count, shadow_kind, pending, pending_paths)
    branches = (branch, branch_media, branch_top)
    queries = (intersect, occluded, scene, args_coherent, args_incoherent)
    packet, shadow_packet, rest_packet = (ray, words, valid), (shadow, shadow_words, shadow_valid), (rest, rest_words,
                                                                                                   rest_valid)
    for start in range(0, n, WIDTH):
        count = min(WIDTH, n - start)
        if camera_on:
            camera_lanes(camera, start, count, sequence, index, xy, px, py, pz, dx, dy, dz)
        for lane in range(WIDTH):
            alive[lane] = lane < count
            branch_top[lane] = 0
            ray_kind[lane] = CAMERA
            if lane < count:
                i = start + lane
                if not camera_on:
                    px[lane], py[lane], pz[lane] = origins[i, 0], origins[i, 1], origins[i, 2]
                    dx[lane], dy[lane], dz[lane] = directions[i, 0], directions[i, 1], directions[i, 2]
                beta[lane, 0] = beta[lane, 1] = beta[lane, 2] = 1.0
                total[lane, 0] = total[lane, 1] = total[lane, 2] = 0.0
                if split:
                    paths[lane, :, :] = 0.0
                category[lane] = GLOSSY_PATH
                sigma[lane, 0] = sigma[lane, 1] = sigma[lane, 2] = 0.0
                for k in range(media):
                    stack[lane, k] = camera_media[k]
                if media and camera_media[0] >= 0:
                    for c in range(3):
                        sigma[lane, c] = absorption[camera_media[0], c]
                prev_pdf[lane] = 0.0
                prev_delta[lane] = True
                eta_scale[lane] = 1.0
                prev_count[lane] = 1.0
                lane_depth[lane] = 0
                layers[lane] = 0
                chain[lane] = CHAIN_START
                travelled[lane] = 0.0
                lane_time[lane] = times[i] if len(times) else 0.0
                if record_hits:
                    for c in range(FIRST_HIT_WORDS):
                        first_hit[lane, c] = 0.0
        first = True
        while True:
            if whitted_on:
                for lane in range(WIDTH):
                    if (not alive[lane]) and branch_top[lane] > 0:
                        # a ray an earlier hit of this lane split off
                        top = pop_branch(branch, branch_media, branch_top, lane, px, py, pz, dx, dy, dz, beta,
                                         lane_depth, stack)
                        ray_kind[lane] = REFLECTION
                        for c in range(3):
                            sigma[lane, c] = absorption[top, c] if top >= 0 else 0.0
                        alive[lane] = True
                        prev_pdf[lane] = 0.0
                        prev_delta[lane] = True
                        prev_count[lane] = 1.0
                        layers[lane] = 0
            for lane in range(WIDTH):
                if alive[lane]:
                    counts[ray_kind[lane] if whitted_on else (CAMERA if lane_depth[lane] == 0 else BOUNCE)] += 1
            if not alive.any():
                break
            # the rays: each live lane's nearest hit (rtmesh.rendering.path_rays)
            if not call_at(stages[0], stages[1], (queries, first, packet, rest_packet, lanes, hits, motion,
                                                  instances)):
                return False
            first = False
            # the vertex: what each lane meets, its light samples, the ray that continues it
            # (path_vertices.meet and sample_lights, path_scatter.scatter, through their entry
            # points, so that they compile apart from this kernel)
            if not call_at(stages[2], stages[3], (lanes, hits, vertices, keys, start, geometry, surface, textured,
                                                  lights, env, options, whitted, motion, instances, photon_map)):
                return False
            if not call_at(stages[4], stages[5], (lanes, vertices, shadows, keys, pixels, samples, sobol_keys, start,
                                                  geometry, surface, lights, env, options, whitted, motion)):
                return False
            if not call_at(stages[6], stages[7], (lanes, vertices, branches, keys, pixels, samples, sobol_keys, start,
                                                  surface, options, whitted)):
                return False
            # the shadow rays: one packet per light sample of the vertices and packet of lanes
            if not call_at(stages[8], stages[9], (queries, shadow_packet, rest_packet, segment, reach, lanes, hits,
                                                  shadows, keys, start, counts, geometry, surface, options, motion,
                                                  instances)):
                return False
        for lane in range(count):
            radiance[start + lane, 0] = total[lane, 0]
            radiance[start + lane, 1] = total[lane, 1]
            radiance[start + lane, 2] = total[lane, 2]
            if split:
                for bucket in range(LIGHT_PATHS):
                    for c in range(3):
                        light_paths[start + lane, bucket, c] = paths[lane, bucket, c]
            if record_hits:
                for c in range(CAMERA_HIT_WORDS):
                    camera_hits[start + lane, c] = first_hit[lane, c]
    keep_alive(owned)
    return True
