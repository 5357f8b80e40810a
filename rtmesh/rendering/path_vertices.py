"""The path kernel's work at a vertex, as stages over a block of lanes: what each lane's
segment meets (:func:`meet`), its next-event estimates and ambient-occlusion rays
(:func:`sample_lights`), and the ray that continues it
(:func:`rtmesh.rendering.path_scatter.scatter`).

:func:`rtmesh.rendering.path_kernel.trace_paths` calls them once per block of
:data:`WIDTH` lanes and bounce, in that order, between its packet queries, through their
entry points (:func:`rtmesh.core.compiled.call_at`).  Each is a kernel of its own, compiled
and cached by itself: one function holding them all took numba about 60 s to compile (its
front end's passes grow faster than the function), and a first run's two processes compile
them side by side (:data:`rtmesh.rendering.path_signatures.PATH_KERNELS`).  A call per
block, not per lane: each call passes every array of its records (numba's calling
convention), which per lane would cost as much as the lane's arithmetic.

Records: ``lanes`` (per-lane state, :data:`LANE_RECORD`), ``hits`` (each lane's nearest
hit: ``t``, primitive, placement, barycentrics), ``vertices = (vertex, vertex_ids, shaded)``
(what :func:`meet` leaves for the other two: ``vertex`` (16, :data:`VERTEX_WORDS`) the
hit point, geometric and shading normals, tangent frame, the direction toward where the
ray came from in that frame and the ambient term, by :data:`POINT` ... :data:`AMBIENT`;
``vertex_ids`` (16, 4) int64 the material, face, parameter row and whether that row is the
lane's ``scratch`` copy; ``shaded`` which lanes reached a surface to shade), ``shadows =
(rays, set, count, kind, pending, pending_paths)`` (each light sample's shadow rays and
what they carry) and ``branches = (branch, branch_media, branch_top)`` (the Whitted
configuration's split rays); the scene's records (``geometry``, ``surface``, ``lights``,
``env``, ``options``, ``whitted``, ``motion``, ``instances``, ``photon_map``) as
:mod:`rtmesh.rendering.path_kernel` describes them.
"""

import math

import numpy as np

from rtmesh.core.compiled import borrowed, inline_row, stage
from rtmesh.geometry.embree_packets import LANES
from rtmesh.lights import light_table as lt
from rtmesh.lights.environment_table import latlong_uv
from rtmesh.lights import light_tree
from rtmesh.materials import models
from rtmesh.materials.metallic_roughness import square_to_cosine_hemisphere_row
from rtmesh.rendering.path_camera_hits import HIT_AO_HERE, record_camera_hit
from rtmesh.rendering.path_lights import area_pdf, environment_pdf_uv, hit_analytic, light_at, sample_li, shadow_segment
from rtmesh.rendering.path_packets import (AO, AREA_SHADOW, COVERAGE, CUTOUT, DIMENSIONS_PER_VERTEX, ENVIRONMENT,
                                           LIGHT_CHOICE, LIGHT_U1, LIGHT_U2, MAX_LAYERS, SHADOW, layer_coin,
                                           mover_to_world, placed)
from rtmesh.rendering.path_surfaces import (alias_sample, colour_tint, environment_radiance_uv, hit_frame,
                                            hit_parameters, is_transparent, leave_surface, occlusion_at, surface_point,
                                            tangent_frame, triangle_light_emission)
from rtmesh.rendering.path_sums import (DIFFUSE_PATH, DIRECT, GLOSSY_PATH, INDIRECT, TRANSMISSION_PATH, add_radiance,
                                        add_to_pass, clamped, pass_bucket)
from rtmesh.rendering.photon_kernel import ALL_PARTS, DIFFUSE_PART, TRANSMITTED_PART, gather
from rtmesh.rendering.whitted_rows import light_factor
from rtmesh.sampling.alias import alias_sample_remapped
from rtmesh.sampling.hashing import mix64, uniform
from rtmesh.sampling.mis import power_heuristic
from rtmesh.sampling.zsobol import seeded_ray_pair, sequence_number, sequence_seeds

