"""Embree's packet queries, called from compiled kernels.

``embreex`` installs the Embree 4 library and traces one ray per call (``rtcIntersect1``
inside its ``run()``).  Embree's 16-wide packet queries with the coherent flag trace several
times more rays per second, but embreex exposes neither them nor its scene handle.  This
module therefore opens the very library embreex installed with ctypes, builds the scene
itself (sharing the caller's vertex and index arrays instead of copying them) and traces
rays 16 at a time from numba kernels that run without the GIL.

The packet structure is not described by embreex's headers: the library embreex ships is
compiled with one instance level and with ``instPrimID``, so ``RTCRayHit16`` is 21 words per
lane (ray: ``org_x org_y org_z tnear dir_x dir_y dir_z time tfar mask id flags``; hit: ``Ng_x
Ng_y Ng_z u v primID geomID instID instPrimID``), 1344 bytes, and must be 64-byte aligned.
Because that layout is a property of how the library was compiled, :func:`packet_library`
accepts only the versions it was verified on and then proves it once per process: it
traces a probe scene with packets and single rays, checks that the hits agree and that
Embree wrote nothing past the packet.  Any failure leaves rtmesh on embreex's ``run()``
(see :class:`rtmesh.geometry.accel.Accel`), with one log line saying which path runs.

numba calls the C functions through ctypes function objects passed as kernel arguments:
a function address baked into a kernel as a global would forbid numba's disk cache, and
the argument form compiles once and stays correct when the library loads at another
address in the next process.
"""

import ctypes
import glob
import logging
import os
import threading

import numpy as np
from numba import types

from rtmesh.core.compile_ahead import KernelGroup
from rtmesh.core.compiled import fix_signatures, kernel, row
from rtmesh.geometry.float32_rays import F32_MAX

log = logging.getLogger(__name__)

# Embree versions whose packet layout (21 words a lane, instPrimID present) was checked
# against the library embreex ships; others use run().
VERIFIED_VERSIONS = ((4, 4),)

LANES = 16
RAY_WORDS = 12  # RTCRay: org xyz, tnear, dir xyz, time, tfar, mask, id, flags
RAYHIT_WORDS = 21  # + RTCHit: Ng xyz, u, v, primID, geomID, instID, instPrimID
_ALIGN_WORDS = 16  # 64 bytes: Embree's packets must be aligned to their width
# word offsets of the fields, in units of LANES
ORG, TNEAR, DIR, TIME, TFAR, MASK, RAY_ID, FLAGS = 0, 3, 4, 7, 8, 9, 10, 11
NG, U, V, PRIM_ID, GEOM_ID, INST_ID, INST_PRIM_ID = 12, 15, 16, 17, 18, 19, 20

RTC_RAY_QUERY_FLAG_INCOHERENT = 0
RTC_RAY_QUERY_FLAG_COHERENT = 1 << 16
_RTC_FEATURE_FLAG_ALL = -1  # 0xFFFFFFFF as the int32 Embree reads
_RTC_SCENE_FLAG_ROBUST = 1 << 2
_RTC_GEOMETRY_TYPE_TRIANGLE = 0
_RTC_BUFFER_TYPE_INDEX, _RTC_BUFFER_TYPE_VERTEX = 0, 1
_RTC_FORMAT_UINT3, _RTC_FORMAT_FLOAT3 = 0x5003, 0x9003
_RTC_DEVICE_PROPERTY_VERSION_MAJOR, _RTC_DEVICE_PROPERTY_VERSION_MINOR = 1, 2
_RTC_DEVICE_PROPERTY_VERSION_PATCH = 3
# the distance embreex gives closest-hit rays (run()'s default tfar): the same value keeps
# both paths' hits identical
DEFAULT_TFAR = np.float32(1e37)
_F32_ZERO = np.float32(0.0)
# Direction components smaller than this (Embree's min_rcp_input) are given to Embree as 0.
# Embree clamps 1/d of such components, and its coherent packet traversal then culls
# boxes that the rays do hit: with components of 1e-19 in a packet, 20-45 % of the rays of
# random bundles missed what single rays hit (tests/test_embree_packets.py).  Exactly 0 is
# handled; the intersection itself cannot tell 1e-19 from 0 next to unit components
# (identical hits to run()'s, on the unflushed rays, for 480000 such rays).
MIN_RCP_INPUT = np.float32(1e-18)
_INVALID_ID = -1  # RTC_INVALID_GEOMETRY_ID as int32

