"""The path kernel's packet queries: a packet's nearest hits over the static scene, the
moving objects and the placed meshes, and its shadow rays' occlusion (through moving objects
and cut-out layers), with the rows that carry points between a moving object's rest pose and
its pose at a lane's time, and a placement's model and world frames.

These rows run once a packet (16 lanes), so they are calls of the kernel
(:func:`rtmesh.rendering.path_kernel.trace_paths`), not inlined into it: numba's SSA,
liveness and lowering passes grow faster than a function's length, and inlining them made
the kernel's first-run compile about a fifth longer with no gain in speed.  The records they
read (``motion``, ``instances``, ``geometry``, ``surface``) are described in
:mod:`rtmesh.rendering.path_kernel`.
"""

import math

import numpy as np

from rtmesh.core.compiled import inline_row, row
from rtmesh.geometry.embree_packets import (DEFAULT_TFAR, DIR, GEOM_ID, INST_ID, INST_PRIM_ID, INVALID_ID, LANES, ORG,
                                            PRIM_ID, TFAR, U, V, lane_word, query_packet)
from rtmesh.geometry.float32_rays import offset_origin
from rtmesh.rendering.path_surfaces import clear_hit, is_transparent, set_lane, surface_point
from rtmesh.sampling.hashing import mix64, uniform

DIMENSIONS_PER_VERTEX = 8
# dimensions of a vertex, after DIMENSIONS_PER_VERTEX * depth
LIGHT_CHOICE, LIGHT_U1, LIGHT_U2, LOBE, BSDF_U1, BSDF_U2, ROULETTE, COVERAGE = range(8)
# cut-out layers a ray passes before the next surface counts as opaque
MAX_LAYERS = 64
# ray counters, by the names of rtmesh.rendering.stats.RenderStats.rays (the path integrator
# counts camera, bounce and shadow rays; its Whitted configuration every kind the Whitted
# stages count)
COUNTER_NAMES = ("camera", "bounce", "shadow", "reflection", "refraction", "bsdf", "area_shadow", "environment",
                 "cutout", "ao")
CAMERA, BOUNCE, SHADOW, REFLECTION, REFRACTION, BSDF, AREA_SHADOW, ENVIRONMENT, CUTOUT, AO = range(len(COUNTER_NAMES))


@row
def layer_coin(key, depth, layer, dimension):
    """The coin of an alpha-blend layer: one number per (vertex, layer)."""
    return uniform(mix64(key ^ np.uint64(layer + 1)), DIMENSIONS_PER_VERTEX * depth + dimension)


@row
def rotate(vx, vy, vz, ax, ay, az, angle):
    """``v`` rotated about the unit axis ``a`` by ``angle`` radians (Rodrigues, as
    :func:`rtmesh.geometry.motion.rotate`)."""
    cos, sin = math.cos(angle), math.sin(angle)
    cx, cy, cz = ay * vz - az * vy, az * vx - ax * vz, ax * vy - ay * vx
    along = ((vx * ax + vy * ay) + vz * az) * (1.0 - cos)
    return vx * cos + cx * sin + ax * along, vy * cos + cy * sin + ay * along, vz * cos + cz * sin + az * along


@inline_row
def mover_to_rest(moves, j, time, px, py, pz, dx, dy, dz):
    """A world ray at ``time`` in mover ``j``'s rest frame (origin and direction)."""
    tx, ty, tz = moves[j, 0], moves[j, 1], moves[j, 2]
    ax, ay, az, radians = moves[j, 3], moves[j, 4], moves[j, 5], moves[j, 6]
    cx, cy, cz = moves[j, 7], moves[j, 8], moves[j, 9]
    px, py, pz = px - time * tx, py - time * ty, pz - time * tz
    if radians == 0.0:
        return px, py, pz, dx, dy, dz
    angle = -radians * time
    qx, qy, qz = rotate(px - cx, py - cy, pz - cz, ax, ay, az, angle)
    ex, ey, ez = rotate(dx, dy, dz, ax, ay, az, angle)
    return qx + cx, qy + cy, qz + cz, ex, ey, ez