# Sobol sequences hold 2**32 points; later samples take hashed numbers
SOBOL_LIMIT = 1 << 32
# the seeds of a vertex past the first (its numbers are hashed, not drawn from a sequence)
_NO_SEEDS = (np.uint64(0), np.uint64(0), np.uint64(0))
# the key of light sample k > 0 of a vertex is mix64(key + k * _LIGHT_ROUND) (sample 0 takes
# the path's own key): its choice and point are the vertex's usual dimensions of that key
_LIGHT_ROUND = np.uint64(0xD1B54A32D192ED03)
# what a path's last vertices were, for caustics: only delta bounces since the camera; a
# non-delta bounce last; a non-delta bounce, then delta bounces only (light met now is a
# caustic path, which photons carry when they are on)
CHAIN_START, CHAIN_SCATTERED, CHAIN_CAUSTIC = 0, 1, 2
# the lanes a call of the stages takes: this many packets of Embree's 16 (a call passes every
# array of its records by value, about a thousand words: measured, Whitted renders at 320x240
# 4 spp took 2-10 % longer than the one-function kernel with 4 packets a call, 1-5 % with 16)
PACKETS = 16
WIDTH = PACKETS * LANES
# the per-lane state of the lanes record, in its order, and each item's index
LANE_RECORD = ("px", "py", "pz", "dx", "dy", "dz", "beta", "total", "paths", "category", "stack", "sigma", "alive",
               "prev_pdf", "prev_delta", "eta_scale", "prev_count", "lane_depth", "layers", "chain", "travelled",
               "ray_kind", "lane_time", "moved", "scratch", "first_hit")
(PX, PY, PZ, DX, DY, DZ, BETA, TOTAL, PATHS, CATEGORY, STACK, SIGMA, ALIVE, PREV_PDF, PREV_DELTA, ETA_SCALE, PREV_COUNT,
 LANE_DEPTH, LAYERS, CHAIN, TRAVELLED, RAY_KIND, LANE_TIME, MOVED, SCRATCH, FIRST_HIT) = range(len(LANE_RECORD))
# a shaded vertex's columns: hit point, geometric normal, shading normal, tangent, bitangent
# (world), the direction toward the ray's origin in the shading frame, the ambient term
POINT, GEOMETRIC, NORMAL, TANGENT, BITANGENT, OUTGOING, AMBIENT = 0, 3, 6, 9, 12, 15, 18
VERTEX_WORDS = 21
# vertex_ids' columns
MATERIAL, FACE, PARAMETER_ROW, IN_SCRATCH, FRONT = 0, 1, 2, 3, 4
VERTEX_IDS = 5


@inline_row
def shaded_vertex(vertex, vertex_ids, lane, scratch, params, tags):
    """A shaded vertex as :func:`meet` left it: its material, face, model tag, parameter table
    and row, then its point, normals, tangent frame and outgoing direction (in that frame):
    5 values and 18 floats."""
    mat = vertex_ids[lane, MATERIAL]
    return (mat, vertex_ids[lane, FACE], tags[mat], scratch if vertex_ids[lane, IN_SCRATCH] else params,
            vertex_ids[lane, PARAMETER_ROW], vertex[lane, 0], vertex[lane, 1], vertex[lane, 2], vertex[lane, 3],
            vertex[lane, 4], vertex[lane, 5], vertex[lane, 6], vertex[lane, 7], vertex[lane, 8], vertex[lane, 9],
            vertex[lane, 10], vertex[lane, 11], vertex[lane, 12], vertex[lane, 13], vertex[lane, 14],
            vertex[lane, 15], vertex[lane, 16], vertex[lane, 17])