# void rtcIntersect16(const int* valid, RTCScene, RTCRayHit16*, RTCIntersectArguments*),
# and rtcOccluded16 alike; pointers travel as 64-bit integers (array.ctypes.data)
_PACKET_QUERY = ctypes.CFUNCTYPE(None, ctypes.c_int64, ctypes.c_int64, ctypes.c_int64, ctypes.c_int64)


def _library_path():
    """The Embree library embreex loads (its wheel's ``embreex.libs``), or None."""
    try:
        import embreex
    except ImportError:
        return None
    here = os.path.dirname(embreex.__file__)
    for folder in (os.path.join(here, os.pardir, "embreex.libs"), here):
        found = sorted(glob.glob(os.path.join(folder, "libembree4*.so*")))
        if found:
            return os.path.normpath(found[0])
    return None


class PacketLibrary:
    """The Embree library embreex installed, opened with ctypes: one device per process.

    Attributes
    ----------
    path : str
    version : tuple of int
        (major, minor, patch) as the device reports it.
    intersect16, occluded16 : ctypes function objects
        ``rtcIntersect16`` and ``rtcOccluded16``, typed for the kernels of this module.
    """

    def __init__(self, path):
        self.path = path
        lib = ctypes.CDLL(path)
        self._lib = lib
        lib.rtcNewDevice.restype = ctypes.c_void_p
        lib.rtcNewDevice.argtypes = [ctypes.c_char_p]
        lib.rtcGetDeviceProperty.restype = ctypes.c_ssize_t
        lib.rtcGetDeviceProperty.argtypes = [ctypes.c_void_p, ctypes.c_int]
        lib.rtcGetDeviceError.restype = ctypes.c_int
        lib.rtcGetDeviceError.argtypes = [ctypes.c_void_p]
        lib.rtcNewScene.restype = ctypes.c_void_p
        lib.rtcNewScene.argtypes = [ctypes.c_void_p]
        lib.rtcSetSceneFlags.argtypes = [ctypes.c_void_p, ctypes.c_int]
        lib.rtcNewGeometry.restype = ctypes.c_void_p
        lib.rtcNewGeometry.argtypes = [ctypes.c_void_p, ctypes.c_int]
        lib.rtcSetSharedGeometryBuffer.argtypes = [
            ctypes.c_void_p, ctypes.c_int, ctypes.c_uint, ctypes.c_int, ctypes.c_void_p,
            ctypes.c_size_t, ctypes.c_size_t, ctypes.c_size_t]
        for name in ("rtcCommitGeometry", "rtcReleaseGeometry", "rtcCommitScene", "rtcReleaseScene",
                     "rtcReleaseDevice"):
            getattr(lib, name).argtypes = [ctypes.c_void_p]
        lib.rtcAttachGeometry.restype = ctypes.c_uint
        lib.rtcAttachGeometry.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        self.device = lib.rtcNewDevice(None)
        if not self.device:
            raise OSError(f"{path}: rtcNewDevice failed (error {lib.rtcGetDeviceError(None)})")
        self.version = tuple(int(lib.rtcGetDeviceProperty(self.device, p)) for p in (
            _RTC_DEVICE_PROPERTY_VERSION_MAJOR, _RTC_DEVICE_PROPERTY_VERSION_MINOR,
            _RTC_DEVICE_PROPERTY_VERSION_PATCH))
        self.intersect16 = _PACKET_QUERY(ctypes.cast(lib.rtcIntersect16, ctypes.c_void_p).value)
        self.occluded16 = _PACKET_QUERY(ctypes.cast(lib.rtcOccluded16, ctypes.c_void_p).value)

    def new_scene(self, vertices32, faces32):
        """Build and commit a robust triangle scene over shared (not copied) buffers.

        Parameters
        ----------
        vertices32 : (V + 1, 3) float32, C-contiguous
            Vertex positions and one row of padding: Embree reads 16 bytes per vertex, so
            4 bytes past the last one must be readable.
        faces32 : (F, 3) uint32 or int32, C-contiguous

        Returns
        -------
        int
            The committed ``RTCScene`` handle; release it with :meth:`release_scene` only
            after the last query, and keep both arrays alive until then.
        """
        lib = self._lib
        scene = lib.rtcNewScene(self.device)
        # robust: the same traversal as embreex's scenes (rtmesh builds those robust), so
        # rays through edges and vertices cannot slip between triangles
        lib.rtcSetSceneFlags(scene, _RTC_SCENE_FLAG_ROBUST)
        geometry = lib.rtcNewGeometry(self.device, _RTC_GEOMETRY_TYPE_TRIANGLE)
        lib.rtcSetSharedGeometryBuffer(geometry, _RTC_BUFFER_TYPE_VERTEX, 0, _RTC_FORMAT_FLOAT3,
                                       vertices32.ctypes.data, 0, 12, len(vertices32) - 1)
        lib.rtcSetSharedGeometryBuffer(geometry, _RTC_BUFFER_TYPE_INDEX, 0, _RTC_FORMAT_UINT3,
                                       faces32.ctypes.data, 0, 12, len(faces32))
        lib.rtcCommitGeometry(geometry)
        lib.rtcAttachGeometry(scene, geometry)
        lib.rtcReleaseGeometry(geometry)  # the scene holds it now
        lib.rtcCommitScene(scene)
        error = lib.rtcGetDeviceError(self.device)
        if error:
            lib.rtcReleaseScene(scene)
            raise RuntimeError(f"Embree could not build the scene (error {error})")
        return scene

    def release_scene(self, scene):
        self._lib.rtcReleaseScene(scene)


