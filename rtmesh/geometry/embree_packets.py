"""Embree's packet queries, called from compiled kernels, 16 rays a packet.

``embreex`` traces one ray per call (``rtcIntersect1`` inside its ``run()``).  Embree's
packet queries with the coherent flag trace several times more rays per second, but
embreex exposes neither them nor its scene handle: :mod:`rtmesh.geometry.embree_library`
opens the library embreex installed, verifies it and builds scenes; this module holds the
packet layout and the kernels that trace rays 16 at a time without the GIL.

The packet structure is not described by embreex's headers: the library embreex ships is
compiled with one instance level and with ``instPrimID``, so ``RTCRayHitN`` is 21 words per
lane (ray: ``org_x org_y org_z tnear dir_x dir_y dir_z time tfar mask id flags``; hit: ``Ng_x
Ng_y Ng_z u v primID geomID instID instPrimID``), field by field, N lanes each, and must be
64-byte aligned.  That layout is a property of how the library was compiled, so
:func:`rtmesh.geometry.embree_library.packet_library` proves it once per process before any
kernel here runs.

**Groups of the machine's native width.**  rtmesh's packets have 16 lanes (:data:`LANES`);
Embree traces a packet natively only as wide as the CPU's vectors: 16 lanes with AVX-512, 8
with AVX or AVX2, 4 with SSE.  A wider query is emulated one ray at a time, which loses the
coherent traversal: on a 2-vCPU AMD EPYC with AVX2, ``rtcIntersect16`` took 99-105 ns a
coherent camera ray and ``rtcIntersect8`` 35-36 (``rtcOccluded16`` 100 against 42 for
shadow rays; docs/BENCHMARKS.md, "Session 23").  So a packet is laid out as
``LANES // GROUP`` consecutive ``RTCRayHitN`` structures of :data:`GROUP` lanes (Embree's
native width here, :func:`rtmesh.core.packet_group.native_group`), each of the full 21 words a lane, and
:func:`query_packet` traces it with one native query a group that has an active lane.
With ``GROUP = 16`` that is one ``RTCRayHit16``.  Word ``field`` of lane ``lane`` is at
:func:`lane_word`.  Every query gives the same hits at every width (the same traversal
arithmetic per ray; the probe of :mod:`~rtmesh.geometry.embree_library` and the tests
compare them with single rays).

numba calls the C functions through ctypes function objects passed as kernel arguments:
a function address baked into a kernel as a global would forbid numba's disk cache, and
the argument form compiles once and stays correct when the library loads at another
address in the next process.  :data:`GROUP` is baked in (a constant of the layout): it is
part of the disk cache's stamp (:func:`rtmesh.core.compiled.package_stamp`), so a cache
compiled on a machine of another width is never loaded.
"""

import ctypes
import threading

import numpy as np
from numba import types

from rtmesh.core.compile_ahead import KernelGroup
from rtmesh.core.compiled import fix_signatures, kernel, row
from rtmesh.core.packet_group import native_group
from rtmesh.geometry.float32_rays import F32_MAX

LANES = 16
# RTCRay (org xyz, tnear, dir xyz, time, tfar, mask, id, flags: 12 words) + RTCHit (Ng xyz,
# u, v, primID, geomID, instID, instPrimID)
RAYHIT_WORDS = 21
ALIGN_WORDS = 16  # 64 bytes: Embree's packets must be aligned to their width
# word offsets of the fields, in units of LANES
ORG, TNEAR, DIR, TIME, TFAR, MASK, RAY_ID, FLAGS = 0, 3, 4, 7, 8, 9, 10, 11
NG, U, V, PRIM_ID, GEOM_ID, INST_ID, INST_PRIM_ID = 12, 15, 16, 17, 18, 19, 20


# Lanes per native query (see the module docstring) and the words of one group.  Every
# packet, closest-hit or occlusion, takes PACKET_WORDS: an occlusion query of the library
# embreex ships reads the nine hit rows that follow its RTCRayN (where an RTCRayHitN keeps its
# hit) and writes them back as it read them.  Inside a buffer its thread owns that changes
# nothing; past the buffer's end it restores stale words into memory another thread may have
# changed in the meantime: a second thread writing those rows finds its writes undone, none
# beyond them (benchmarks/probe_occlusion_rows.py), and two render threads corrupted the
# heap.  So every group has room for a whole RTCRayHitN.
GROUP = native_group()
GROUP_WORDS = RAYHIT_WORDS * GROUP
PACKET_WORDS = RAYHIT_WORDS * LANES

