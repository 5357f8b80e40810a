"""The two tracing paths, Embree's packets from compiled kernels and embreex's ``run()``,
answer the same queries with the same hits on a robust scene; the packets' layout in groups
of the machine's native width."""

import os
import subprocess
import sys

import numba
import numpy as np
import pytest
import trimesh

from rtmesh.core import packet_group
from rtmesh.geometry import embree_library, embree_packets
from rtmesh.geometry.accel import Accel

pytestmark = pytest.mark.skipif(embree_library.packet_library() is None,
                                reason="Embree packets are verified only for Embree 4.4")


def _scene():
    """A smooth sphere on a ground quad: no two triangles overlap, so no hit is a tie."""
    sphere = trimesh.creation.icosphere(subdivisions=4)
    ground = np.array([[-5, -5, -1.5], [5, -5, -1.5], [5, 5, -1.5], [-5, 5, -1.5]], float)
    vertices = np.vstack([sphere.vertices, ground])
    n = len(sphere.vertices)
    faces = np.vstack([sphere.faces, [[n, n + 1, n + 2], [n, n + 2, n + 3]]])
    return vertices, faces


@pytest.fixture(scope="module")
def twins():
    vertices, faces = _scene()
    return Accel(vertices, faces, packets=True), Accel(vertices, faces, packets=False)


def _rays(n, seed=0):
    rng = np.random.default_rng(seed)
    origins = rng.normal(size=(n, 3)) * 3.0
    toward = rng.normal(size=(n, 3)) * 0.5 - origins
    return origins, toward / np.linalg.norm(toward, axis=1, keepdims=True)


def test_packet_and_single_ray_hits_are_identical(twins):
    packets, single = twins
    origins, directions = _rays(20011)  # not a multiple of 16: a partial last packet
    a, b = packets.intersect(origins, directions), single.intersect(origins, directions)
    assert 0.3 < a.hit.mean() < 0.99  # both hits and misses are exercised
    np.testing.assert_array_equal(a.prim, b.prim)
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.u[a.hit], b.u[b.hit])
    np.testing.assert_array_equal(a.v[a.hit], b.v[b.hit])
    assert np.all(np.isinf(a.t[~a.hit]))


def test_packet_hits_take_any_layout_and_precision(twins):
    """Component-major, float32 and repeated-row (stride 0) inputs give the same hits."""
    packets, _ = twins
    origins, directions = _rays(999, seed=1)
    expected = packets.intersect(origins, directions)
    column_major = packets.intersect(np.asfortranarray(origins), np.asfortranarray(directions))
    np.testing.assert_array_equal(column_major.prim, expected.prim)
    as_float32 = packets.intersect(origins.astype(np.float32), directions.astype(np.float32))
    np.testing.assert_array_equal(as_float32.t, expected.t)
    eye = np.broadcast_to(np.array([0.0, 0.0, 6.0]), (999, 3))
    toward = -eye + np.random.default_rng(2).normal(size=(999, 3)) * 0.3
    toward /= np.linalg.norm(toward, axis=1, keepdims=True)
    a = packets.intersect(eye, toward)
    b = packets.intersect(np.ascontiguousarray(eye), toward)
    np.testing.assert_array_equal(a.t, b.t)


def test_packet_and_single_ray_occlusion_are_identical(twins):
    packets, single = twins
    origins, directions = _rays(10007, seed=3)
    t_max = np.random.default_rng(4).uniform(0.0, 6.0, len(origins))
    t_max[::7] = np.inf  # rays toward infinitely distant lights
    a, b = packets.occluded(origins, directions, t_max), single.occluded(origins, directions, t_max)
    assert 0.1 < a.mean() < 0.9
    np.testing.assert_array_equal(a, b)
    rows = np.arange(3, len(origins), 5)
    np.testing.assert_array_equal(packets.occluded(origins, directions, t_max, rows=rows), a[rows])
    as_float32 = packets.occluded(origins.astype(np.float32), directions.astype(np.float32),
                                  t_max.astype(np.float32))
    np.testing.assert_array_equal(as_float32, b)