_library = None
_library_checked = False
_library_lock = threading.Lock()


def packet_library():
    """The process's :class:`PacketLibrary`, or None where packets cannot be used safely.

    Opened and verified on the first call (version, then a probe trace, see the module
    docstring); the outcome is logged once and kept.  Set ``RTMESH_EMBREE=run`` in the
    environment to use embreex's ``run()`` regardless.

    Returns
    -------
    PacketLibrary or None
    """
    global _library, _library_checked
    with _library_lock:
        if _library_checked:
            return _library
        _library_checked = True
        _library, reason = _open_verified()
        if _library is None:
            log.info("tracing with embreex run(), one ray at a time: %s", reason)
        else:
            log.info("tracing with Embree %s 16-wide packets (%s)",
                     ".".join(map(str, _library.version)), _library.path)
        return _library


def query_kernels():
    """:func:`intersect_rays` and :func:`occluded_rays`, each compiled (or loaded from the
    disk cache) for its one signature (:data:`QUERY_KERNELS`) on the first call in the
    process, and for no other (see :func:`closest_rays` and :func:`shadow_rays` for the
    arguments they take).

    Not at :func:`packet_library`: a render through the fused stage
    (:mod:`rtmesh.rendering.direct_stage`) traces with packets of its own and never calls
    them, and their compile took 2.4 s of its first run.

    Returns
    -------
    intersect_rays, occluded_rays : numba dispatchers
    """
    global _queries_fixed
    if not _queries_fixed:
        with _library_lock:
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

    return numba.typeof(_PACKET_QUERY(0))


_queries_fixed = False  # set by query_kernels


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


