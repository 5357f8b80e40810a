"""The path kernel's ray stages: each live lane's nearest hit (:func:`trace_segments`) and
the vertices' shadow rays (:func:`trace_shadows`), one Embree packet query per 16 lanes.

:func:`rtmesh.rendering.path_kernel.trace_paths` calls them through their entry points
(:func:`rtmesh.core.compiled.call_at`), as it calls the vertex stages of
:mod:`rtmesh.rendering.path_vertices`, so that each compiles and caches on its own (their
packet rows, :mod:`rtmesh.rendering.path_packets`, took half of the path kernel's compile).

Records: ``queries = (intersect, occluded, scene, coherent, incoherent)`` (Embree's
packet queries, the committed scene's handle, the query arguments of camera rays and of
the others), ``packet`` and ``rest`` (``(ray, words, valid)`` of the packet traced and of
a mover's rest frame, :func:`rtmesh.geometry.embree_packets.packet_buffers`), ``lanes``,
``hits`` and ``shadows`` as :mod:`rtmesh.rendering.path_vertices` describes them.
"""

import numpy as np

from rtmesh.core.compiled import borrowed, stage
from rtmesh.geometry.embree_packets import DEFAULT_TFAR, LANES
from rtmesh.rendering.path_camera_hits import count_escaped
from rtmesh.rendering.path_packets import AO, MAX_LAYERS, nearest_hits, occluded, shadows_through_cutouts
from rtmesh.rendering.path_surfaces import load_lanes, set_lane
from rtmesh.rendering.path_vertices import (ALIVE, DX, DY, DZ, FIRST_HIT, LANE_DEPTH, LANE_TIME, PATHS, PX, PY, PZ,
                                            TOTAL)
from rtmesh.rendering.path_sums import accept_shadows


@stage
def trace_segments(queries, first, packet, rest, lanes, hits, motion, instances):
    """The nearest hit of every live lane's ray, into ``hits``: one ``rtcIntersect16`` per
    packet of lanes with a live one (camera rays, ``first``, with the coherent flag).

    Parameters
    ----------
    queries, packet, rest, lanes, hits : tuples
        The module's records.
    first : bool
        Whether the rays are the camera's.
    motion, instances : tuples
        The scene's records (:mod:`rtmesh.rendering.path_kernel`).
    """
    # views that own nothing, known so here: no reference counts (rtmesh.core.compiled.borrowed)
    queries, packet, rest, lanes, hits, motion, instances = borrowed(
        (queries, packet, rest, lanes, hits, motion, instances))
    intersect, scene, coherent, incoherent = queries[0], queries[2], queries[3], queries[4]
    ray, words, valid = packet
    rest_ray, rest_words, rest_valid = rest
    px, py, pz, dx, dy, dz = lanes[PX], lanes[PY], lanes[PZ], lanes[DX], lanes[DY], lanes[DZ]
    alive, lane_time = lanes[ALIVE], lanes[LANE_TIME]
    best_t, best_prim, best_instance, best_u, best_v = hits
    args = coherent if first else incoherent
    for lo in range(0, len(alive), LANES):
        hi = lo + LANES
        if load_lanes(alive[lo:hi], ray, words, valid, px[lo:hi], py[lo:hi], pz[lo:hi], dx[lo:hi], dy[lo:hi],
                      dz[lo:hi], DEFAULT_TFAR) == 0:
            continue
        nearest_hits(intersect, scene, args, incoherent, ray, words, valid, motion, instances[0], lane_time[lo:hi],
                     px[lo:hi], py[lo:hi], pz[lo:hi], dx[lo:hi], dy[lo:hi], dz[lo:hi], rest_ray, rest_words,
                     rest_valid, best_t[lo:hi], best_prim[lo:hi], best_instance[lo:hi], best_u[lo:hi],
                     best_v[lo:hi])


