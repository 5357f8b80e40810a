"""The Embree library embreex installs, opened with ctypes and verified before packets trace.

``embreex`` installs the Embree 4 library; rtmesh opens that very library with ctypes
(:class:`PacketLibrary`), builds its scenes itself over shared vertex and index arrays
(:class:`SharedScene`), and traces them with the packet kernels of
:mod:`rtmesh.geometry.embree_packets`.  The packet layout those kernels assume is a property
of how the library was compiled, so :func:`packet_library` accepts only the versions it
was verified on and then proves the layout once per process: it traces a probe scene with
packets and single rays, checks that the hits agree and that Embree wrote nothing past the
packet.  Any failure leaves rtmesh on embreex's ``run()`` (see
:class:`rtmesh.geometry.accel.Accel`), with one log line saying which path runs.
"""

import ctypes
import glob
import logging
import os
import threading

import numpy as np

from rtmesh.geometry.embree_packets import (ALIGN_WORDS, DEFAULT_TFAR, DIR, GEOM_ID, GROUP, INST_PRIM_ID, INVALID_ID,
                                            LANES, MASK, ORG, PACKET_QUERY, PACKET_WORDS, PRIM_ID, RAYHIT_WORDS,
                                            RTC_FEATURE_FLAG_ALL, RTC_RAY_QUERY_FLAG_COHERENT, TFAR, U, V)

log = logging.getLogger(__name__)

# Embree versions whose packet layout (21 words a lane, instPrimID present) was checked
# against the library embreex ships; others use run().
VERIFIED_VERSIONS = ((4, 4),)