def test_empty_batches(twins):
    packets, _ = twins
    none = np.zeros((0, 3))
    assert len(packets.intersect(none, none)) == 0
    assert packets.occluded(none, none, np.zeros(0)).shape == (0,)


def test_hits_do_not_depend_on_how_rays_are_grouped_into_packets(twins):
    """Without ties (no coplanar overlapping triangles) a ray's hit does not depend on the
    other rays of its packet.  (With ties it can: the scheduler keeps the chunks, and so the
    packets, the same for every thread count; see rtmesh.rendering.scheduler.)"""
    packets, _ = twins
    origins, directions = _rays(4099, seed=5)
    expected = packets.intersect(origins, directions)
    order = np.random.default_rng(6).permutation(len(origins))
    shuffled = packets.intersect(origins[order], directions[order])
    np.testing.assert_array_equal(shuffled.prim, expected.prim[order])
    np.testing.assert_array_equal(shuffled.t, expected.t[order])


def test_shared_vertices_are_the_traced_float32_positions():
    vertices, faces = _scene()
    accel = Accel(vertices, faces, packets=True)
    np.testing.assert_array_equal(accel.vertices32, vertices.astype(np.float32))
    assert accel.vertices32.dtype == np.float32 and accel.vertices32.shape == vertices.shape


def test_the_probe_accepts_this_library():
    library = embree_library.packet_library()
    assert library.version[:2] in embree_library.VERIFIED_VERSIONS
    assert embree_library._probe(library) is None


@pytest.mark.parametrize("path", ["packets", "run"])
def test_environment_chooses_the_path_and_one_log_line_says_which(path):
    env = dict(os.environ, RTMESH_EMBREE="run" if path == "run" else "")
    code = ("import logging; logging.basicConfig(level=logging.INFO, format='%(message)s');"
            "from rtmesh.geometry.accel import Accel; import numpy as np;"
            "a = Accel(np.eye(3), [[0, 1, 2]]); print('packets' if a.packets else 'run')")
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert done.stdout.strip() == path
    lines = [line for line in done.stderr.splitlines() if line.startswith("tracing with")]
    assert len(lines) == 1
    assert ("packets" in lines[0]) == (path == "packets")