@inline_row
def mover_to_world(moves, j, time, px, py, pz, gx, gy, gz, nx, ny, nz):
    """A rest-pose surface point and its two normals carried to ``time`` by mover ``j``."""
    ax, ay, az, radians = moves[j, 3], moves[j, 4], moves[j, 5], moves[j, 6]
    if radians != 0.0:
        angle = radians * time
        cx, cy, cz = moves[j, 7], moves[j, 8], moves[j, 9]
        px, py, pz = rotate(px - cx, py - cy, pz - cz, ax, ay, az, angle)
        px, py, pz = px + cx, py + cy, pz + cz
        gx, gy, gz = rotate(gx, gy, gz, ax, ay, az, angle)
        nx, ny, nz = rotate(nx, ny, nz, ax, ay, az, angle)
    return (px + time * moves[j, 0], py + time * moves[j, 1], pz + time * moves[j, 2], gx, gy, gz, nx, ny, nz)


@row
def nearest_on_movers(intersect, motion, lane_time, valid, ox, oy, oz, ex, ey, ez, rest, rest_words, rest_valid,
                       args, best_t, best_prim, best_u, best_v):
    """Each valid lane's ray (world origin ``o`` and direction ``e``, (LANES,) float64 each)
    against every moving object, traced in the object's rest pose at the lane's time up to
    ``best_t``: a nearer hit replaces the lane's ``best_t``, ``best_prim`` (the global face)
    and ``best_u, best_v`` (barycentrics on the rest-pose triangle); the static scene's hit
    already there wins ties."""
    movers, face_maps, face_offsets, moves = motion[2], motion[3], motion[4], motion[5]
    for j in range(len(movers)):
        for lane in range(LANES):
            rest_valid[lane] = valid[lane]
            if valid[lane]:
                qx, qy, qz, fx, fy, fz = mover_to_rest(moves, j, lane_time[lane], ox[lane], oy[lane], oz[lane], ex[lane],
                                                  ey[lane], ez[lane])
                set_lane(rest, rest_words, lane, qx, qy, qz, fx, fy, fz,
                         np.float32(min(best_t[lane], np.float64(DEFAULT_TFAR))))
                clear_hit(rest_words, lane)
        query_packet(intersect, movers[j], rest_valid, rest, args, 0)
        for lane in range(LANES):
            if rest_valid[lane] and rest_words[lane_word(GEOM_ID, lane)] != INVALID_ID:
                tm = np.float64(rest[lane_word(TFAR, lane)])
                if tm < best_t[lane]:
                    best_t[lane] = tm
                    best_prim[lane] = face_maps[face_offsets[j] + rest_words[lane_word(PRIM_ID, lane)]]
                    best_u[lane] = np.float64(rest[lane_word(U, lane)])
                    best_v[lane] = np.float64(rest[lane_word(V, lane)])


@inline_row
def placed(to_world, normal_to_world, j, px, py, pz, gx, gy, gz, nx, ny, nz):
    """A prototype's surface point and its two unit normals carried to the world by
    placement ``j`` (see the module notes on ``instances``)."""
    a = to_world[j]
    wx = ((a[0] * px + a[1] * py) + a[2] * pz) + a[9]
    wy = ((a[3] * px + a[4] * py) + a[5] * pz) + a[10]
    wz = ((a[6] * px + a[7] * py) + a[8] * pz) + a[11]
    b = normal_to_world[j]
    gx, gy, gz = (b[0] * gx + b[1] * gy) + b[2] * gz, (b[3] * gx + b[4] * gy) + b[5] * gz, \
        (b[6] * gx + b[7] * gy) + b[8] * gz
    nx, ny, nz = (b[0] * nx + b[1] * ny) + b[2] * nz, (b[3] * nx + b[4] * ny) + b[5] * nz, \
        (b[6] * nx + b[7] * ny) + b[8] * nz
    g = math.sqrt((gx * gx + gy * gy) + gz * gz)
    n = math.sqrt((nx * nx + ny * ny) + nz * nz)
    return wx, wy, wz, gx / g, gy / g, gz / g, nx / n, ny / n, nz / n


@inline_row
def hit_face(words, lane, instance_faces, static_faces):
    """The face a packet lane hit, in the per-face tables, and its placement (-1: none):
    a placement's hit is its prototype's face ``instance_faces[placement] + primID``, the
    static scene's its ``static_faces`` entry (empty: the identity)."""
    local = words[lane_word(PRIM_ID, lane)]
    if words[lane_word(INST_ID, lane)] != INVALID_ID:
        placement = np.int64(words[lane_word(INST_PRIM_ID, lane)])
        return instance_faces[placement] + local, placement
    return (static_faces[local] if len(static_faces) else np.int64(local)), np.int64(-1)