def _open_verified():
    """(PacketLibrary, None) when the packet path is safe here, else (None, reason)."""
    if os.environ.get("RTMESH_EMBREE", "").strip().lower() == "run":
        return None, "RTMESH_EMBREE=run"
    path = _library_path()
    if path is None:
        return None, "embreex's Embree library was not found"
    try:
        library = PacketLibrary(path)
    except (OSError, AttributeError) as error:
        return None, f"cannot open {path}: {error}"
    if library.version[:2] not in VERIFIED_VERSIONS:
        return None, (f"Embree {'.'.join(map(str, library.version))} is not a version whose packet "
                      f"layout rtmesh was checked against")
    problem = _probe(library)
    if problem:
        return None, problem
    return library, None


def _probe(library):
    """Trace a small scene both ways; a description of the first disagreement, or None."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    rng = np.random.default_rng(1)
    vertices = rng.uniform(-1.0, 1.0, (60, 3)).astype(np.float32)
    faces = rng.integers(0, 60, (40, 3)).astype(np.int32)
    origins = rng.uniform(-3.0, 3.0, (37, 3)).astype(np.float32)
    directions = rng.normal(size=(37, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins[:20] = 0.0  # rays from inside the cloud of triangles, hitting most of them
    reference = rtcore_scene.EmbreeScene(robust=True)
    TriangleMesh(reference, vertices, faces)
    expected = reference.run(origins, directions.astype(np.float32), output=1)
    with SharedScene(library, vertices, faces) as scene:
        t, prim, u, v, guard_intact = _probe_packets(library, scene.handle, origins,
                                                     directions.astype(np.float32))
    if not guard_intact:
        return "Embree wrote past the 16-wide packet: its layout differs from the one rtmesh expects"
    hit = expected["primID"] >= 0
    if not hit.any():
        return "the probe scene was missed by every ray"
    if not (np.array_equal(prim, expected["primID"]) and np.array_equal(t[hit], expected["tfar"][hit])
            and np.array_equal(u[hit], expected["u"][hit]) and np.array_equal(v[hit], expected["v"][hit])):
        return "packet and single-ray hits differ on the probe scene"
    return None


def _probe_packets(library, scene, origins, directions):
    """Trace float32 rays 16 at a time through ctypes calls (no compiled code: the probe
    runs before the kernels are trusted), each packet followed by 64 guard words.

    Returns
    -------
    t, u, v : (n,) float32
    prim : (n,) int32
        -1 for misses.
    guard_intact : bool
        Embree left every guard word alone.
    """
    n = len(origins)
    t, u, v = (np.empty(n, np.float32) for _ in range(3))
    prim = np.empty(n, np.int32)
    words = RAYHIT_WORDS * LANES
    guard = np.int32(0x5EED5EED)

    def aligned(count, dtype):
        """:func:`aligned_words` for NumPy (that one is compiled-only)."""
        raw = np.zeros(count + _ALIGN_WORDS, dtype)
        skip = ((-raw.ctypes.data) % 64) // 4
        return raw[skip:skip + count]

    buffer = aligned(words + 64, np.float32)
    ints = buffer.view(np.int32)
    packet = buffer[:words].reshape(RAYHIT_WORDS, LANES)
    fields = packet.view(np.int32)
    valid = aligned(LANES, np.int32)
    args = aligned(8, np.int32)
    args[0], args[1] = RTC_RAY_QUERY_FLAG_COHERENT, _RTC_FEATURE_FLAG_ALL
    intact = True
    for start in range(0, n, LANES):
        count = min(LANES, n - start)
        rows = slice(start, start + count)
        ints[words:] = guard
        packet[:] = 0.0
        packet[ORG:ORG + 3, :count] = origins[rows].T
        packet[DIR:DIR + 3, :count] = directions[rows].T
        packet[TFAR, :count] = DEFAULT_TFAR
        fields[MASK] = -1
        fields[GEOM_ID:INST_PRIM_ID + 1] = _INVALID_ID
        valid[:] = 0
        valid[:count] = -1
        library.intersect16(valid.ctypes.data, scene, buffer.ctypes.data, args.ctypes.data)
        intact = intact and bool((ints[words:] == guard).all())
        hit = fields[GEOM_ID, :count] != _INVALID_ID
        prim[rows] = np.where(hit, fields[PRIM_ID, :count], -1)
        t[rows], u[rows], v[rows] = packet[TFAR, :count], packet[U, :count], packet[V, :count]
    return t, prim, u, v, intact


class SharedScene:
    """A committed Embree scene over float32 vertices and uint32 faces it shares.

    Parameters
    ----------
    library : PacketLibrary
    vertices : (V, 3) float
    faces : (F, 3) int

    Attributes
    ----------
    handle : int
        The ``RTCScene``, for the query kernels.
    vertices32 : (V, 3) float32
        The positions Embree traces (a view of the padded buffer it shares).
    faces32 : (F, 3) uint32
    """

    def __init__(self, library, vertices, faces):
        self.library = library
        padded = np.empty((len(vertices) + 1, 3), dtype=np.float32)
        padded[:-1] = vertices
        padded[-1] = 0.0
        self._padded = padded
        self.vertices32 = padded[:-1]
        self.faces32 = np.ascontiguousarray(faces, dtype=np.uint32)
        self.handle = library.new_scene(padded, self.faces32)

    def close(self):
        # getattr: __del__ runs on an object whose __init__ failed before setting it
        if getattr(self, "handle", 0):
            self.library.release_scene(self.handle)
            self.handle = 0

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        self.close()


# ------------------------------------------------------------------ kernels


@row
def aligned_words(n, dtype):
    """A zeroed array of ``n`` 4-byte words starting on a 64-byte boundary."""
    raw = np.zeros(n + _ALIGN_WORDS, dtype)
    skip = ((-raw.ctypes.data) % 64) // 4
    return raw[skip:skip + n]


@row
def query_arguments(flags):
    """``RTCIntersectArguments`` / ``RTCOccludedArguments`` (32 bytes): query flags, all
    features, and NULL context, filter and callback."""
    args = aligned_words(np.int64(8), np.int32)
    args[0] = flags
    args[1] = _RTC_FEATURE_FLAG_ALL
    return args


@row
def packet_buffers(fields, packets, flags):
    """Scratch for ``packets`` packets side by side, each 64-byte aligned.

    Parameters
    ----------
    fields : int
        Words per lane: :data:`RAYHIT_WORDS` for closest-hit queries, :data:`RAY_WORDS` for
        occlusion.
    packets : int
    flags : int
        Query flags.

    Returns
    -------
    rays : (packets * fields * LANES,) float32
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
    rays = aligned_words(packets * fields * LANES, np.float32)
    return rays, rays.view(np.int32), aligned_words(packets * LANES, np.int32), query_arguments(flags)