RTC_RAY_QUERY_FLAG_INCOHERENT = 0
RTC_RAY_QUERY_FLAG_COHERENT = 1 << 16
RTC_FEATURE_FLAG_ALL = -1  # 0xFFFFFFFF as the int32 Embree reads
# the distance embreex gives closest-hit rays (run()'s default tfar): the same value keeps
# both paths' hits identical
DEFAULT_TFAR = np.float32(1e37)
_F32_ZERO = np.float32(0.0)
# Direction components smaller than this (Embree's min_rcp_input) are given to Embree as 0.
# Embree clamps 1/d of such components, and its coherent packet traversal then culls
# boxes that the rays do hit: with components of 1e-19 in a packet, 20-45 % of the rays of
# random bundles missed what single rays hit (tests/geometry/test_embree_packets.py).  Exactly 0 is
# handled; the intersection itself cannot tell 1e-19 from 0 next to unit components
# (identical hits to run()'s, on the unflushed rays, for 480000 such rays).
MIN_RCP_INPUT = np.float32(1e-18)
INVALID_ID = -1  # RTC_INVALID_GEOMETRY_ID as int32

# void rtcIntersectN(const int* valid, RTCScene, RTCRayHitN*, RTCIntersectArguments*),
# and rtcOccludedN alike; pointers travel as 64-bit integers (array.ctypes.data)
PACKET_QUERY = ctypes.CFUNCTYPE(None, ctypes.c_int64, ctypes.c_int64, ctypes.c_int64, ctypes.c_int64)


def query_kernels():
    """:func:`intersect_rays` and :func:`occluded_rays`, each compiled (or loaded from the
    disk cache) for its one signature (:data:`QUERY_KERNELS`) on the first call in the
    process, and for no other (see :func:`closest_rays` and :func:`shadow_rays` for the
    arguments they take).

    Not when the library is opened: a render through the fused stage
    (:mod:`rtmesh.rendering.direct_stage`) traces with packets of its own and never calls
    them, and their compile took 2.4 s of its first run.

    Returns
    -------
    intersect_rays, occluded_rays : numba dispatchers
    """
    global _queries_fixed
    if not _queries_fixed:
        with _queries_lock:
            if not _queries_fixed:
                QUERY_KERNELS.prepare()
                for dispatcher, signature in QUERY_KERNELS.kernels:
                    fix_signatures(dispatcher, [signature])
                _queries_fixed = True
    return intersect_rays, occluded_rays


def numba_typeof_query():
    """numba's type of the ctypes prototype of the packet queries (the same for any
    address)."""
    import numba

    return numba.typeof(PACKET_QUERY(0))


_queries_fixed = False  # set by query_kernels
_queries_lock = threading.Lock()


def closest_rays(origins, directions):
    """Closest-hit rays as :func:`intersect_rays` takes them: float64 (float32 input is
    widened exactly; the kernel rounds every coordinate to float32 as Embree needs it).

    Parameters
    ----------
    origins, directions : (n, 3) float, any layout

    Returns
    -------
    origins, directions : (n, 3) float64
    """
    return (np.asarray(origins, dtype=np.float64), np.asarray(directions, dtype=np.float64))


def shadow_rays(origins, directions, t_max):
    """Shadow rays as :func:`occluded_rays` takes them: float32, the precision Embree traces
    in (rounding to nearest, as the kernel would); lengths clamped to the largest float32
    first, so no length overflows the conversion.

    Parameters
    ----------
    origins, directions : (n, 3) float, any layout
    t_max : (n,) float

    Returns
    -------
    origins, directions : (n, 3) float32
    t_max : (n,) float32
    """
    # np.minimum keeps a NaN (as the kernel did) and keeps float32 input float32
    t_max = np.minimum(t_max, F32_MAX).astype(np.float32, copy=False)
    return (np.asarray(origins, dtype=np.float32), np.asarray(directions, dtype=np.float32), t_max)


# ------------------------------------------------------------------ kernels


@row
def aligned_words(n, dtype):
    """A zeroed array of ``n`` 4-byte words starting on a 64-byte boundary."""
    raw = np.zeros(n + ALIGN_WORDS, dtype)
    skip = ((-raw.ctypes.data) % 64) // 4
    return raw[skip:skip + n]


@row
def query_arguments(flags):
    """``RTCIntersectArguments`` / ``RTCOccludedArguments`` (32 bytes): query flags, all
    features, and NULL context, filter and callback."""
    args = aligned_words(np.int64(8), np.int32)
    args[0] = flags
    args[1] = RTC_FEATURE_FLAG_ALL
    return args