@row
def shadows_through_cutouts(intersect, scene, args, shadow, shadow_words, shadow_valid, geometry, surface,
                             offset_scale, keys, start, lane_depth, reach, counts, motion, instances, lane_time,
                             segment, rest, rest_words, rest_valid, best_t, best_prim, best_instance, best_u, best_v,
                             first_layer):
    """Trace the shadow packet's rays with closest hits over the static scene and every
    moving object (at each lane's time: :func:`nearest_on_movers`, the segment's ray read
    back from the packet into ``segment`` (6, LANES)), passing cut-out layers (decided on the
    rest-pose triangle's texture coordinates, which motion leaves alone), until each is
    blocked (its ``shadow_valid`` lane cleared) or free; a free ray keeps its lane set.
    Layer ``j``'s blend coin is that of layer ``first_layer + j`` (each light sample of a
    vertex its own coins).  A layer of a placed mesh is passed where its prototype's face
    is transparent, from its point carried to the world (``instances``, the kernel's record)."""
    material_id = geometry[5]
    has_static, static_faces, movers, moves, face_mover = motion[0], motion[1], motion[2], motion[5], motion[6]
    instance_faces, to_world, normal_to_world = instances
    for layer in range(MAX_LAYERS):
        active = 0
        for lane in range(LANES):
            if shadow_valid[lane]:
                clear_hit(shadow_words, lane)
                active += 1
        if active == 0:
            return
        if layer > 0:
            counts[SHADOW] += active
        if has_static:
            query_packet(intersect, scene, shadow_valid, shadow, args, 0)
        for lane in range(LANES):
            # nothing nearer than the segment's end, unless the static scene has it
            best_t[lane] = reach[lane]
            best_prim[lane] = -1
            best_instance[lane] = -1
            if shadow_valid[lane] and has_static and shadow_words[lane_word(GEOM_ID, lane)] != INVALID_ID:
                best_t[lane] = np.float64(shadow[lane_word(TFAR, lane)])
                best_prim[lane], best_instance[lane] = hit_face(shadow_words, lane, instance_faces, static_faces)
                best_u[lane] = np.float64(shadow[lane_word(U, lane)])
                best_v[lane] = np.float64(shadow[lane_word(V, lane)])
            for k in range(3):
                segment[k, lane] = np.float64(shadow[lane_word(ORG + k, lane)])
                segment[3 + k, lane] = np.float64(shadow[lane_word(DIR + k, lane)])
        if len(movers):
            nearest_on_movers(intersect, motion, lane_time, shadow_valid, segment[0], segment[1], segment[2],
                               segment[3], segment[4], segment[5], rest, rest_words, rest_valid, args, best_t,
                               best_prim, best_u, best_v)
        more = False
        for lane in range(LANES):
            if not shadow_valid[lane] or best_prim[lane] < 0:
                continue
            prim = best_prim[lane]
            bu, bv = best_u[lane], best_v[lane]
            mat = material_id[prim]
            coin = layer_coin(keys[start + lane], lane_depth[lane], first_layer + layer, COVERAGE)
            if layer + 1 < MAX_LAYERS and is_transparent(surface, geometry, mat, prim, bu, bv, coin):
                # on past the layer: the rest of the segment from just beyond it
                t = best_t[lane]
                hx, hy, hz, gx, gy, gz, nx, ny, nz = surface_point(geometry, prim, bu, bv)
                if len(face_mover) and face_mover[prim] >= 0:
                    hx, hy, hz, gx, gy, gz, nx, ny, nz = mover_to_world(moves, face_mover[prim], lane_time[lane], hx, hy,
                                                                   hz, gx, gy, gz, nx, ny, nz)
                if best_instance[lane] >= 0:
                    hx, hy, hz, gx, gy, gz, nx, ny, nz = placed(to_world, normal_to_world, best_instance[lane], hx, hy,
                                                                hz, gx, gy, gz, nx, ny, nz)
                dx, dy, dz = segment[3, lane], segment[4, lane], segment[5, lane]
                if (gx * dx + gy * dy) + gz * dz < 0.0:
                    gx, gy, gz = -gx, -gy, -gz
                qx, qy, qz = offset_origin(hx, hy, hz, gx, gy, gz, dx, dy, dz, offset_scale)
                reach[lane] = reach[lane] - t
                if not reach[lane] > 0.0:
                    continue  # the layer was the end of the segment: free
                set_lane(shadow, shadow_words, lane, np.float64(qx), np.float64(qy), np.float64(qz), dx, dy, dz,
                         np.float32(reach[lane]))
                more = True
            else:
                shadow_valid[lane] = 0
        if not more:
            return