@row
def set_lane(ray, words, lane, ox, oy, oz, dx, dy, dz, tfar):
    """Write one ray into lane ``lane`` of a packet (tnear 0, time 0, all masks).

    The coordinates are rounded to float32 (to nearest, as NumPy's ``astype`` does), the
    direction's as :func:`packet_direction` forms them.
    """
    ray[ORG * LANES + lane] = np.float32(ox)
    ray[(ORG + 1) * LANES + lane] = np.float32(oy)
    ray[(ORG + 2) * LANES + lane] = np.float32(oz)
    for c, value in ((0, dx), (1, dy), (2, dz)):
        ray[(DIR + c) * LANES + lane] = packet_direction(value)
    ray[TFAR * LANES + lane] = np.float32(tfar)
    ray[TNEAR * LANES + lane] = _F32_ZERO
    ray[TIME * LANES + lane] = _F32_ZERO
    words[MASK * LANES + lane] = -1
    words[RAY_ID * LANES + lane] = 0
    words[FLAGS * LANES + lane] = 0


@row
def packet_direction(value):
    """A direction component as a packet holds it: rounded to float32 (to nearest, as
    NumPy's ``astype`` does), and 0 below :data:`MIN_RCP_INPUT`."""
    d = np.float32(value)
    return _F32_ZERO if abs(d) < MIN_RCP_INPUT else d