@row
def packet_buffers(packets, flags):
    """Scratch for ``packets`` packets side by side, each 64-byte aligned.

    Parameters
    ----------
    packets : int
    flags : int
        Query flags.

    Returns
    -------
    rays : (packets * PACKET_WORDS,) float32
        Packet ``q`` at ``q * PACKET_WORDS``, its words at :func:`lane_word`: closest-hit and
        occlusion packets alike (each group has room for the hit rows that an occlusion
        query touches, :data:`PACKET_WORDS`).
    words : the same memory as int32
    valid : (packets * LANES,) int32
        Lane masks, packet ``q``'s at ``q * LANES``.
    args : (8,) int32
        The query arguments (:func:`query_arguments`).

    Notes
    -----
    Callers pass ``np.int64(...)``, not bare constants: numba compiles a row once for each
    literal value it is called with (about half a second each on a first run).
    """
    rays = aligned_words(packets * PACKET_WORDS, np.float32)
    return rays, rays.view(np.int32), aligned_words(packets * LANES, np.int32), query_arguments(flags)


@row
def lane_word(field, lane):
    """Word offset of ``field`` of lane ``lane`` in a packet: in group ``lane // GROUP``, an
    ``RTCRayHitN`` of :data:`GROUP` lanes (field by field).  Lanes past ``LANES - 1`` run on
    into the packets that follow (lane ``b`` of a buffer is lane ``b % LANES`` of packet
    ``b // LANES``), as the fused stage's blocks address them."""
    return (lane // GROUP) * GROUP_WORDS + field * GROUP + lane % GROUP


@row
def query_packet(query, scene, valid, rays, args, q):
    """Trace packet ``q`` of a buffer (:func:`packet_buffers`) with Embree's native query
    ``query`` (``rtcIntersectN`` or ``rtcOccludedN``, N = :data:`GROUP`), once for each
    group with an active lane."""
    for group in range(LANES // GROUP):
        first = q * LANES + group * GROUP
        for lane in range(first, first + GROUP):
            if valid[lane]:
                words = q * PACKET_WORDS + group * GROUP_WORDS
                query(valid.ctypes.data + 4 * first, scene, rays.ctypes.data + 4 * words, args.ctypes.data)
                break


@row
def set_lane(ray, words, lane, ox, oy, oz, dx, dy, dz, tfar):
    """Write one ray into lane ``lane`` of a packet (tnear 0, time 0, all masks).

    The coordinates are rounded to float32 (to nearest, as NumPy's ``astype`` does), the
    direction's as :func:`packet_direction` forms them.
    """
    ray[lane_word(ORG, lane)] = np.float32(ox)
    ray[lane_word(ORG + 1, lane)] = np.float32(oy)
    ray[lane_word(ORG + 2, lane)] = np.float32(oz)
    for c, value in ((0, dx), (1, dy), (2, dz)):
        ray[lane_word(DIR + c, lane)] = packet_direction(value)
    ray[lane_word(TFAR, lane)] = np.float32(tfar)
    ray[lane_word(TNEAR, lane)] = _F32_ZERO
    ray[lane_word(TIME, lane)] = _F32_ZERO
    words[lane_word(MASK, lane)] = -1
    words[lane_word(RAY_ID, lane)] = 0
    words[lane_word(FLAGS, lane)] = 0


@row
def packet_direction(value):
    """A direction component as a packet holds it: rounded to float32 (to nearest, as
    NumPy's ``astype`` does), and 0 below :data:`MIN_RCP_INPUT`."""
    d = np.float32(value)
    return _F32_ZERO if abs(d) < MIN_RCP_INPUT else d


@row
def clear_hit(words, lane):
    """Mark lane ``lane`` of a closest-hit packet as not hitting anything yet."""
    words[lane_word(GEOM_ID, lane)] = INVALID_ID
    words[lane_word(PRIM_ID, lane)] = INVALID_ID
    words[lane_word(INST_ID, lane)] = INVALID_ID
    words[lane_word(INST_PRIM_ID, lane)] = INVALID_ID


@row
def _load_rays(ray, words, valid, origins, directions, rows, start, count, tfar):
    """Fill a packet's ray part with rays ``rows[start:start + count]`` (or ``start ..``
    without rows); lanes past ``count`` are marked invalid."""
    for lane in range(LANES):
        if lane < count:
            i = rows[start + lane] if len(rows) else start + lane
            # float64 coordinates and a float32 length whatever the rays' dtype (exact
            # conversions), so that set_lane compiles once for every caller
            set_lane(ray, words, lane, np.float64(origins[i, 0]), np.float64(origins[i, 1]),
                     np.float64(origins[i, 2]), np.float64(directions[i, 0]), np.float64(directions[i, 1]),
                     np.float64(directions[i, 2]), np.float32(tfar[i]) if len(tfar) else DEFAULT_TFAR)
            valid[lane] = -1
        else:
            valid[lane] = 0


@row
def _intersect_packet(intersect, scene, ray, words, valid, args, origins, directions, start, count):
    """Trace rays ``start .. start + count - 1`` as one packet; the hits are left in it."""
    _load_rays(ray, words, valid, origins, directions, np.empty(0, np.int64), start, count,
               np.empty(0, np.float32))
    for lane in range(LANES):
        clear_hit(words, lane)
    query_packet(intersect, scene, valid, ray, args, 0)


@kernel
def intersect_rays(intersect, scene, origins, directions, flags, face_offset):
    """Closest hits of rays, a packet of 16 at a time (:func:`query_packet`).

    Parameters
    ----------
    intersect : ctypes function object
        :attr:`PacketLibrary.intersect`.
    scene : int
        A committed ``RTCScene``.
    origins, directions : (n, 3) float64, any strides
        Rays (unit directions), rounded to float32 here (see :func:`closest_rays`).
    flags : int
        ``RTC_RAY_QUERY_FLAG_COHERENT`` for rays that travel together (camera rays of
        neighbouring samples), else ``RTC_RAY_QUERY_FLAG_INCOHERENT``.
    face_offset : (k,) int64
        A scene with an instance array (:mod:`rtmesh.scene.instances`): each placement's
        first face in the per-face tables, so that a hit on placement ``j`` (its
        ``instPrimID``) reports face ``face_offset[j] + primID``; empty for a scene without.

    Returns
    -------
    t : (n,) float64
        Distances, ``inf`` for misses.
    prim : (n,) int32
        Triangle hit (its index in the per-face tables), -1 for a miss.
    u, v : (n,) float64
        Barycentric coordinates (0 for misses).
    instance : (n,) int32
        The placement hit, -1 for a world-space face or a miss.
    """
    n = origins.shape[0]
    t = np.empty(n)
    prim = np.empty(n, np.int32)
    u = np.empty(n)
    v = np.empty(n)
    instance = np.empty(n, np.int32)
    ray, words, valid, args = packet_buffers(np.int64(1), flags)
    for start in range(0, n, LANES):
        count = min(LANES, n - start)
        _intersect_packet(intersect, scene, ray, words, valid, args, origins, directions, start, count)
        for lane in range(count):
            i = start + lane
            instance[i] = -1
            if words[lane_word(GEOM_ID, lane)] == INVALID_ID:
                prim[i] = -1
                t[i] = np.inf
                u[i] = 0.0
                v[i] = 0.0
            else:
                prim[i] = words[lane_word(PRIM_ID, lane)]
                if len(face_offset) and words[lane_word(INST_ID, lane)] != INVALID_ID:
                    # a placement (one instance level): its prototype's face
                    placed = words[lane_word(INST_PRIM_ID, lane)]
                    instance[i] = placed
                    prim[i] = np.int32(face_offset[placed] + prim[i])
                t[i] = np.float64(ray[lane_word(TFAR, lane)])
                u[i] = np.float64(ray[lane_word(U, lane)])
                v[i] = np.float64(ray[lane_word(V, lane)])
    return t, prim, u, v, instance


@kernel
def occluded_rays(occluded, scene, origins, directions, t_max, rows, flags):
    """Whether anything lies on each segment, a packet of 16 at a time (:func:`query_packet`).

    Parameters
    ----------
    occluded : ctypes function object
        :attr:`PacketLibrary.occluded`.
    scene : int
    origins, directions : (n, 3) float32, any strides
    t_max : (n,) float32
        Segment lengths, already clamped to the largest float32 (see :func:`shadow_rays`:
        ``run()``'s robust mode handles that better than inf).
    rows : (k,) int64
        Trace only these rays; empty: all.
    flags : int
        Query flags, as for :func:`intersect_rays`.

    Returns
    -------
    (n,) or (k,) bool
    """
    n = len(rows) if len(rows) else origins.shape[0]
    blocked = np.empty(n, np.bool_)
    ray, words, valid, args = packet_buffers(np.int64(1), flags)
    for start in range(0, n, LANES):
        count = min(LANES, n - start)
        _load_rays(ray, words, valid, origins, directions, rows, start, count, t_max)
        query_packet(occluded, scene, valid, ray, args, 0)
        for lane in range(count):
            # Embree marks an occluded ray by setting its tfar to -inf
            blocked[start + lane] = ray[lane_word(TFAR, lane)] == -np.inf
    return blocked


def _query_signatures():
    """The one signature of each query kernel."""
    query = numba_typeof_query()
    # read-only views: writable arrays convert to them, and read-only ones (a camera's
    # repeated origin row) are accepted as they are
    rows = types.Array(types.int64, 1, "A", readonly=True)
    vectors64 = types.Array(types.float64, 2, "A", readonly=True)
    vectors32 = types.Array(types.float32, 2, "A", readonly=True)
    lengths32 = types.Array(types.float32, 1, "A", readonly=True)
    return [(intersect_rays, (query, types.int64, vectors64, vectors64, types.int64, rows)),
            (occluded_rays, (query, types.int64, vectors32, vectors32, lengths32, rows, types.int64))]


# the packet queries of the general path (rtmesh.core.compile_ahead)
QUERY_KERNELS = KernelGroup(__name__, "packet queries", _query_signatures())