@inline_row
def _choice(choice_pmf, by_tree, tree, light, vertex, lane):
    """The probability that next-event estimation at the lane's previous vertex chose
    ``light``: its power share, or the light tree's pmf at that vertex's point and normal."""
    if by_tree:
        return light_tree.light_pmf(tree, light, vertex[lane, 0], vertex[lane, 1], vertex[lane, 2], vertex[lane, 6],
                                    vertex[lane, 7], vertex[lane, 8])
    return choice_pmf[light]


@stage
def meet(lanes, hits, vertices, keys, start, geometry, surface, textured, lights, env, options, whitted, motion,
         instances, photon_map):
    """What each live lane's segment meets: a visible quad or disk light, the background, a
    cut-out layer it passes, or a surface, whose emission it takes (MIS-weighted), whose
    shading frame it forms and, with photons, whose photons it gathers.  Lanes whose path
    ends here are no longer ``alive``; those at a surface to shade are ``shaded``, their
    vertex in ``vertices``.

    Parameters
    ----------
    lanes, hits, vertices : tuples
        The module's records.
    keys : (n,) uint64
        Each sample's random key; lane ``j`` is sample ``start + j``.
    start : int
    textured : (M,) bool
        :func:`rtmesh.rendering.path_surfaces.textured_materials`.
    geometry, surface, lights, env, options, whitted, motion, instances, photon_map : tuples
        The scene's records.
    """
    # views that own nothing, known so here: no reference counts (rtmesh.core.compiled.borrowed)
    lanes, hits, vertices, keys, geometry, surface, textured, lights, env, options, whitted, motion, instances, \
        photon_map = borrowed((lanes, hits, vertices, keys, geometry, surface, textured, lights, env, options, whitted,
                               motion, instances, photon_map))
    (px, py, pz, dx, dy, dz, beta, total, paths, category, stack, sigma, alive, prev_pdf, prev_delta, eta_scale,
     prev_count, lane_depth, layers, chain, travelled, ray_kind, lane_time, moved, scratch, first_hit) = lanes
    vertex, vertex_ids, shaded = vertices
    best_t, best_prim, best_instance, best_u, best_v = hits
    material_id = geometry[5]
    tags, transmissive, unlit, albedo_table = surface[0], surface[2], surface[5], surface[6]
    light_rows, light_pmf, face_light, analytic, env_light = lights[0], lights[3], lights[4], lights[5], lights[6]
    placement_light, tree = lights[9], lights[10]
    max_depth, clamp, offset_scale, background_seen, cutouts, split = (options[0], options[2], options[3], options[4],
                                                                       options[5], options[6])
    media = len(options[7])
    record_hits, pass_albedo = options[10], options[12]
    whitted_on, group_pmf, ambient, occlusion_strength, ao_samples = whitted[0], whitted[6], whitted[7], whitted[8], \
        whitted[12]
    choice_pmf = group_pmf if whitted_on else light_pmf
    # a light tree chooses by the previous vertex (its point and normal, still in vertex)
    by_tree = light_tree.in_use(tree)
    env_pixels, env_func, env_mean, env_cos, env_sin = env[0], env[3], env[4], env[5], env[6]
    moves, face_mover = motion[5], motion[6]
    instance_to_world, instance_normals = instances[1], instances[2]
    photons_on, scatters = photon_map[0], photon_map[10]
    radius_scale, footprint_a, footprint_b, max_radius = photon_map[6], photon_map[7], photon_map[8], photon_map[9]
    for lane in range(len(alive)):
        shaded[lane] = False
        if not alive[lane]:
            continue
        key = keys[start + lane]
        depth = lane_depth[lane]
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
                w = power_heuristic(prev_pdf[lane], _choice(choice_pmf, by_tree, tree, seen, vertex, lane) * area_pdf(
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
                # the map's (u, v) of the direction, once for its radiance and its density
                mapped = env_pixels.shape[0] != 1
                u = v = 0.0
                if mapped or not prev_delta[lane]:
                    u, v = latlong_uv(env_cos, env_sin, dx[lane], dy[lane], dz[lane])
                if mapped:
                    lr, lg, lb = environment_radiance_uv(env_pixels, u, v)
                else:
                    # a uniform background (one row of one texel): no lookup
                    lr, lg, lb = env_pixels[0, 0, 0], env_pixels[0, 0, 1], env_pixels[0, 0, 2]
                w = 1.0
                if not prev_delta[lane]:
                    w = power_heuristic(prev_pdf[lane], _choice(choice_pmf, by_tree, tree, env_light, vertex,
                                                                lane) * environment_pdf_uv(
                        env_func, env_mean, u, v, dy[lane]) * prev_count[lane])
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
        bsdf_params, bsdf_row, er, eg, eb, in_scratch = hit_parameters(
            surface, geometry, textured, mat, prim, bu, bv, scratch, lane, stack, media,
            (gx * dx[lane] + gy * dy[lane]) + gz * dz[lane] < 0.0)
        # emission, from the front side (the winding's normal), as pbrt's and Mitsuba's
        # area lights (whitted: from both)
        front = (gx * dx[lane] + gy * dy[lane]) + gz * dz[lane] < 0.0
        if (front or whitted_on) and er + eg + eb > 0.0 and not photon_path:
            w = 1.0
            if not prev_delta[lane]:
                light = face_light[prim]
                if light >= 0 and best_instance[lane] >= 0:
                    # a placed emitter: its placement's lights, by the face's rank
                    light += placement_light[best_instance[lane]]
                if light >= 0:
                    w = power_heuristic(prev_pdf[lane], _choice(choice_pmf, by_tree, tree, light, vertex, lane) * area_pdf(
                        light_at(light_rows, light, face_mover, moves, lane_time[lane], moved, lane),
                        px[lane], py[lane], pz[lane], dx[lane], dy[lane], dz[lane], t) * prev_count[lane])
            r, g, b = clamped(beta[lane, 0] * er * w, beta[lane, 1] * eg * w, beta[lane, 2] * eb * w, limit)
            add_radiance(total, lane, r, g, b)
            add_to_pass(paths, split, lane, pass_bucket(depth, category[lane]), r, g, b)
        if record_hits and depth == 0:
            # the camera-hit passes' surface (rtmesh.rendering.path_camera_hits)
            record_camera_hit(first_hit, lane, surface, geometry, pass_albedo, mat, prim, bu, bv, hx, hy, hz, gx, gy,
                              gz, nx, ny, nz, dx[lane], dy[lane], dz[lane], instances, best_instance[lane])
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
            ox, oy, oz, instances, best_instance[lane])
        lox = (tx * ox + ty * oy) + tz * oz
        loy = (sx * ox + sy * oy) + sz * oz
        loz = (nx * ox + ny * oy) + nz * oz
        tag = tags[mat]
        # whitted: every hit takes the ambient light (tinted by the colour's textures,
        # darkened by glTF's baked occlusion)
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
        for c, value in enumerate((hx, hy, hz, gx, gy, gz, nx, ny, nz, tx, ty, tz, sx, sy, sz, lox, loy, loz,
                                   ambient_r, ambient_g, ambient_b)):
            vertex[lane, c] = value
        vertex_ids[lane, MATERIAL], vertex_ids[lane, FACE], vertex_ids[lane, PARAMETER_ROW] = mat, prim, bsdf_row
        vertex_ids[lane, IN_SCRATCH], vertex_ids[lane, FRONT] = in_scratch, front
        shaded[lane] = True


@stage
def sample_lights(lanes, vertices, shadows, keys, pixels, samples, sobol_keys, start, geometry, surface, lights, env,
                  options, whitted, motion):
    """Next-event estimation at each shaded lane's vertex: ``light_samples`` estimates at a
    path's first vertex that can take light, one at later ones (whitted: every delta light
    once and ``light_samples`` of each other light, at every vertex), each a shadow ray in
    ``shadows`` with what it carries if unoccluded; and (whitted) the ambient occlusion rays.

    Parameters
    ----------
    lanes, vertices, shadows : tuples
        The module's records.
    keys, pixels, samples : (n,) arrays
        Each sample's random key, pixel and sample index (:func:`rtmesh.rendering.path_kernel.trace_paths`).
    sobol_keys : (8,) uint64
    start : int
        Lane ``j`` is sample ``start + j``.
    geometry, surface, lights, env, options, whitted, motion : tuples
        The scene's records.
    """
    # views that own nothing, known so here: no reference counts (rtmesh.core.compiled.borrowed)
    lanes, vertices, shadows, keys, pixels, samples, sobol_keys, geometry, surface, lights, env, options, whitted, \
        motion = borrowed((lanes, vertices, shadows, keys, pixels, samples, sobol_keys, geometry, surface, lights, env,
                           options, whitted, motion))
    dx, dy, dz, beta, category, alive = lanes[DX], lanes[DY], lanes[DZ], lanes[BETA], lanes[CATEGORY], lanes[ALIVE]
    prev_count, lane_depth, chain = lanes[PREV_COUNT], lanes[LANE_DEPTH], lanes[CHAIN]
    lane_time, moved, scratch, first_hit = lanes[LANE_TIME], lanes[MOVED], lanes[SCRATCH], lanes[FIRST_HIT]
    vertex, vertex_ids, shaded = vertices
    shadow_rays, shadow_set, shadow_count, shadow_kind, pending, pending_paths = shadows
    tags, params, transmissive, albedo_table = surface[0], surface[1], surface[2], surface[6]
    light_rows, light_probability, light_alias, light_pmf = lights[0], lights[1], lights[2], lights[3]
    light_texels, light_descriptors, tree = lights[7], lights[8], lights[10]
    max_depth, clamp, offset_scale, split, light_samples, light_block = (options[0], options[2], options[3],
                                                                         options[6], options[8], options[9])
    (whitted_on, delta_rows, group_start, group_order, group_probability, group_alias, group_pmf) = whitted[:7]
    ao_samples, ao_distance, ao_block = whitted[12], whitted[13], whitted[14]
    ao_pass = options[11]
    deltas = len(delta_rows) if whitted_on else 0
    by_tree = light_tree.in_use(tree)
    area_rounds = light_samples * (len(group_start) - 1) if whitted_on else light_samples
    moves, face_mover = motion[5], motion[6]
    has_lights = len(light_rows) > 0
    for lane in range(len(alive)):
        if not shaded[lane]:
            continue
        (mat, _, tag, bsdf_params, bsdf_row, hx, hy, hz, gx, gy, gz, nx, ny, nz, tx, ty, tz, sx, sy, sz, lox, loy,
         loz) = shaded_vertex(vertex, vertex_ids, lane, scratch, params, tags)
        key, depth = keys[start + lane], lane_depth[lane]
        base = DIMENSIONS_PER_VERTEX * depth
        ox, oy, oz = -dx[lane], -dy[lane], -dz[lane]
        whitted_hit = whitted_on and tag == models.BLINN_PHONG
        follow = (max_depth < 0) | (depth + 1 <= max_depth)
        ambient_r, ambient_g, ambient_b = vertex[lane, AMBIENT], vertex[lane, AMBIENT + 1], vertex[lane, AMBIENT + 2]
        # the first vertex's light points: per-pixel Owen-scrambled Sobol pairs (stratified
        # over the pixel's samples and each sample's light samples), later vertices' hashed
        # numbers
        sample_index = samples[start + lane] if len(samples) else -1
        sobol = (depth == 0) & (sample_index >= 0) & (sample_index < SOBOL_LIMIT)
        pixel = np.uint64(pixels[start + lane]) if sobol else np.uint64(0)
        # the scrambling seeds of the pixel's light-point and AO sequences, formed once for
        # all of the vertex's light samples and AO rays
        light_seeds = sequence_seeds(sobol_keys, 0, pixel) if sobol else _NO_SEEDS
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
                # the first vertex's light samples take the pixel's stratified points
                stratified = sobol and sample_index * light_samples + kk < SOBOL_LIMIT
                if kk < 0:
                    lu1 = lu2 = 0.5
                elif stratified:
                    lu1, lu2 = seeded_ray_pair(sobol_keys, 0, light_seeds, pixel, sample_index, kk, light_samples,
                                               light_block)
                else:
                    lu1, lu2 = uniform(light_key, base + LIGHT_U1), uniform(light_key, base + LIGHT_U2)
                # choice: the probability of choosing this light
                if kk < 0:
                    chosen, count_f, choice = delta_rows[k], 1.0, 1.0
                elif whitted_on:
                    # the light within its group by the sample's first number, rescaled to
                    # sample the light too (the emissive triangles: a pixel's stratified
                    # points stay stratified over the mesh, as the Whitted stages' faces)
                    lo, hi = group_start[group], group_start[group + 1]
                    pick, lu1 = alias_sample_remapped(group_probability[lo:hi], group_alias[lo:hi], lu1)
                    chosen = group_order[lo + pick]
                    count_f, choice = np.float64(light_samples), group_pmf[chosen]
                else:
                    # the light's number: at the first vertex one of the pixel's stratified
                    # set (a dimension of its own, its strata not following the pixel
                    # position: zsobol.sequence_number), later a hashed one
                    if stratified:
                        uc = sequence_number(sobol_keys, 3, pixel, sample_index, kk, light_samples, light_block)
                    else:
                        uc = uniform(light_key, base + LIGHT_CHOICE)
                    count_f = np.float64(area_count)
                    if by_tree:
                        # by the lights' importance at this vertex (rtmesh.lights.light_tree)
                        chosen, choice = light_tree.choose_light(tree, hx, hy, hz, nx, ny, nz, uc)
                        if chosen < 0:
                            continue
                    else:
                        chosen = alias_sample(light_probability, light_alias, uc)
                        choice = light_pmf[chosen]
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
                p_light = choice * pdf_li
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
        # the ao pass's rays: those of the camera ray's surface (rtmesh.rendering.path_camera_hits)
        ao_here = ao_pass and depth == 0
        first_hit[lane, HIT_AO_HERE] = 1.0 if ao_here else 0.0
        if ao_samples > 0 and (ao_here | (ambient_r > 0.0) | (ambient_g > 0.0) | (ambient_b > 0.0)):
            # ambient occlusion (whitted): the ambient term over ao_samples cosine-weighted
            # rays about the geometric normal (on the viewer's side), each counting if
            # nothing lies within ao_distance (and for the ao pass at the camera ray's surface)
            if (gx * ox + gy * oy) + gz * oz < 0.0:
                ux, uy, uz = -gx, -gy, -gz
            else:
                ux, uy, uz = gx, gy, gz
            ax, ay, az, cx, cy, cz = tangent_frame(ux, uy, uz)
            ao_seeds = sequence_seeds(sobol_keys, 2, pixel) if sobol else _NO_SEEDS
            for j in range(ao_samples):
                k = deltas + area_rounds + j
                if sobol and sample_index * ao_samples + j < SOBOL_LIMIT:
                    # the first vertex's: a pixel's spp x ao_samples directions one stratified set
                    # in the sampler's AO dimension (the Whitted stages' points under sobol)
                    au1, au2 = seeded_ray_pair(sobol_keys, 2, ao_seeds, pixel, sample_index, j, ao_samples, ao_block)
                else:
                    ao_key = mix64(key + np.uint64(k) * _LIGHT_ROUND)
                    au1, au2 = uniform(ao_key, base + LIGHT_U1), uniform(ao_key, base + LIGHT_U2)
                lx, ly, lz = square_to_cosine_hemisphere_row(au1, au2)
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
