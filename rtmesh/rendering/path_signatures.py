"""The path integrator's compile-ahead group (:mod:`rtmesh.core.compile_ahead`): the one
signature of the path kernel, of its vertex stages and of the BSDF rows and photon gather
they call, from small
records of the types :class:`rtmesh.rendering.path_stage.PathStage` builds, and the records
of a scene without placements (``no_instances``) and of the path integrator's kernel
configuration (``no_whitted``)."""

import functools

import numpy as np

from rtmesh.core.compile_ahead import KernelGroup, compile_locked
from rtmesh.core.compiled import entry_point
from rtmesh.io.texture_atlas import DESCRIPTOR_WIDTH
from rtmesh.lights import light_table as lt
from rtmesh.lights.light_tree import NO_TREE
from rtmesh.materials import lobes, models
from rtmesh.rendering import path_rays, path_scatter
from rtmesh.rendering.film_sums import accumulate_samples
from rtmesh.rendering import path_vertices as pv
from rtmesh.rendering.path_camera_hits import FIRST_HIT_WORDS
from rtmesh.rendering.path_kernel import trace_paths
from rtmesh.rendering.photon_kernel import empty_photon_map, gather

def no_instances():
    """The kernel's ``instances`` record of a scene without placed meshes."""
    return (np.zeros(0, np.int64), np.zeros((0, 12)), np.zeros((0, 9)))


def no_whitted(materials, ao_samples=0, ao_distance=0.0, ao_block=0):
    """The kernel's ``whitted`` record under the path integrator (``materials``: the count),
    with the ``ao`` pass's rays (``ao_samples`` of ``ao_distance`` a camera ray's surface,
    ``ao_block`` the :func:`~rtmesh.sampling.zsobol.block_bits` of spp x ``ao_samples``)."""
    return (False, np.zeros(0, np.int64), np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros(0),
            np.zeros(0, np.int64), np.zeros(0), np.zeros((materials, 3)), np.zeros(materials), 0.0, False, 0,
            int(ao_samples), float(ao_distance), int(ao_block))


def no_camera():
    """The kernel's ``camera`` record when the camera rays are handed to it
    (:mod:`rtmesh.rendering.path_camera`)."""
    z = np.zeros
    return (False, 0, z(5, np.uint64), z((1, 2)), z(2), 1, 1, z(13), z(3), 1.0, z(0, np.int64), z(0, np.int64),
            z((0, 2)))


def small_records():
    """Small records of the shapes and types :class:`rtmesh.rendering.path_stage.PathStage`
    builds (the energy tables, ``geometry``, ``surface``, ``lights``, ``env``), for the
    signatures of the kernels that take them."""
    z = np.zeros
    energy = (z((2, 3)), z((2, 2, 2, 2)), z((2, 2)))
    geometry = (z((1, 9)), z((1, 3)), z((0, 3)), z((1, 3), np.int32), z(0, bool), z(1, np.int32), z((0, 6)),
                z((0, 12)), z((0, 6)))
    surface = (z(1, np.int64), z((1, lobes.PARAMETER_WIDTH)), z(1, bool), z((1, 3)), z((1, 3)), z((1, 4)),
               energy, z((1, 6), np.int64), z((1, 6), np.int64), z(1), z(1, np.int64), z(1), z(1),
               z(1, np.float32), z((1, DESCRIPTOR_WIDTH)), z(1), z(0, np.int64))
    lights = (z((1, lt.WIDTH)), z(1), z(1, np.int64), z(1), z(1, np.int64), z(0, np.int64), -1, z(1, np.float32),
              z((0, DESCRIPTOR_WIDTH)), z(0, np.int64), NO_TREE)
    env = (z((1, 3, 3), np.float32), z(2), z((1, 2)), z((1, 1)), 1.0, 1.0, 0.0)
    return energy, geometry, surface, lights, env


def lane_records():
    """Small records of the types :func:`rtmesh.rendering.path_kernel.trace_paths` hands its
    vertex stages (:mod:`rtmesh.rendering.path_vertices`): ``lanes``, ``hits``,
    ``vertices``, ``shadows``, ``branches``."""
    z = np.zeros
    i64 = np.int64
    floats = {"px", "py", "pz", "dx", "dy", "dz", "prev_pdf", "eta_scale", "prev_count", "travelled", "lane_time"}
    shapes = {"beta": (z((1, 3)),), "total": (z((1, 3)),), "paths": (z((1, 1, 3)),), "stack": (z((1, 1), i64),),
              "sigma": (z((1, 3)),), "alive": (z(1, bool),), "prev_delta": (z(1, bool),),
              "moved": (z((1, lt.WIDTH)),), "scratch": (z((1, lobes.PARAMETER_WIDTH)),),
              "first_hit": (z((1, FIRST_HIT_WORDS)),)}
    lanes = tuple(z(1) if name in floats else shapes[name][0] if name in shapes else z(1, i64)
                  for name in pv.LANE_RECORD)
    hits = (z(1), z(1, i64), z(1, i64), z(1), z(1))
    vertices = (z((1, pv.VERTEX_WORDS)), z((1, pv.VERTEX_IDS), i64), z(1, bool))
    shadows = (z((1, 1, 7)), z((1, 1), bool), z(1, i64), z(1, i64), z((1, 1, 3)), z((1, 1, 1, 3)))
    branches = (z((1, 1, 1)), z((1, 1, 1), i64), z(1, i64))
    return lanes, hits, vertices, shadows, branches