_RTC_SCENE_FLAG_ROBUST = 1 << 2
_RTC_GEOMETRY_TYPE_TRIANGLE = 0
_RTC_GEOMETRY_TYPE_INSTANCE_ARRAY = 122
_RTC_BUFFER_TYPE_TRANSFORM = 23
_RTC_FORMAT_UINT = 0x5001
_RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR = 0x9234
_RTC_BUFFER_TYPE_INDEX, _RTC_BUFFER_TYPE_VERTEX = 0, 1
_RTC_FORMAT_UINT3, _RTC_FORMAT_FLOAT3 = 0x5003, 0x9003
_RTC_DEVICE_PROPERTY_VERSION_MAJOR, _RTC_DEVICE_PROPERTY_VERSION_MINOR = 1, 2
_RTC_DEVICE_PROPERTY_VERSION_PATCH = 3
_RTC_DEVICE_PROPERTY_NATIVE_RAY = {4: 32, 8: 33, 16: 34}

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
    intersect, occluded : ctypes function objects
        ``rtcIntersectN`` and ``rtcOccludedN`` of the machine's native width N
        (:data:`rtmesh.geometry.embree_packets.GROUP`), typed for the kernels of
        :mod:`rtmesh.geometry.embree_packets`.
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
        lib.rtcSetGeometryInstancedScenes.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t]
        self.device = lib.rtcNewDevice(None)
        if not self.device:
            raise OSError(f"{path}: rtcNewDevice failed (error {lib.rtcGetDeviceError(None)})")
        self.version = tuple(int(lib.rtcGetDeviceProperty(self.device, p)) for p in (
            _RTC_DEVICE_PROPERTY_VERSION_MAJOR, _RTC_DEVICE_PROPERTY_VERSION_MINOR,
            _RTC_DEVICE_PROPERTY_VERSION_PATCH))
        self.intersect = self.packet_query("Intersect", GROUP)
        self.occluded = self.packet_query("Occluded", GROUP)

    def packet_query(self, kind, width):
        """``rtcIntersectN`` or ``rtcOccludedN`` (``kind`` "Intersect" or "Occluded") of
        ``width`` (4, 8 or 16) lanes, as the kernels call it (:data:`PACKET_QUERY`)."""
        return PACKET_QUERY(ctypes.cast(getattr(self._lib, f"rtc{kind}{width}"), ctypes.c_void_p).value)

    def native(self, width):
        """Whether the device traces packets of ``width`` (4, 8 or 16) lanes natively
        (``RTC_DEVICE_PROPERTY_NATIVE_RAY{width}_SUPPORTED``)."""
        return bool(self._lib.rtcGetDeviceProperty(self.device, _RTC_DEVICE_PROPERTY_NATIVE_RAY[width]))

    def new_scene(self, vertices32, faces32, instances=None):
        """Build and commit a robust triangle scene over shared (not copied) buffers.

        Parameters
        ----------
        vertices32 : (V + 1, 3) float32, C-contiguous
            Vertex positions and one row of padding: Embree reads 16 bytes per vertex, so
            4 bytes past the last one must be readable.
        faces32 : (F, 3) uint32 or int32, C-contiguous
            May be empty (a scene of instances only: no triangle geometry is attached).
        instances : (scenes, prototype, columns), optional
            Committed scenes placed by affine transforms, as one instance array
            (``RTC_GEOMETRY_TYPE_INSTANCE_ARRAY``, attached after the triangles):
            ``scenes`` (P,) uintp their handles (:meth:`new_scene`), ``prototype`` (k,)
            uint32 each placement's scene, ``columns`` (k, 12) float32 each placement's
            model-to-world transform in Embree's ``FLOAT3X4_COLUMN_MAJOR`` (the columns of
            the linear part, then the translation).  A hit on placement ``j`` has the
            array's geometry id as ``instID`` and ``j`` as ``instPrimID`` (one instance
            level: the library is compiled with ``RTC_MAX_INSTANCE_LEVEL_COUNT = 1``).
            Embree shares the three arrays: keep them alive with the scene.

        Returns
        -------
        int
            The committed ``RTCScene`` handle; release it with :meth:`release_scene` only
            after the last query, and keep both arrays (and every instanced scene) alive
            until then.
        """
        lib = self._lib
        scene = lib.rtcNewScene(self.device)
        # robust: the same traversal as embreex's scenes (rtmesh builds those robust), so
        # rays through edges and vertices cannot slip between triangles
        lib.rtcSetSceneFlags(scene, _RTC_SCENE_FLAG_ROBUST)
        if len(faces32):
            geometry = lib.rtcNewGeometry(self.device, _RTC_GEOMETRY_TYPE_TRIANGLE)
            lib.rtcSetSharedGeometryBuffer(geometry, _RTC_BUFFER_TYPE_VERTEX, 0, _RTC_FORMAT_FLOAT3,
                                           vertices32.ctypes.data, 0, 12, len(vertices32) - 1)
            lib.rtcSetSharedGeometryBuffer(geometry, _RTC_BUFFER_TYPE_INDEX, 0, _RTC_FORMAT_UINT3,
                                           faces32.ctypes.data, 0, 12, len(faces32))
            lib.rtcCommitGeometry(geometry)
            lib.rtcAttachGeometry(scene, geometry)
            lib.rtcReleaseGeometry(geometry)  # the scene holds it now
        if instances is not None:
            # one instance array for every placement: a handful of calls however many there
            # are (10,000 instance geometries took 0.09 s of ctypes calls alone)
            scenes, prototype, columns = instances
            geometry = lib.rtcNewGeometry(self.device, _RTC_GEOMETRY_TYPE_INSTANCE_ARRAY)
            lib.rtcSetGeometryInstancedScenes(geometry, scenes.ctypes.data, len(scenes))
            lib.rtcSetSharedGeometryBuffer(geometry, _RTC_BUFFER_TYPE_INDEX, 0, _RTC_FORMAT_UINT,
                                           prototype.ctypes.data, 0, 4, len(prototype))
            lib.rtcSetSharedGeometryBuffer(geometry, _RTC_BUFFER_TYPE_TRANSFORM, 0, _RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR,
                                           columns.ctypes.data, 0, 48, len(columns))
            lib.rtcCommitGeometry(geometry)
            lib.rtcAttachGeometry(scene, geometry)
            lib.rtcReleaseGeometry(geometry)
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
_library_failure = None
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
    global _library, _library_checked, _library_failure
    with _library_lock:
        if _library_checked:
            return _library
        _library_checked = True
        _library, reason = _open_verified()
        if _library is None:
            _library_failure = reason
            log.info("tracing with embreex run(), one ray at a time: %s", reason)
        else:
            log.info("tracing with Embree %s packets of %d rays, %d-wide queries (%s)",
                     ".".join(map(str, _library.version)), LANES, GROUP, _library.path)
        return _library



def packet_failure():
    """Why :func:`packet_library` is None (a phrase), or None when packets trace."""
    packet_library()
    return _library_failure


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
        return "Embree wrote past the packet: its layout differs from the one rtmesh expects"
    hit = expected["primID"] >= 0
    if not hit.any():
        return "the probe scene was missed by every ray"
    if not (np.array_equal(prim, expected["primID"]) and np.array_equal(t[hit], expected["tfar"][hit])
            and np.array_equal(u[hit], expected["u"][hit]) and np.array_equal(v[hit], expected["v"][hit])):
        return "packet and single-ray hits differ on the probe scene"
    return None


def aligned_array(count, dtype):
    """A zeroed NumPy array of ``count`` 4-byte words starting on a 64-byte boundary:
    :func:`rtmesh.geometry.embree_packets.aligned_words` for Python callers (that one is
    compiled-only)."""
    raw = np.zeros(count + ALIGN_WORDS, dtype)
    skip = ((-raw.ctypes.data) % 64) // 4
    return raw[skip:skip + count]