@row
def clear_hit(words, lane):
    """Mark lane ``lane`` of a ``RTCRayHit16`` packet as not hitting anything yet."""
    words[GEOM_ID * LANES + lane] = _INVALID_ID
    words[PRIM_ID * LANES + lane] = _INVALID_ID
    words[INST_ID * LANES + lane] = _INVALID_ID
    words[INST_PRIM_ID * LANES + lane] = _INVALID_ID


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
def _intersect_packet(intersect16, scene, ray, words, valid, args, origins, directions, start, count):
    """Trace rays ``start .. start + count - 1`` as one packet; the hits are left in it."""
    _load_rays(ray, words, valid, origins, directions, np.empty(0, np.int64), start, count,
               np.empty(0, np.float32))
    for lane in range(LANES):
        clear_hit(words, lane)
    intersect16(valid.ctypes.data, scene, ray.ctypes.data, args.ctypes.data)


@kernel
def intersect_rays(intersect16, scene, origins, directions, flags):
    """Closest hits of rays, 16 at a time through ``rtcIntersect16``.

    Parameters
    ----------
    intersect16 : ctypes function object
        :attr:`PacketLibrary.intersect16`.
    scene : int
        A committed ``RTCScene``.
    origins, directions : (n, 3) float64, any strides
        Rays (unit directions), rounded to float32 here (see :func:`closest_rays`).
    flags : int
        ``RTC_RAY_QUERY_FLAG_COHERENT`` for rays that travel together (camera rays of
        neighbouring samples), else ``RTC_RAY_QUERY_FLAG_INCOHERENT``.

    Returns
    -------
    t : (n,) float64
        Distances, ``inf`` for misses.
    prim : (n,) int32
        Triangle hit, -1 for a miss.
    u, v : (n,) float64
        Barycentric coordinates (0 for misses).
    """
    n = origins.shape[0]
    t = np.empty(n)
    prim = np.empty(n, np.int32)
    u = np.empty(n)
    v = np.empty(n)
    ray, words, valid, args = packet_buffers(np.int64(RAYHIT_WORDS), np.int64(1), flags)
    for start in range(0, n, LANES):
        count = min(LANES, n - start)
        _intersect_packet(intersect16, scene, ray, words, valid, args, origins, directions, start, count)
        for lane in range(count):
            i = start + lane
            if words[GEOM_ID * LANES + lane] == _INVALID_ID:
                prim[i] = -1
                t[i] = np.inf
                u[i] = 0.0
                v[i] = 0.0
            else:
                prim[i] = words[PRIM_ID * LANES + lane]
                t[i] = np.float64(ray[TFAR * LANES + lane])
                u[i] = np.float64(ray[U * LANES + lane])
                v[i] = np.float64(ray[V * LANES + lane])
    return t, prim, u, v


@kernel
def occluded_rays(occluded16, scene, origins, directions, t_max, rows, flags):
    """Whether anything lies on each segment, 16 at a time through ``rtcOccluded16``.

    Parameters
    ----------
    occluded16 : ctypes function object
        :attr:`PacketLibrary.occluded16`.
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
    ray, words, valid, args = packet_buffers(np.int64(RAY_WORDS), np.int64(1), flags)
    for start in range(0, n, LANES):
        count = min(LANES, n - start)
        _load_rays(ray, words, valid, origins, directions, rows, start, count, t_max)
        occluded16(valid.ctypes.data, scene, ray.ctypes.data, args.ctypes.data)
        for lane in range(count):
            # Embree marks an occluded ray by setting its tfar to -inf
            blocked[start + lane] = ray[TFAR * LANES + lane] == -np.inf
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
    return [(intersect_rays, (query, types.int64, vectors64, vectors64, types.int64)),
            (occluded_rays, (query, types.int64, vectors32, vectors32, lengths32, rows, types.int64))]


# the packet queries of the general path (rtmesh.core.compile_ahead)
QUERY_KERNELS = KernelGroup(__name__, "packet queries", _query_signatures())