@pytest.mark.parametrize("tiniest", [-40, -19, -12])
def test_coherent_packets_with_nearly_axis_aligned_rays(twins, tiniest):
    """Bundles of rays with one direction component near zero, of either sign (an
    axis-aligned camera, refraction through an axis-aligned face): Embree's coherent
    traversal loses hits when such components are below 1e-18 unless they are flushed."""
    packets, single = twins
    rng = np.random.default_rng(7)
    n = 16 * 500
    bundle = rng.normal(size=(n // 16, 3))
    origins = np.repeat(bundle / np.linalg.norm(bundle, axis=1, keepdims=True) * 3.0, 16, axis=0)
    directions = -origins + rng.normal(size=(n, 3)) * 0.3
    axis = rng.integers(0, 3, n)
    directions[np.arange(n), axis] = rng.choice([-1.0, 1.0], n) * 10.0 ** rng.uniform(tiniest, -5, n)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    a, b = packets.intersect(origins, directions), single.intersect(origins, directions)
    assert a.hit.mean() > 0.3
    np.testing.assert_array_equal(a.prim, b.prim)
    np.testing.assert_array_equal(a.t, b.t)
    t_max = np.full(n, 2.5)
    np.testing.assert_array_equal(packets.occluded(origins, directions, t_max),
                                  single.occluded(origins, directions, t_max))


@numba.njit
def _packet_buffers(packets):
    rays, words, valid, _ = embree_packets.packet_buffers(packets, np.int64(0))
    return rays, words, valid


@numba.njit
def _lane_words(fields, lanes):
    """lane_word of every field and lane, (fields, lanes)."""
    out = np.empty((fields, lanes), np.int64)
    for field in range(fields):
        for lane in range(lanes):
            out[field, lane] = embree_packets.lane_word(field, lane)
    return out


@pytest.mark.parametrize("packets", [1, 4])
def test_every_packet_buffer_holds_the_hit_rows_an_occlusion_query_rewrites(packets):
    """rtcOccluded16 reads and writes back the nine hit rows after an RTCRay16
    (benchmarks/probe_occlusion_rows.py): a buffer whose last packet lacked them let a query
    restore stale words into memory another render thread had changed (heap corruption).
    Every group of every packet, occlusion packets included, has the whole RTCRayHitN."""
    rays, words, valid = _packet_buffers(np.int64(packets))
    lanes = embree_packets.LANES
    assert len(rays) == packets * embree_packets.RAYHIT_WORDS * lanes
    assert words.ctypes.data == rays.ctypes.data and len(valid) == packets * lanes
    assert rays.ctypes.data % 64 == 0 and valid.ctypes.data % 64 == 0


def test_lane_words_lay_each_group_out_as_embrees_native_packet():
    """Lane b of packets side by side (b up to four packets' lanes) lies in group b // GROUP,
    an RTCRayHitN of GROUP lanes: its fields GROUP words apart, its lanes consecutive, the
    group starting on a boundary of its own size (Embree's alignment of an N-wide packet);
    every word of the buffer once."""
    group, fields = embree_packets.GROUP, embree_packets.RAYHIT_WORDS
    words = _lane_words(fields, 4 * embree_packets.LANES)
    assert np.array_equal(np.sort(words.ravel()), np.arange(words.size))
    for b in range(words.shape[1]):
        start = (b // group) * fields * group
        assert (start * 4) % (4 * group) == 0
        np.testing.assert_array_equal(words[:, b], start + np.arange(fields) * group + b % group)
    if group == embree_packets.LANES:  # one RTCRayHit16 a packet: field-major rows of 16 lanes
        np.testing.assert_array_equal(words[:, :16], np.arange(fields)[:, None] * 16 + np.arange(16))


@pytest.mark.parametrize("features, group", [
    ({"avx512f": True, "avx512cd": True, "avx512dq": True, "avx512bw": True, "avx512vl": True, "avx2": True,
      "avx": True}, 16),
    ({"avx512f": True, "avx512cd": True, "avx2": True, "avx": True}, 8),  # AVX-512 without BW, DQ, VL (KNL)
    ({"avx2": True, "avx": True, "fma": True}, 8),
    ({"avx": True}, 8),
    ({"sse4.2": True}, 4),
])
def test_native_group_follows_the_cpus_vector_width(features, group):
    assert packet_group.native_group(features) == group


def test_embree_traces_the_chosen_group_natively_and_no_wider_group():
    """The layout's width is the widest packet Embree reports as native on this machine."""
    library = embree_library.packet_library()
    assert library.native(embree_packets.GROUP)
    if embree_packets.GROUP < 16:
        assert not library.native(2 * embree_packets.GROUP)


@pytest.mark.parametrize("width", [4, 8, 16])
def test_every_packet_width_gives_the_single_rays_hits(width):
    """rtcIntersect4, 8 and 16 (native or emulated here) give run()'s hits to the bit:
    the packet width is a matter of speed only."""
    vertices, faces = _scene()
    library = embree_library.packet_library()
    rng = np.random.default_rng(7)
    n = 4 * width
    origins = np.zeros((n, 3), np.float32)
    origins[:, 2] = 3.0
    directions = rng.normal(size=(n, 3))
    directions[:, 2] = -np.abs(directions[:, 2]) - 1.0
    directions = (directions / np.linalg.norm(directions, axis=1, keepdims=True)).astype(np.float32)
    with embree_library.SharedScene(library, vertices, faces) as scene:
        t, prim, u, v, guard_intact = embree_library._probe_packets(library, scene.handle, origins, directions,
                                                                    group=width)
    assert guard_intact
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    reference = rtcore_scene.EmbreeScene(robust=True)
    TriangleMesh(reference, vertices.astype(np.float32), faces.astype(np.int32))
    expected = reference.run(origins, directions, output=1)
    hits = expected["primID"] >= 0
    assert hits.mean() > 0.5
    np.testing.assert_array_equal(prim, expected["primID"])
    for ours, theirs in ((t, "tfar"), (u, "u"), (v, "v")):
        np.testing.assert_array_equal(ours[hits], expected[theirs][hits])