def _probe_packets(library, scene, origins, directions, group=GROUP):
    """Trace float32 rays 16 at a time, in groups of ``group`` lanes (``rtcIntersect{group}``
    each; by default the native width, as the kernels lay packets out:
    :func:`rtmesh.geometry.embree_packets.lane_word`), through ctypes calls (no compiled code:
    the probe runs before the kernels are trusted), each packet followed by 64 guard words.

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
    groups = LANES // group
    intersect = library.packet_query("Intersect", group)
    guard = np.int32(0x5EED5EED)

    buffer = aligned_array(PACKET_WORDS + 64, np.float32)
    ints = buffer.view(np.int32)
    # (group, field, lane in the group)
    packet = buffer[:PACKET_WORDS].reshape(groups, RAYHIT_WORDS, group)
    fields = packet.view(np.int32)
    valid = aligned_array(LANES, np.int32)
    args = aligned_array(8, np.int32)
    args[0], args[1] = RTC_RAY_QUERY_FLAG_COHERENT, RTC_FEATURE_FLAG_ALL
    intact = True
    for start in range(0, n, LANES):
        count = min(LANES, n - start)
        rows = slice(start, start + count)
        ints[PACKET_WORDS:] = guard
        lanes = np.zeros((RAYHIT_WORDS, LANES), np.float32)
        lanes[ORG:ORG + 3, :count] = origins[rows].T
        lanes[DIR:DIR + 3, :count] = directions[rows].T
        lanes[TFAR, :count] = DEFAULT_TFAR
        packet[:] = lanes.reshape(RAYHIT_WORDS, groups, group).transpose(1, 0, 2)
        fields[:, MASK] = -1
        fields[:, GEOM_ID:INST_PRIM_ID + 1] = INVALID_ID
        valid[:] = 0
        valid[:count] = -1
        for g in range(groups):
            intersect(valid.ctypes.data + 4 * group * g, scene, buffer.ctypes.data + 4 * RAYHIT_WORDS * group * g,
                      args.ctypes.data)
        intact = intact and bool((ints[PACKET_WORDS:] == guard).all())
        # (field, lane) copies of the packet's results
        by_field = packet.transpose(1, 0, 2).reshape(RAYHIT_WORDS, LANES)
        by_field_ints = fields.transpose(1, 0, 2).reshape(RAYHIT_WORDS, LANES)
        hit = by_field_ints[GEOM_ID, :count] != INVALID_ID
        prim[rows] = np.where(hit, by_field_ints[PRIM_ID, :count], -1)
        t[rows], u[rows], v[rows] = by_field[TFAR, :count], by_field[U, :count], by_field[V, :count]
    return t, prim, u, v, intact


class SharedScene:
    """A committed Embree scene over float32 vertices and uint32 faces it shares.

    Parameters
    ----------
    library : PacketLibrary
    vertices : (V, 3) float
    faces : (F, 3) int
    instances : (scenes, prototype, transforms), optional
        Placements (see :meth:`PacketLibrary.new_scene`): ``scenes`` a list of
        :class:`SharedScene`, ``prototype`` (k,) int each placement's, ``transforms``
        (k, 3, 4) float its model-to-world ``[A | t]``.

    Attributes
    ----------
    handle : int
        The ``RTCScene``, for the query kernels.
    vertices32 : (V, 3) float32
        The positions Embree traces (a view of the padded buffer it shares).
    faces32 : (F, 3) uint32
    """

    def __init__(self, library, vertices, faces, instances=None):
        self.library = library
        padded = np.empty((len(vertices) + 1, 3), dtype=np.float32)
        padded[:-1] = vertices
        padded[-1] = 0.0
        self._padded = padded
        self.vertices32 = padded[:-1]
        self.faces32 = np.ascontiguousarray(faces, dtype=np.uint32)
        placed = None
        if instances is not None:
            scenes, prototype, transforms = instances
            # Embree's column-major 3x4 (the columns of A, then t: the rows of the transpose),
            # shared: 4 spare bytes after each buffer, as Embree may read 16-byte vectors
            columns = np.zeros((len(transforms) + 1, 12), np.float32)
            columns[:-1] = np.asarray(transforms, dtype=np.float32).transpose(0, 2, 1).reshape(-1, 12)
            index = np.zeros(len(prototype) + 4, np.uint32)
            index[:len(prototype)] = prototype
            handles = np.array([scene.handle for scene in scenes], dtype=np.uintp)
            # the instanced scenes and the shared arrays live as long as this scene
            self._instanced = (scenes, handles, index, columns)
            placed = (handles, index[:len(prototype)], columns[:-1])
        self.handle = library.new_scene(padded, self.faces32, placed)

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