@row
def nearest_hits(intersect, scene, args, args_incoherent, ray, words, valid, motion, instance_faces, lane_time,
                  px, py, pz, dx, dy, dz, rest, rest_words, rest_valid, best_t, best_prim, best_instance, best_u,
                  best_v):
    """Trace the packet ``ray`` (its ``valid`` lanes) against the static scene and every
    moving object and keep each lane's nearest hit: ``best_t``, ``best_prim`` (the face in
    the per-face tables), ``best_instance`` (the placement, or -1) and ``best_u, best_v``
    (``best_prim`` -1 and ``best_t`` inf for a miss).  Once a packet, so a call (not
    inlined: the path kernel's first-run compile grows faster than its length)."""
    has_static, static_faces = motion[0], motion[1]
    if has_static:
        query_packet(intersect, scene, valid, ray, args, 0)
    for lane in range(LANES):
        best_t[lane] = math.inf
        best_prim[lane] = -1
        best_instance[lane] = -1
        if valid[lane] and has_static and words[lane_word(GEOM_ID, lane)] != INVALID_ID:
            best_t[lane] = np.float64(ray[lane_word(TFAR, lane)])
            best_prim[lane], best_instance[lane] = hit_face(words, lane, instance_faces, static_faces)
            best_u[lane] = np.float64(ray[lane_word(U, lane)])
            best_v[lane] = np.float64(ray[lane_word(V, lane)])
    # (a scene with moving objects has no placements: rtmesh.scene.instances.unsupported
    # renders it from copies, so a mover's hit leaves best_instance at -1)
    nearest_on_movers(intersect, motion, lane_time, valid, px, py, pz, dx, dy, dz, rest, rest_words,
                       rest_valid, args_incoherent, best_t, best_prim, best_u, best_v)


@row
def occluded(occluded_query, scene, args, shadow, shadow_valid, motion, lane_time, reach, rest, rest_words, rest_valid):
    """Clear ``shadow_valid`` of the lanes whose shadow ray (the packet ``shadow``, each
    lane ``reach[lane]`` long) meets the static scene or a moving object (at the lane's
    time, in the object's rest pose).  Once a packet: a call, as :func:`nearest_hits`."""
    has_static, movers, moves = motion[0], motion[2], motion[5]
    if has_static:
        query_packet(occluded_query, scene, shadow_valid, shadow, args, 0)
        for lane in range(LANES):
            if shadow_valid[lane] and shadow[lane_word(TFAR, lane)] == -np.inf:
                shadow_valid[lane] = 0
    for j in range(len(movers)):
        for lane in range(LANES):
            rest_valid[lane] = shadow_valid[lane]
            if shadow_valid[lane]:
                ox, oy, oz, ex, ey, ez = mover_to_rest(
                    moves, j, lane_time[lane], np.float64(shadow[lane_word(ORG, lane)]),
                    np.float64(shadow[lane_word(ORG + 1, lane)]), np.float64(shadow[lane_word(ORG + 2, lane)]),
                    np.float64(shadow[lane_word(DIR, lane)]), np.float64(shadow[lane_word(DIR + 1, lane)]),
                    np.float64(shadow[lane_word(DIR + 2, lane)]))
                set_lane(rest, rest_words, lane, ox, oy, oz, ex, ey, ez, np.float32(reach[lane]))
        query_packet(occluded_query, movers[j], rest_valid, rest, args, 0)
        for lane in range(LANES):
            if rest_valid[lane] and rest[lane_word(TFAR, lane)] == -np.inf:
                shadow_valid[lane] = 0