def _path_signatures():
    """The path kernel, its vertex stages and the rows they call, each with its one
    signature, from the types of :func:`small_records` and
    :func:`lane_records`.

    Returns
    -------
    list of (dispatcher, tuple of numba types)
    """
    import numba
    from numba import types

    from rtmesh.geometry.embree_packets import numba_typeof_query

    f64 = types.float64
    z = np.zeros
    rows = types.Array(f64, 2, "C")
    energy, geometry, surface, lights, env = small_records()
    bsdf_args = (types.int64, rows, types.int64, numba.typeof(energy))
    evaluate = bsdf_args + (f64,) * 6
    sample = bsdf_args + (f64,) * 6
    options = (-1, 3, 0.0, np.float32(1.0), True, False, False, z(4, np.int64), 1, 0, False, False, z((1, 3)))
    whitted = no_whitted(1)
    motion = (True, z(0, np.int64), z(0, np.int64), z(0, np.int64), z(1, np.int64), z((0, 10)), z(0, np.int64))
    instances = no_instances()
    photon_map = empty_photon_map(1)
    query = numba_typeof_query()
    index = types.Array(types.int64, 1, "C")
    camera = no_camera()
    trace = (query, query, types.int64, numba.typeof(camera), rows, rows, types.Array(types.uint64, 1, "C"), index,
             index,
             types.Array(types.uint64, 1, "C"), types.Array(f64, 1, "C")) + tuple(
        numba.typeof(record) for record in (geometry, surface, lights, env, options, whitted, motion, instances,
                                            photon_map)) + (
        index, rows, types.Array(f64, 3, "C"), rows, types.Array(types.int64, 1, "C"))
    i64 = types.int64
    gathered = ((numba.typeof(photon_map),) + (f64,) * 7 + (i64, i64, rows, i64, numba.typeof(energy))
                + (f64,) * 12 + (i64,))
    lanes, hits, vertices, shadows, branches = (numba.typeof(record) for record in lane_records())
    records = dict(zip(("geometry", "surface", "lights", "env", "options", "whitted", "motion", "instances",
                        "photon_map"), trace[11:20]))
    u64s = types.Array(types.uint64, 1, "C")
    start = types.int64
    meet = (lanes, hits, vertices, u64s, start, records["geometry"], records["surface"],
            types.Array(types.boolean, 1, "C")) + tuple(records[name] for name in (
                "lights", "env", "options", "whitted", "motion", "instances", "photon_map"))
    sample_lights = (lanes, vertices, shadows, u64s, index, index, u64s, start) + tuple(records[name] for name in (
        "geometry", "surface", "lights", "env", "options", "whitted", "motion"))
    scatter = (lanes, vertices, branches, u64s, index, index, u64s, start, records["surface"], records["options"],
               records["whitted"])
    words = types.Array(types.int32, 1, "C")
    packet = types.BaseTuple.from_types((types.Array(types.float32, 1, "C"), words, words))
    queries = types.BaseTuple.from_types((query, query, types.int64, words, words))
    segments = (queries, types.boolean, packet, packet, lanes, hits, records["motion"], records["instances"])
    shadow_rays = (queries, packet, packet, rows, types.Array(f64, 1, "C"), lanes, hits, shadows, u64s, start, index,
                   records["geometry"], records["surface"], records["options"], records["motion"],
                   records["instances"])
    # the film's sums of the kernel's (pixels, spp, 3) radiance, row-major
    components, indices = types.float64[:, ::1], types.int64[::1]
    film = (components, components, indices, indices, types.float64[:, :, ::1], types.float32[:, ::1])
    return [(models.evaluate, evaluate), (models.parts, evaluate), (accumulate_samples, film),
            (pv.sample_lights, sample_lights),
            (trace_paths, trace), (path_rays.trace_segments, segments), (path_rays.trace_shadows, shadow_rays),
            (models.sample, sample), (path_scatter.scatter, scatter), (gather, gathered), (pv.meet, meet)]


# the path integrator's kernels, in the order a first run best compiles them in two processes:
# the render the BSDF evaluation, the light samples' stage and the path kernel, the helper the
# longest stage first (meet, with the photon gather) and then the others from the last back
# (cold, one process, CPU seconds: meet 16.8, sample_lights 10.9, trace_paths 8.4, evaluate
# 5.2, trace_shadows 4.8, scatter 4.5, sample 2.4, trace_segments 1.9, gather 1.0, parts 0.9)
PATH_KERNELS = KernelGroup(__name__, "path", _path_signatures())


@functools.cache
def stage_entries():
    """The path kernel's stages' entry points (:func:`rtmesh.core.compiled.entry_point`:
    address and signature token of ``trace_segments``, ``meet``, ``sample_lights``,
    ``scatter`` and ``trace_shadows``, in that order) for
    :func:`rtmesh.rendering.path_kernel.trace_paths`, as a (10,) int64 array; each stage,
    and ``trace_paths`` itself, compiled or loaded from the disk cache on the first call
    (:class:`rtmesh.rendering.path_stage.PathStage` makes it as it sets a scene up, so that
    a process's first render does not load them)."""
    stages = {dispatcher: signature for dispatcher, signature in PATH_KERNELS.kernels}
    compile_locked(trace_paths, stages[trace_paths])
    entries = []
    for stage in (path_rays.trace_segments, pv.meet, pv.sample_lights, path_scatter.scatter, path_rays.trace_shadows):
        compile_locked(stage, stages[stage])
        entries.extend(entry_point(stage, stages[stage]))
    return np.array(entries, np.int64)
