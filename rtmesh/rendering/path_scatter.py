"""The path kernel's last vertex stage: the ray that continues each shaded lane's path, a
BSDF sample (Russian roulette after ``rr_depth`` vertices) or, in the Whitted configuration
at a Blinn-Phong hit, the mirror or refracted ray with the other kept on the lane's stack of
split rays.  Records and calling as :mod:`rtmesh.rendering.path_vertices` describes them.
"""

import numpy as np

from rtmesh.core.compiled import borrowed, stage
from rtmesh.materials import lobes, models
from rtmesh.rendering.path_packets import (BSDF, BSDF_U1, BSDF_U2, DIMENSIONS_PER_VERTEX, LOBE, REFLECTION,
                                           REFRACTION, ROULETTE)
from rtmesh.rendering.path_media import cross_interface, crossing_scale, twin_material
from rtmesh.rendering.path_surfaces import leave_surface, sampled_direction
from rtmesh.rendering.path_sums import lobe_category
from rtmesh.rendering.path_vertices import (ALIVE, BETA, CATEGORY, CHAIN, CHAIN_CAUSTIC, CHAIN_SCATTERED, CHAIN_START,
                                            DX, DY, DZ, ETA_SCALE, FRONT, LANE_DEPTH, PREV_DELTA, PREV_PDF, PX, PY,
                                            PZ, RAY_KIND, SCRATCH, SIGMA, SOBOL_LIMIT, STACK, shaded_vertex)
from rtmesh.rendering.whitted_rows import branches, push_branch
from rtmesh.sampling.hashing import uniform
from rtmesh.sampling.zsobol import sequence_pair

# Russian roulette lets a path on with at most this probability (Mitsuba 3's 0.95): with
# max_depth -1 a throughput that never falls (total internal reflection inside a clear
# glass, light bouncing between perfect mirrors) would otherwise never end a path; past
# rr_depth a path then ends within 20 more vertices on average and within 450 all but
# once in 1e10
SURVIVAL = 0.95


@stage
def scatter(lanes, vertices, branches_, keys, pixels, samples, sobol_keys, start, surface, options, whitted):
    """The ray that continues each shaded lane's path: a BSDF sample (then Russian roulette
    after ``rr_depth`` vertices), or (whitted, Blinn-Phong hits) the mirror or refracted
    ray, the other kept on the lane's stack of ``branches_``; lanes past ``max_depth`` end.

    Parameters
    ----------
    lanes, vertices, branches_ : tuples
        The module's records.
    keys, pixels, samples : (n,) arrays
    sobol_keys : (8,) uint64
    start : int
        Lane ``j`` is sample ``start + j``.
    surface, options, whitted : tuples
        The scene's records.
    """
    # views that own nothing, known so here: no reference counts (rtmesh.core.compiled.borrowed)
    lanes, vertices, branches_, keys, pixels, samples, sobol_keys, surface, options, whitted = borrowed(
        (lanes, vertices, branches_, keys, pixels, samples, sobol_keys, surface, options, whitted))
    px, py, pz, dx, dy, dz = lanes[PX], lanes[PY], lanes[PZ], lanes[DX], lanes[DY], lanes[DZ]
    beta, category, stack, sigma, alive = lanes[BETA], lanes[CATEGORY], lanes[STACK], lanes[SIGMA], lanes[ALIVE]
    prev_pdf, prev_delta, eta_scale = lanes[PREV_PDF], lanes[PREV_DELTA], lanes[ETA_SCALE]
    lane_depth, chain, ray_kind, scratch = lanes[LANE_DEPTH], lanes[CHAIN], lanes[RAY_KIND], lanes[SCRATCH]
    vertex, vertex_ids, shaded = vertices
    branch, branch_media, branch_top = branches_
    tags, params, transmissive, absorption, albedo_table, slots = (surface[0], surface[1], surface[2], surface[4],
                                                                   surface[6], surface[7])
    max_depth, rr_depth, offset_scale = options[0], options[1], options[3]
    media = len(options[7])
    whitted_on, cutoff, exact_fresnel = whitted[0], whitted[9], whitted[10]
    for lane in range(len(alive)):
        if not shaded[lane]:
            continue
        (mat, prim, tag, bsdf_params, bsdf_row, hx, hy, hz, gx, gy, gz, nx, ny, nz, tx, ty, tz, sx, sy, sz, lox,
         loy, loz) = shaded_vertex(vertex, vertex_ids, lane, scratch, params, tags)
        depth = lane_depth[lane]
        if not ((max_depth < 0) | (depth + 1 <= max_depth)) or (whitted_on and depth + 2 > max_depth):
            # (whitted: the last hit a ray may reach takes light, but sends no ray on)
            alive[lane] = False
            continue
        key = keys[start + lane]
        base = DIMENSIONS_PER_VERTEX * depth
        ox, oy, oz = -dx[lane], -dy[lane], -dz[lane]
        whitted_hit = whitted_on and tag == models.BLINN_PHONG
        front = vertex_ids[lane, FRONT] != 0
        # the first vertex's BSDF point: a per-pixel Owen-scrambled Sobol pair (stratified
        # over the pixel's samples), later vertices' hashed numbers
        sample_index = samples[start + lane] if len(samples) else -1
        sobol = (depth == 0) & (sample_index >= 0) & (sample_index < SOBOL_LIMIT)
        pixel = np.uint64(pixels[start + lane]) if sobol else np.uint64(0)
        if sobol:
            bu1, bu2 = sequence_pair(sobol_keys, 1, pixel, sample_index)
        else:
            bu1, bu2 = uniform(key, base + BSDF_U1), uniform(key, base + BSDF_U2)
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
        ndx, ndy, ndz, side, below = sampled_direction(wx, wy, wz, tx, ty, tz, sx, sy, sz, nx, ny, nz, gx, gy, gz,
                                                       transmissive[mat])
        if below:
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
            # A path survives with at most SURVIVAL (Mitsuba's rule): a throughput that stays
            # at 1 (total internal reflection in clear glass, a mirror box) still ends
            q = min(max(beta[lane, 0], max(beta[lane, 1], beta[lane, 2])) * eta_scale[lane], SURVIVAL)
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
