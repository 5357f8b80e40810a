"""The path integrator's compiled kernel: unidirectional path tracing with next-event
estimation and multiple importance sampling, over Embree packets.

Each block of 16 camera samples is one 16-wide packet: the camera rays are traced with the
coherent flag, every later segment of the 16 paths as one incoherent packet of the lanes
still alive, and each round's shadow rays as one occlusion packet per light sample.  Per
lane and vertex:

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
   throughput without the radiance scaling of the refractions so far, pbrt-v4's ``etaScale``).

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
descriptors)`` (:class:`rtmesh.lights.light_table.LightTable`, the last two its projectors'
images); ``env = (pixels, marginal, conditional,
func, mean, cos_rotation, sin_rotation)`` (:class:`rtmesh.lights.light_table.EnvironmentTables`);
``options = (max_depth, rr_depth, clamp, offset_scale, background_seen, cutouts, split,
camera_media, light_samples, light_block)``: ``camera_media`` the media the camera sits in
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
faces) are crossed together, as the Whitted path does (:func:`rtmesh.rendering.path_surfaces.twin_material`).
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

import math

import numpy as np

from rtmesh.core.compiled import borrowed, keep_alive, kernel
from rtmesh.geometry.embree_packets import (DEFAULT_TFAR, LANES, RAYHIT_WORDS, RTC_RAY_QUERY_FLAG_COHERENT,
                                            RTC_RAY_QUERY_FLAG_INCOHERENT, packet_buffers, query_arguments)
from rtmesh.lights import light_table as lt
from rtmesh.materials import lobes, models
from rtmesh.rendering.photon_kernel import ALL_PARTS, DIFFUSE_PART, TRANSMITTED_PART, gather
from rtmesh.rendering.path_lights import area_pdf, environment_pdf, hit_analytic, light_at, sample_li, shadow_segment
from rtmesh.rendering.path_packets import (AO, AREA_SHADOW, BOUNCE, BSDF, BSDF_U1, BSDF_U2, CAMERA, COVERAGE, CUTOUT,
                                           DIMENSIONS_PER_VERTEX, ENVIRONMENT, LIGHT_CHOICE, LIGHT_U1, LIGHT_U2, LOBE,
                                           MAX_LAYERS, REFLECTION, REFRACTION, ROULETTE, SHADOW, layer_coin,
                                           mover_to_world, nearest_hits, occluded, placed, shadows_through_cutouts)
from rtmesh.rendering.path_surfaces import alias_sample, colour_tint, load_lanes, occlusion_at, set_lane
from rtmesh.rendering.path_surfaces import environment_radiance as _environment_radiance
from rtmesh.rendering.path_surfaces import (cross_interface, crossing_scale, twin_material, hit_frame, hit_parameters, is_transparent,
                                            leave_surface, surface_point, tangent_frame, textured_materials, to_world,
                                            triangle_light_emission)
from rtmesh.materials.metallic_roughness import square_to_cosine_hemisphere_row
from rtmesh.rendering.path_sums import (DIFFUSE_PATH, DIRECT, GLOSSY_PATH, INDIRECT, LIGHT_PATHS, TRANSMISSION_PATH,
                                        accept_shadows, add_radiance, add_to_pass, clamped, lobe_category, pass_bucket)
from rtmesh.rendering.whitted_rows import BRANCH_WORDS, branches, light_factor, pop_branch, push_branch
from rtmesh.sampling.hashing import mix64, uniform
from rtmesh.sampling.mis import power_heuristic
from rtmesh.sampling.zsobol import sequence_pair, sequence_ray_pair

# Sobol sequences hold 2**32 points; later samples take hashed numbers
SOBOL_LIMIT = 1 << 32
# the key of light sample k > 0 of a vertex is mix64(key + k * _LIGHT_ROUND) (sample 0 takes
# the path's own key): its choice and point are the vertex's usual dimensions of that key
_LIGHT_ROUND = np.uint64(0xD1B54A32D192ED03)
# what a path's last vertices were, for caustics: only delta bounces since the camera; a
# non-delta bounce last; a non-delta bounce, then delta bounces only (light met now is a
# caustic path, which photons carry when they are on)
CHAIN_START, CHAIN_SCATTERED, CHAIN_CAUSTIC = 0, 1, 2


@kernel
def trace_paths(intersect16, occluded16, scene, origins, directions, keys, pixels, samples, sobol_keys, times,
                geometry, surface, lights, env, options, whitted, motion, instances, photon_map, radiance, light_paths,
                counts):
    """Trace one path per camera ray and write its radiance.

    Parameters
    ----------
    intersect16, occluded16 : ctypes function objects
        Embree's packet queries (:class:`rtmesh.geometry.embree_library.PacketLibrary`).
    scene : int
        The committed ``RTCScene``.
    origins, directions : (n, 3) float64
        Camera rays in the re-centred frame (unit directions).
    keys : (n,) uint64
        Each sample's random key (:func:`rtmesh.sampling.hashing.path_key`).
    pixels, samples : (n,) int64, or (0,)
        Each ray's pixel and sample index: the first vertex's light and BSDF points are
        Sobol pairs of the pixel's sequences (``samples`` empty: hashed numbers throughout).
    sobol_keys : (6,) uint64
        Those sequences (sobol or zsobol) and their two dimension keys
        (:func:`rtmesh.sampling.zsobol.sequence_keys`).
    times : (n,) float64, or (0,)
        Each sample's time in the shutter (scenes with moving objects).
    geometry, surface, lights, env, options, whitted, motion, instances, photon_map : tuples
        The records described in the module notes.
    radiance : (n, 3) float64
        Output.
    light_paths : (n, LIGHT_PATHS, 3) float64, or (0, LIGHT_PATHS, 3)
        Output of the light-path passes, with ``split``.
    counts : (len(COUNTER_NAMES),) int64
        Rays traced (active lanes only) by :data:`rtmesh.rendering.path_packets.COUNTER_NAMES`,
        added to: camera, bounce and shadow rays (whitted: camera, reflection, refraction,
        BSDF-sampled, cut-out, shadow, area-light shadow and environment shadow rays).
    """
    # read through views that own nothing: no reference counts in the per-lane rows
    # (rtmesh.core.compiled.borrowed; the caller holds the arrays)
    geometry, surface, lights, env, options, whitted, motion, instances, photon_map = borrowed(
        (geometry, surface, lights, env, options, whitted, motion, instances, photon_map))
    origins, directions, keys, pixels, samples, sobol_keys, times, radiance, light_paths, counts = borrowed(
        (origins, directions, keys, pixels, samples, sobol_keys, times, radiance, light_paths, counts))
    n = origins.shape[0]
    material_id = geometry[5]
    tags, transmissive, slots = surface[0], surface[2], surface[7]
    absorption, unlit, albedo_table = surface[4], surface[5], surface[6]
    textured = textured_materials(surface, geometry)
    light_rows, light_probability, light_alias, light_pmf, face_light, analytic, env_light, light_texels, \
        light_descriptors = lights
    (max_depth, rr_depth, clamp, offset_scale, background_seen, cutouts, split, camera_media, light_samples,
     light_block) = options
    media = len(camera_media)
    (whitted_on, delta_rows, group_start, group_order, group_probability, group_alias, group_pmf, ambient,
     occlusion_strength, cutoff, exact_fresnel, branch_depth, ao_samples, ao_distance) = whitted
    # which light a light sample takes: one by power among all (path), or every delta light
    # once and light_samples of each other light (whitted: LightTable.light_groups, the
    # emissive triangles one light); the density of a light's choice, for MIS
    deltas = len(delta_rows) if whitted_on else 0
    choice_pmf = group_pmf if whitted_on else light_pmf
    area_rounds = light_samples * (len(group_start) - 1) if whitted_on else light_samples
    env_pixels, env_marginal, env_conditional, env_func, env_mean, env_cos, env_sin = env
    moves, face_mover = motion[5], motion[6]
    instance_faces, instance_to_world, instance_normals = instances
    has_lights = len(light_rows) > 0
    photons_on, scatters = photon_map[0], photon_map[10]
    radius_scale, footprint_a, footprint_b, max_radius = photon_map[6], photon_map[7], photon_map[8], photon_map[9]
    ray, words, valid, args_coherent = packet_buffers(np.int64(RAYHIT_WORDS), np.int64(1),
                                                      np.int64(RTC_RAY_QUERY_FLAG_COHERENT))
    args_incoherent = query_arguments(np.int64(RTC_RAY_QUERY_FLAG_INCOHERENT))
    shadow, shadow_words, shadow_valid, _ = packet_buffers(np.int64(RAYHIT_WORDS), np.int64(1),
                                                           np.int64(RTC_RAY_QUERY_FLAG_INCOHERENT))
    # a mover's packet (its rest frame), and the nearest hit of each lane over the scenes
    rest, rest_words, rest_valid, _ = packet_buffers(np.int64(RAYHIT_WORDS), np.int64(1),
                                                     np.int64(RTC_RAY_QUERY_FLAG_INCOHERENT))
    best_t = np.zeros(LANES)
    best_prim = np.zeros(LANES, np.int64)
    best_instance = np.full(LANES, -1, np.int64)
    best_u = np.zeros(LANES)
    best_v = np.zeros(LANES)
    # the shadow packet's rays in float64 (origins, directions) for the movers' rest frames
    segment = np.zeros((6, LANES))
    lane_time = np.zeros(LANES)
    # each lane's light row carried to its time (an emissive triangle of a moving object)
    moved = np.zeros((LANES, lt.WIDTH))
    scratch = np.zeros((LANES, lobes.PARAMETER_WIDTH))
    px = np.zeros(LANES)
    py = np.zeros(LANES)
    pz = np.zeros(LANES)
    dx = np.zeros(LANES)
    dy = np.zeros(LANES)
    dz = np.zeros(LANES)
    beta = np.zeros((LANES, 3))
    total = np.zeros((LANES, 3))
    # per light sample of a vertex (rtmesh.rendering.settings.RenderSettings.light_samples):
    # each lane's shadow ray (origin, direction, length) and the light it brings if free
    # (whitted: then ao_samples ambient-occlusion rays)
    light_slots = deltas + area_rounds + ao_samples
    shadow_rays = np.zeros((light_slots, LANES, 7))
    shadow_set = np.zeros((light_slots, LANES), np.bool_)
    shadow_count = np.zeros(light_slots, np.int64)
    shadow_kind = np.full(light_slots, SHADOW, np.int64)
    pending = np.zeros((light_slots, LANES, 3))
    paths = np.zeros((LANES, LIGHT_PATHS, 3))
    pending_paths = np.zeros((light_slots if split else 1, LANES, LIGHT_PATHS, 3))
    category = np.zeros(LANES, np.int64)
    stack = np.full((LANES, max(media, 1)), -1, np.int64)
    # whitted: the rays a lane's hits split off, followed when its current ray ends
    branch = np.zeros((LANES, branch_depth, BRANCH_WORDS))
    branch_media = np.full((LANES, branch_depth, max(media, 1)), -1, np.int64)
    branch_top = np.zeros(LANES, np.int64)
    sigma = np.zeros((LANES, 3))
    reach = np.zeros(LANES)
    alive = np.zeros(LANES, np.bool_)
    prev_pdf = np.zeros(LANES)
    prev_delta = np.zeros(LANES, np.bool_)
    # the product of eta'^2 over the path's crossings (undoes their radiance scaling)
    eta_scale = np.ones(LANES)
    # light samples taken at the path's last vertex (the light strategy's sample count in the
    # MIS weight of emission its BSDF sample meets)
    prev_count = np.ones(LANES)
    lane_depth = np.zeros(LANES, np.int64)
    layers = np.zeros(LANES, np.int64)
    # with photons: the path's last vertices (CHAIN_*), its length so far (the gather radius)
    chain = np.zeros(LANES, np.int64)
    travelled = np.zeros(LANES)
    # what each lane's ray is, for the counters (whitted)
    ray_kind = np.zeros(LANES, np.int64)
    # the scratch arrays too, through views that own nothing (owned stays alive to the end)
    owned = (ray, words, valid, args_coherent, args_incoherent, shadow, shadow_words, shadow_valid, rest, rest_words,
             rest_valid, best_t, best_prim, best_instance, best_u, best_v, segment, lane_time, moved, scratch, px,
             py, pz, dx, dy, dz, beta, total, shadow_rays, shadow_set, shadow_count, pending, paths, pending_paths,
             category, stack, branch, branch_media, branch_top, sigma, reach, alive, prev_pdf, prev_delta, eta_scale,
             prev_count, lane_depth, layers, chain, travelled, ray_kind, shadow_kind)
    (ray, words, valid, args_coherent, args_incoherent, shadow, shadow_words, shadow_valid, rest, rest_words,
     rest_valid, best_t, best_prim, best_instance, best_u, best_v, segment, lane_time, moved, scratch, px,
     py, pz, dx, dy, dz, beta, total, shadow_rays, shadow_set, shadow_count, pending, paths, pending_paths,
     category, stack, branch, branch_media, branch_top, sigma, reach, alive, prev_pdf, prev_delta, eta_scale,
     prev_count, lane_depth, layers, chain, travelled, ray_kind, shadow_kind) = borrowed(owned)
    for start in range(0, n, LANES):
        count = min(LANES, n - start)
        for lane in range(LANES):
            alive[lane] = lane < count
            branch_top[lane] = 0
            ray_kind[lane] = CAMERA
            if lane < count:
                i = start + lane
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
        first = True
        while True:
            if whitted_on:
                for lane in range(LANES):
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
            if load_lanes(alive, ray, words, valid, px, py, pz, dx, dy, dz, DEFAULT_TFAR) == 0:
                break
            for lane in range(LANES):
                if alive[lane]:
                    counts[ray_kind[lane] if whitted_on else (CAMERA if lane_depth[lane] == 0 else BOUNCE)] += 1
            args = args_coherent if first else args_incoherent
            first = False
            nearest_hits(intersect16, scene, args, args_incoherent, ray, words, valid, motion, instance_faces,
                          lane_time, px, py, pz, dx, dy, dz, rest, rest_words, rest_valid, best_t, best_prim,
                          best_instance, best_u, best_v)
            for lane in range(LANES):
                if not alive[lane]:
                    continue
                key = keys[start + lane]
                depth = lane_depth[lane]
                base = DIMENSIONS_PER_VERTEX * depth
                limit = clamp if depth > 1 else 0.0
                hit = best_prim[lane] >= 0
                t = best_t[lane]
                # a visible quad or disk light before the surface ends the path there
                seen = -1
                # (within lt.FLUSH_MARGIN of the surface: a light flush with a ceiling is seen)
                for k in range(len(analytic)):
                    a = analytic[k]
                    ta = hit_analytic(light_rows[a], px[lane], py[lane], pz[lane], dx[lane], dy[lane], dz[lane],
                                      t * lt.FLUSH_MARGIN)
                    if ta < t * lt.FLUSH_MARGIN:
                        t, seen = ta, a
                if sigma[lane, 0] + sigma[lane, 1] + sigma[lane, 2] > 0.0 and t < math.inf:
                    for c in range(3):
                        beta[lane, c] *= math.exp(-sigma[lane, c] * t)
                # with photons, light reached through a non-delta vertex and then delta bounces
                # only is theirs (caustic paths): the camera path does not count it again
                photon_path = photons_on and chain[lane] == CHAIN_CAUSTIC
                if seen >= 0 and photon_path:
                    alive[lane] = False
                    continue
                if seen >= 0:
                    light = light_rows[seen]
                    w = 1.0
                    if not prev_delta[lane]:
                        w = power_heuristic(prev_pdf[lane], choice_pmf[seen] * area_pdf(
                            light, px[lane], py[lane], pz[lane], dx[lane], dy[lane], dz[lane], t) * prev_count[lane])
                    r, g, b = clamped(beta[lane, 0] * light[lt.RADIANCE] * w, beta[lane, 1] * light[lt.RADIANCE + 1] * w,
                                       beta[lane, 2] * light[lt.RADIANCE + 2] * w, limit)
                    add_radiance(total, lane, r, g, b)
                    add_to_pass(paths, split, lane, pass_bucket(depth, category[lane]), r, g, b)
                    alive[lane] = False
                    continue
                if not hit:
                    # (whitted: what mirrors and glass show of the background, lighting or not)
                    if ((env_light >= 0) & (not photon_path) | ((depth == 0) & background_seen)
                            | (whitted_on & (depth > 0) & prev_delta[lane])):
                        if env_pixels.shape[0] == 1:
                            # a uniform background (one row of one texel): no lookup
                            lr, lg, lb = env_pixels[0, 0, 0], env_pixels[0, 0, 1], env_pixels[0, 0, 2]
                        else:
                            lr, lg, lb = _environment_radiance(env_pixels, env_cos, env_sin, dx[lane], dy[lane],
                                                               dz[lane])
                        w = 1.0
                        if not prev_delta[lane]:
                            w = power_heuristic(prev_pdf[lane], choice_pmf[env_light] * environment_pdf(
                                env_marginal, env_conditional, env_func, env_mean, env_cos, env_sin,
                                dx[lane], dy[lane], dz[lane]) * prev_count[lane])
                        r, g, b = clamped(beta[lane, 0] * lr * w, beta[lane, 1] * lg * w, beta[lane, 2] * lb * w,
                                           limit)
                        add_radiance(total, lane, r, g, b)
                        add_to_pass(paths, split, lane, pass_bucket(depth, category[lane]), r, g, b)
                    alive[lane] = False
                    continue
                prim = best_prim[lane]
                bu, bv = best_u[lane], best_v[lane]
                mat = material_id[prim]
                travelled[lane] += t
                hx, hy, hz, gx, gy, gz, nx, ny, nz = surface_point(geometry, prim, bu, bv)
                if len(face_mover) and face_mover[prim] >= 0:
                    hx, hy, hz, gx, gy, gz, nx, ny, nz = mover_to_world(moves, face_mover[prim], lane_time[lane], hx, hy, hz,
                                                                   gx, gy, gz, nx, ny, nz)
                if best_instance[lane] >= 0:
                    hx, hy, hz, gx, gy, gz, nx, ny, nz = placed(instance_to_world, instance_normals, best_instance[lane],
                                                                 hx, hy, hz, gx, gy, gz, nx, ny, nz)
                if cutouts and layers[lane] + 1 < MAX_LAYERS and is_transparent(
                        surface, geometry, mat, prim, bu, bv, layer_coin(key, depth, layers[lane], COVERAGE)):
                    # the ray passes this layer: on from just beyond it, same depth
                    layers[lane] += 1
                    ray_kind[lane] = CUTOUT
                    px[lane], py[lane], pz[lane] = leave_surface(hx, hy, hz, gx, gy, gz, dx[lane], dy[lane], dz[lane],
                                                                 offset_scale)
                    continue
                layers[lane] = 0
                bsdf_params, bsdf_row, er, eg, eb = hit_parameters(
                    surface, geometry, textured, mat, prim, bu, bv, scratch, lane, stack, media,
                    (gx * dx[lane] + gy * dy[lane]) + gz * dz[lane] < 0.0)
                # emission, from the front side (the winding's normal), as pbrt's and Mitsuba's
                # area lights (whitted: from both)
                front = (gx * dx[lane] + gy * dy[lane]) + gz * dz[lane] < 0.0
                if (front or whitted_on) and er + eg + eb > 0.0 and not photon_path:
                    w = 1.0
                    if not prev_delta[lane]:
                        light = face_light[prim]
                        if light >= 0:
                            w = power_heuristic(prev_pdf[lane], choice_pmf[light] * area_pdf(
                                light_at(light_rows, light, face_mover, moves, lane_time[lane], moved, lane),
                                px[lane], py[lane], pz[lane], dx[lane], dy[lane], dz[lane], t) * prev_count[lane])
                    r, g, b = clamped(beta[lane, 0] * er * w, beta[lane, 1] * eg * w, beta[lane, 2] * eb * w, limit)
                    add_radiance(total, lane, r, g, b)
                    add_to_pass(paths, split, lane, pass_bucket(depth, category[lane]), r, g, b)
                if unlit[mat, 0] > 0.0:
                    add_radiance(total, lane, beta[lane, 0] * unlit[mat, 1], beta[lane, 1] * unlit[mat, 2],
                         beta[lane, 2] * unlit[mat, 3])
                    add_to_pass(paths, split, lane, pass_bucket(depth, category[lane]), beta[lane, 0] * unlit[mat, 1],
                              beta[lane, 1] * unlit[mat, 2], beta[lane, 2] * unlit[mat, 3])
                    alive[lane] = False
                    continue
                # the shading frame: normal maps bend the front side's normal; reflection-only
                # models turn the frame to the viewer's side, transmissive ones keep the
                # outward side (inside: wo.z < 0)
                ox, oy, oz = -dx[lane], -dy[lane], -dz[lane]
                gx, gy, gz, nx, ny, nz, tx, ty, tz, sx, sy, sz = hit_frame(
                    surface, geometry, mat, prim, bu, bv, transmissive[mat], scratch, lane, gx, gy, gz, nx, ny, nz,
                    ox, oy, oz)
                lox = (tx * ox + ty * oy) + tz * oz
                loy = (sx * ox + sy * oy) + sz * oz
                loz = (nx * ox + ny * oy) + nz * oz
                tag = tags[mat]
                follow = (max_depth < 0) | (depth + 1 <= max_depth)
                # whitted: Blinn-Phong hits light by Whitted's factor and split into their mirror
                # and refracted rays (rtmesh.rendering.whitted_rows); every hit takes the ambient
                # light (tinted by the colour's textures, darkened by glTF's baked occlusion)
                whitted_hit = whitted_on and tag == models.BLINN_PHONG
                ambient_r = ambient_g = ambient_b = 0.0
                if whitted_on and (ambient[mat, 0] > 0.0) | (ambient[mat, 1] > 0.0) | (ambient[mat, 2] > 0.0):
                    cr, cg, cb, _, _, _ = colour_tint(surface, geometry, mat, prim, bu, bv)
                    occluded_part = occlusion_at(surface, geometry, mat, prim, bu, bv, occlusion_strength[mat])
                    ambient_r = beta[lane, 0] * (ambient[mat, 0] * cr * occluded_part)
                    ambient_g = beta[lane, 1] * (ambient[mat, 1] * cg * occluded_part)
                    ambient_b = beta[lane, 2] * (ambient[mat, 2] * cb * occluded_part)
                    if ao_samples == 0:
                        add_radiance(total, lane, ambient_r, ambient_g, ambient_b)
                # caustics: the photons near this vertex (paths of at least two segments)
                segments = max_depth - depth if max_depth >= 0 else -1
                if photons_on and scatters[mat] and (segments < 0 or segments >= 2):
                    radius = min(radius_scale * (footprint_a + footprint_b * travelled[lane]), max_radius)
                    cr, cg, cb = gather(photon_map, hx, hy, hz, gx, gy, gz, radius, segments, tag, bsdf_params,
                                        bsdf_row, albedo_table, tx, ty, tz, sx, sy, sz, nx, ny, nz, lox, loy, loz, ALL_PARTS)
                    cr, cg, cb = clamped(beta[lane, 0] * cr, beta[lane, 1] * cg, beta[lane, 2] * cb,
                                          clamp if depth > 0 else 0.0)
                    add_radiance(total, lane, cr, cg, cb)
                    if split:
                        if depth == 0:
                            # split by the part of the BSDF the photons' light comes through
                            dr, dg, db = gather(photon_map, hx, hy, hz, gx, gy, gz, radius, segments, tag,
                                                bsdf_params, bsdf_row, albedo_table, tx, ty, tz, sx, sy, sz, nx, ny,
                                                nz, lox, loy, loz, DIFFUSE_PART)
                            ur, ug, ub = gather(photon_map, hx, hy, hz, gx, gy, gz, radius, segments, tag,
                                                bsdf_params, bsdf_row, albedo_table, tx, ty, tz, sx, sy, sz, nx, ny,
                                                nz, lox, loy, loz, TRANSMITTED_PART)
                            dr, dg, db = beta[lane, 0] * dr, beta[lane, 1] * dg, beta[lane, 2] * db
                            ur, ug, ub = beta[lane, 0] * ur, beta[lane, 1] * ug, beta[lane, 2] * ub
                            add_to_pass(paths, split, lane, INDIRECT + DIFFUSE_PATH, dr, dg, db)
                            add_to_pass(paths, split, lane, INDIRECT + TRANSMISSION_PATH, ur, ug, ub)
                            add_to_pass(paths, split, lane, INDIRECT + GLOSSY_PATH, cr - (dr + ur), cg - (dg + ug),
                                      cb - (db + ub))
                        else:
                            add_to_pass(paths, split, lane, INDIRECT + category[lane], cr, cg, cb)
                # the first vertex's light and BSDF points: per-pixel Owen-scrambled Sobol pairs
                # (stratified over the pixel's samples; its light points over the pixel's
                # samples and each sample's light samples), later vertices' hashed numbers
                sample_index = samples[start + lane] if len(samples) else -1
                sobol = (depth == 0) & (sample_index >= 0) & (sample_index < SOBOL_LIMIT)
                pixel = np.uint64(pixels[start + lane]) if sobol else np.uint64(0)
                if sobol:
                    bu1, bu2 = sequence_pair(sobol_keys, 1, pixel, sample_index)
                else:
                    bu1, bu2 = uniform(key, base + BSDF_U1), uniform(key, base + BSDF_U2)
                # next-event estimation: light_samples estimates at the first vertex that can
                # take light (reached from the camera through delta lobes only), one at later
                # vertices; each weighted against the one BSDF sample by the power heuristic
                # with the strategies' sample counts (Veach 1997, 9.2.2) and divided by their number
                # (whitted: every delta light once, then light_samples among the others, at every vertex)
                area_count = area_rounds if whitted_on or chain[lane] == CHAIN_START else 1
                rounds = deltas + area_count
                prev_count[lane] = np.float64(light_samples if whitted_on else area_count)
                if follow and has_lights:
                    for k in range(rounds):
                        light_key = key if k == 0 else mix64(key + np.uint64(k) * _LIGHT_ROUND)
                        # kk: the light sample's index among its light's (-1: a delta light)
                        kk = k - deltas
                        group = 0
                        if whitted_on and kk >= 0:
                            group = kk // light_samples
                            kk -= group * light_samples
                        if kk < 0:
                            lu1 = lu2 = 0.5
                        elif sobol and sample_index * light_samples + kk < SOBOL_LIMIT:
                            lu1, lu2 = sequence_ray_pair(sobol_keys, 0, pixel, sample_index, kk, light_samples,
                                                         light_block)
                        else:
                            lu1, lu2 = uniform(light_key, base + LIGHT_U1), uniform(light_key, base + LIGHT_U2)
                        if kk < 0:
                            chosen, count_f = delta_rows[k], 1.0
                        elif whitted_on:
                            lo, hi = group_start[group], group_start[group + 1]
                            chosen = group_order[lo + alias_sample(group_probability[lo:hi], group_alias[lo:hi],
                                                                   uniform(light_key, base + LIGHT_CHOICE))]
                            count_f = np.float64(light_samples)
                        else:
                            chosen = alias_sample(light_probability, light_alias, uniform(light_key, base + LIGHT_CHOICE))
                            count_f = np.float64(area_count)
                        nee_limit = (clamp if depth > 0 else 0.0) / count_f
                        # an emitter on a moving object where it is at the lane's time
                        light = light_at(light_rows, chosen, face_mover, moves, lane_time[lane], moved, lane)
                        wx, wy, wz, distance, lr, lg, lb, pdf_li, delta, b1, b2 = sample_li(
                            light, env, light_texels, light_descriptors, hx, hy, hz, lu1, lu2)
                        if light[0] == lt.TRIANGLE and pdf_li > 0.0:
                            # the emitter's own (textured) radiance at the sampled point
                            lr, lg, lb = triangle_light_emission(surface, geometry, light, b1, b2)
                        if not ((pdf_li > 0.0) & ((lr > 0.0) | (lg > 0.0) | (lb > 0.0))):
                            continue
                        side = (gx * wx + gy * wy) + gz * wz
                        if not (transmissive[mat] or side > 0.0):
                            continue
                        lix = (tx * wx + ty * wy) + tz * wz
                        liy = (sx * wx + sy * wy) + sz * wz
                        liz = (nx * wx + ny * wy) + nz * wz
                        if whitted_hit:
                            fr, fg, fbb = light_factor(bsdf_params, bsdf_row, lox, loy, loz, lix, liy, liz)
                            pdf_bsdf = 0.0
                        else:
                            fr, fg, fbb, pdf_bsdf = models.evaluate(tag, bsdf_params, bsdf_row, albedo_table, lox, loy,
                                                                    loz, lix, liy, liz)
                        if not ((fr > 0.0) | (fg > 0.0) | (fbb > 0.0)):
                            continue
                        p_light = (1.0 if kk < 0 else choice_pmf[chosen]) * pdf_li
                        w = 1.0 if delta else power_heuristic(p_light * count_f, pdf_bsdf)
                        scale = w / (p_light * count_f)
                        pending[k, lane, 0], pending[k, lane, 1], pending[k, lane, 2] = clamped(
                            beta[lane, 0] * fr * lr * scale, beta[lane, 1] * fg * lg * scale,
                            beta[lane, 2] * fbb * lb * scale, nee_limit)
                        if split:
                            pending_paths[k, lane, :, :] = 0.0
                            if depth == 0:
                                # split by the part of the BSDF the light comes through
                                dr, dg, db, ur, ug, ub = models.parts(tag, bsdf_params, bsdf_row, albedo_table,
                                                                      lox, loy, loz, lix, liy, liz)
                                cr, cg, cb = (beta[lane, 0] * lr * scale, beta[lane, 1] * lg * scale,
                                              beta[lane, 2] * lb * scale)
                                add_to_pass(pending_paths[k], split, lane, DIRECT + DIFFUSE_PATH,
                                          dr * cr, dg * cg, db * cb)
                                add_to_pass(pending_paths[k], split, lane, DIRECT + TRANSMISSION_PATH,
                                          ur * cr, ug * cg, ub * cb)
                                add_to_pass(pending_paths[k], split, lane, DIRECT + GLOSSY_PATH,
                                          pending[k, lane, 0] - (dr + ur) * cr, pending[k, lane, 1] - (dg + ug) * cg,
                                          pending[k, lane, 2] - (db + ub) * cb)
                            else:
                                add_to_pass(pending_paths[k], split, lane, INDIRECT + category[lane],
                                          pending[k, lane, 0], pending[k, lane, 1], pending[k, lane, 2])
                        # its shadow ray, traced with the packet's others of this light sample
                        ray_k = shadow_rays[k, lane]
                        ray_k[0], ray_k[1], ray_k[2], ray_k[3], ray_k[4], ray_k[5], ray_k[6] = shadow_segment(
                            hx, hy, hz, gx, gy, gz, wx, wy, wz, distance, delta, light, offset_scale)
                        shadow_set[k, lane] = True
                        shadow_count[k] += 1
                        if whitted_on:
                            shadow_kind[k] = SHADOW if delta else (ENVIRONMENT if light[0] == lt.ENVIRONMENT
                                                                   else AREA_SHADOW)
                if ao_samples > 0 and (ambient_r > 0.0) | (ambient_g > 0.0) | (ambient_b > 0.0):
                    # ambient occlusion (whitted): the ambient term over ao_samples cosine-weighted
                    # rays about the geometric normal (on the viewer's side), each counting if
                    # nothing lies within ao_distance
                    if (gx * ox + gy * oy) + gz * oz < 0.0:
                        ux, uy, uz = -gx, -gy, -gz
                    else:
                        ux, uy, uz = gx, gy, gz
                    ax, ay, az, cx, cy, cz = tangent_frame(ux, uy, uz)
                    for j in range(ao_samples):
                        k = deltas + area_rounds + j
                        ao_key = mix64(key + np.uint64(k) * _LIGHT_ROUND)
                        lx, ly, lz = square_to_cosine_hemisphere_row(uniform(ao_key, base + LIGHT_U1),
                                                                     uniform(ao_key, base + LIGHT_U2))
                        wx, wy, wz = (ax * lx + cx * ly) + ux * lz, (ay * lx + cy * ly) + uy * lz, (az * lx + cz * ly) + uz * lz
                        ray_k = shadow_rays[k, lane]
                        ray_k[0], ray_k[1], ray_k[2] = leave_surface(hx, hy, hz, ux, uy, uz, wx, wy, wz, offset_scale)
                        ray_k[3], ray_k[4], ray_k[5], ray_k[6] = wx, wy, wz, ao_distance
                        pending[k, lane, 0] = ambient_r / ao_samples
                        pending[k, lane, 1] = ambient_g / ao_samples
                        pending[k, lane, 2] = ambient_b / ao_samples
                        shadow_set[k, lane] = True
                        shadow_count[k] += 1
                        shadow_kind[k] = AO
                if not follow or (whitted_on and depth + 2 > max_depth):
                    # (whitted: the last hit a ray may reach takes light, but sends no ray on)
                    alive[lane] = False
                    continue
                if whitted_hit:
                    # the Whitted split: on along the refracted ray (or the mirror ray), the
                    # other kept for later; rays whose throughput falls under the cutoff are not followed
                    rx, ry, rz, wr, wg, wb, ux, uy, uz, ur, ug, ub = branches(
                        bsdf_params, bsdf_row, ox, oy, oz, nx, ny, nz, gx, gy, gz, front, exact_fresnel, bu1, bu2)
                    reflects = max(beta[lane, 0] * wr, max(beta[lane, 1] * wg, beta[lane, 2] * wb)) >= cutoff
                    refracts = max(beta[lane, 0] * ur, max(beta[lane, 1] * ug, beta[lane, 2] * ub)) >= cutoff
                    reflects &= (wr > 0.0) | (wg > 0.0) | (wb > 0.0)
                    refracts &= (ur > 0.0) | (ug > 0.0) | (ub > 0.0)
                    if reflects and refracts:
                        qx, qy, qz = leave_surface(hx, hy, hz, gx, gy, gz, rx, ry, rz, offset_scale)
                        push_branch(branch, branch_media, branch_top, lane, qx, qy, qz, rx, ry, rz,
                                    beta[lane, 0] * wr, beta[lane, 1] * wg, beta[lane, 2] * wb, depth + 1, stack)
                    if refracts:
                        rx, ry, rz, wr, wg, wb = ux, uy, uz, ur, ug, ub
                        if media:
                            top = cross_interface(stack, lane, mat, front, twin_material(surface, prim))
                            for c in range(3):
                                sigma[lane, c] = absorption[top, c] if top >= 0 else 0.0
                    elif not reflects:
                        alive[lane] = False
                        continue
                    beta[lane, 0] *= wr
                    beta[lane, 1] *= wg
                    beta[lane, 2] *= wb
                    ray_kind[lane] = REFRACTION if refracts else REFLECTION
                    prev_pdf[lane] = 0.0
                    prev_delta[lane] = True
                    px[lane], py[lane], pz[lane] = leave_surface(hx, hy, hz, gx, gy, gz, rx, ry, rz, offset_scale)
                    dx[lane], dy[lane], dz[lane] = rx, ry, rz
                    lane_depth[lane] = depth + 1
                    continue
                # continue the path by sampling the BSDF
                wx, wy, wz, gr, gg, gb, pdf, flags = models.sample(
                    tag, bsdf_params, bsdf_row, albedo_table, lox, loy, loz, uniform(key, base + LOBE), bu1, bu2)
                if (flags == lobes.FAILED) | (not ((gr > 0.0) | (gg > 0.0) | (gb > 0.0))):
                    alive[lane] = False
                    continue
                ndx, ndy, ndz = to_world(wx, wy, wz, tx, ty, tz, sx, sy, sz, nx, ny, nz)
                side = (gx * ndx + gy * ndy) + gz * ndz
                if (not transmissive[mat]) and not side > 0.0:
                    # a shading-normal sample below the geometric surface
                    alive[lane] = False
                    continue
                beta[lane, 0] *= gr
                beta[lane, 1] *= gg
                beta[lane, 2] *= gb
                ray_kind[lane] = REFRACTION if flags & lobes.TRANSMISSION else BSDF
                prev_pdf[lane] = pdf
                prev_delta[lane] = (flags & lobes.DELTA) != 0
                if prev_delta[lane]:
                    chain[lane] = CHAIN_CAUSTIC if chain[lane] != CHAIN_START else CHAIN_START
                else:
                    chain[lane] = CHAIN_SCATTERED
                if depth == 0:
                    category[lane] = lobe_category(flags)
                if transmissive[mat] and (flags & lobes.TRANSMISSION) and media:
                    # into the interior when the outward normal faces away from the new ray
                    top = cross_interface(stack, lane, mat, side < 0.0, twin_material(surface, prim))
                    for c in range(3):
                        sigma[lane, c] = absorption[top, c] if top >= 0 else 0.0
                # the radiance scaling 1 / eta'^2 of a refraction, kept apart for the roulette
                # (pbrt-v4's etaScale)
                eta_scale[lane] *= crossing_scale(slots, tag, bsdf_params, bsdf_row, loz, flags)
                if depth + 1 >= rr_depth:
                    # on the throughput without the radiance scaling of the crossings: inside
                    # glass (1 / 1.5^2 of it) paths would otherwise end by roulette without
                    # carrying less light out, only noise
                    q = max(beta[lane, 0], max(beta[lane, 1], beta[lane, 2])) * eta_scale[lane]
                    if q < 1.0:
                        if uniform(key, base + ROULETTE) >= q:
                            alive[lane] = False
                            continue
                        beta[lane, 0] /= q
                        beta[lane, 1] /= q
                        beta[lane, 2] /= q
                px[lane], py[lane], pz[lane] = leave_surface(hx, hy, hz, gx, gy, gz, ndx, ndy, ndz, offset_scale)
                dx[lane], dy[lane], dz[lane] = ndx, ndy, ndz
                lane_depth[lane] = depth + 1
            # the shadow rays: one packet per light sample of the vertices
            for k in range(light_slots):
                if shadow_count[k] == 0:
                    continue
                counts[shadow_kind[k]] += shadow_count[k]
                shadow_count[k] = 0
                for lane in range(LANES):
                    shadow_valid[lane] = 0
                    if shadow_set[k, lane]:
                        shadow_set[k, lane] = False
                        ray_k = shadow_rays[k, lane]
                        reach[lane] = ray_k[6]
                        set_lane(shadow, shadow_words, lane, ray_k[0], ray_k[1], ray_k[2], ray_k[3], ray_k[4],
                                 ray_k[5], np.float32(reach[lane]))
                        shadow_valid[lane] = -1
                if cutouts:
                    shadows_through_cutouts(intersect16, scene, args_incoherent, shadow, shadow_words, shadow_valid,
                                             geometry, surface, offset_scale, keys, start, lane_depth, reach, counts,
                                             motion, lane_time, segment, rest, rest_words, rest_valid, best_t,
                                             best_prim, best_u, best_v, (k + 1) * MAX_LAYERS)
                else:
                    occluded(occluded16, scene, args_incoherent, shadow, shadow_valid, motion, lane_time, reach,
                              rest, rest_words, rest_valid)
                accept_shadows(shadow_valid, pending[k], pending_paths[k if split else 0], split, total, paths)
        for lane in range(count):
            radiance[start + lane, 0] = total[lane, 0]
            radiance[start + lane, 1] = total[lane, 1]
            radiance[start + lane, 2] = total[lane, 2]
            if split:
                for bucket in range(LIGHT_PATHS):
                    for c in range(3):
                        light_paths[start + lane, bucket, c] = paths[lane, bucket, c]
    keep_alive(owned)