@stage
def trace_shadows(queries, packet, rest, segment, reach, lanes, hits, shadows, keys, start, counts, geometry,
                  surface, options, motion, instances):
    """The shadow rays the vertex stages set: one occlusion packet per light sample and
    packet of lanes (through cut-out layers with ``cutouts``), the light of each that
    arrives added to its lane's radiance (and light-path passes), the rays counted by kind.

    Parameters
    ----------
    queries, packet, rest, lanes, hits, shadows : tuples
        The module's records (``hits`` serves as scratch).
    segment : (6, 16) float64
        Scratch: a packet's rays in float64, for the movers' rest frames.
    reach : (WIDTH,) float64
        Scratch: each lane's shadow ray length.
    keys : (n,) uint64
        Each sample's random key; lane ``j`` is sample ``start + j``.
    start : int
    counts : (len(COUNTER_NAMES),) int64
        Rays traced, by kind, added to.
    geometry, surface, options, motion, instances : tuples
        The scene's records.
    """
    # views that own nothing, known so here: no reference counts (rtmesh.core.compiled.borrowed)
    queries, packet, rest, segment, reach, lanes, hits, shadows, keys, counts, geometry, surface, options, \
        motion, instances = borrowed((queries, packet, rest, segment, reach, lanes, hits, shadows, keys, counts,
                                      geometry, surface, options, motion, instances))
    intersect, occluded_query, scene, incoherent = queries[0], queries[1], queries[2], queries[4]
    shadow, shadow_words, shadow_valid = packet
    rest_ray, rest_words, rest_valid = rest
    total, paths, lane_depth, lane_time = lanes[TOTAL], lanes[PATHS], lanes[LANE_DEPTH], lanes[LANE_TIME]
    first_hit = lanes[FIRST_HIT]
    best_t, best_prim, best_instance, best_u, best_v = hits
    shadow_rays, shadow_set, shadow_count, shadow_kind, pending, pending_paths = shadows
    offset_scale, cutouts, split, ao_pass = options[3], options[5], options[6], options[11]
    width = len(total)
    for k in range(len(shadow_count)):
        if shadow_count[k] == 0:
            continue
        counts[shadow_kind[k]] += shadow_count[k]
        shadow_count[k] = 0
        for lo in range(0, width, LANES):
            hi = lo + LANES
            set_count = 0
            for lane in range(LANES):
                shadow_valid[lane] = 0
                if shadow_set[k, lo + lane]:
                    shadow_set[k, lo + lane] = False
                    ray_k = shadow_rays[k, lo + lane]
                    reach[lo + lane] = ray_k[6]
                    set_lane(shadow, shadow_words, lane, ray_k[0], ray_k[1], ray_k[2], ray_k[3], ray_k[4], ray_k[5],
                             np.float32(ray_k[6]))
                    shadow_valid[lane] = -1
                    set_count += 1
            if set_count == 0:
                continue
            if cutouts:
                shadows_through_cutouts(intersect, scene, incoherent, shadow, shadow_words, shadow_valid, geometry,
                                        surface, offset_scale, keys, start + lo, lane_depth[lo:hi], reach[lo:hi],
                                        counts, motion, instances, lane_time[lo:hi], segment, rest_ray, rest_words,
                                        rest_valid, best_t[lo:hi], best_prim[lo:hi], best_instance[lo:hi],
                                        best_u[lo:hi], best_v[lo:hi], (k + 1) * MAX_LAYERS)
            else:
                occluded(occluded_query, scene, incoherent, shadow, shadow_valid, motion, lane_time[lo:hi], reach[lo:hi],
                         rest_ray, rest_words, rest_valid)
            if ao_pass and shadow_kind[k] == AO:
                count_escaped(shadow_valid, first_hit[lo:hi])
            accept_shadows(shadow_valid, pending[k, lo:hi], pending_paths[k if split else 0, lo:hi], split,
                           total[lo:hi], paths[lo:hi])
