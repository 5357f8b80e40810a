"""The compiled scene-build passes (rtmesh.geometry.build_kernels) give the arrays the NumPy code they
replace gave, to the bit (zero signs included), so that no image changes."""

import numpy as np
import pytest
import trimesh
from scenes import icosphere
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from rtmesh.geometry import build_kernels
from rtmesh.geometry.accel import corner_table
from rtmesh.geometry.smoothing import face_normals_and_corner_angles, smooth_vertex_normals
from rtmesh.loaders.importers import load_trimesh
from rtmesh.loaders.mesh_processing import _merge_keeps_everything
from rtmesh.loaders.trimesh_parts import parts_from_trimesh
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene.model import MeshPart, Scene


# ---------------------------------------------------------------- the NumPy formulations
def numpy_face_normals_and_corner_angles(vertices, faces):
    p0, p1, p2 = (np.asarray(vertices, dtype=np.float64)[faces[:, k]] for k in range(3))
    e01, e12, e20 = p1 - p0, p2 - p1, p0 - p2
    cross = np.cross(e01, -e20)
    double_area = np.sqrt(np.einsum("ij,ij->i", cross, cross))
    normals = cross / np.where(double_area > 0.0, double_area, np.inf)[:, None]
    angles = np.stack([np.arctan2(double_area, -np.einsum("ij,ij->i", e01, e20)),
                       np.arctan2(double_area, -np.einsum("ij,ij->i", e12, e01)),
                       np.arctan2(double_area, -np.einsum("ij,ij->i", e20, e12))], axis=1)
    angles[double_area == 0.0] = 0.0
    return normals, angles


def numpy_smooth_vertex_normals(vertices, faces, crease_angle):
    """Edges paired by a sort, corners grouped by SciPy's connected components."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.intp).reshape(-1, 3)
    n_faces = len(faces)
    face_normal, angle = numpy_face_normals_and_corner_angles(vertices, faces)
    start, end = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    key = np.minimum(start, end) * len(vertices) + np.maximum(start, end)
    order = np.argsort(key)
    shared = key[order[1:]] == key[order[:-1]]
    slot_a, slot_b = order[:-1][shared], order[1:][shared]
    if crease_angle is not None:
        cosine = np.einsum("ij,ij->i", face_normal[slot_a // 3], face_normal[slot_b // 3])
        slot_a, slot_b = slot_a[cosine > np.cos(crease_angle)], slot_b[cosine > np.cos(crease_angle)]
    b_next = 3 * (slot_b // 3) + (slot_b + 1) % 3
    same_way = start[slot_b] == start[slot_a]
    links = (np.concatenate([slot_a, 3 * (slot_a // 3) + (slot_a + 1) % 3]),
             np.concatenate([np.where(same_way, slot_b, b_next), np.where(same_way, b_next, slot_b)]))
    graph = coo_matrix((np.ones(len(links[0]), dtype=np.int8), links), shape=(3 * n_faces, 3 * n_faces))
    n_groups, group = connected_components(graph, directed=False)
    source = np.zeros(n_groups, dtype=np.intp)
    source[group] = start
    weighted = (face_normal[:, None, :] * angle[:, :, None]).reshape(-1, 3)
    normal_sum = np.stack([np.bincount(group, weighted[:, c], minlength=n_groups) for c in range(3)], axis=1)
    length = np.sqrt(np.einsum("ij,ij->i", normal_sum, normal_sum))
    normals = normal_sum / np.where(length > 0.0, length, np.inf)[:, None]
    return vertices[source], group.reshape(n_faces, 3).astype(np.intp), normals, source


def assert_identical(actual, expected):
    for a, e in zip(actual, expected, strict=True):
        assert (a is None) == (e is None)
        if a is None:
            continue
        a, e = np.asarray(a), np.asarray(e)
        assert a.dtype == e.dtype and a.shape == e.shape
        assert np.array_equal(a, e, equal_nan=a.dtype.kind == "f")
        if a.dtype.kind == "f":
            assert np.array_equal(np.signbit(a), np.signbit(e))


# ---------------------------------------------------------------- test meshes
def noisy_sphere():
    sphere = icosphere(3)
    rng = np.random.default_rng(4)
    return sphere.vertices + rng.normal(scale=0.03, size=sphere.vertices.shape), sphere.faces


def degenerate_mesh():
    """Zero-length edges, repeated corners, a vertex no face uses, and a coincident pair."""
    vertices, faces = noisy_sphere()
    vertices, faces = vertices.copy(), faces.copy()
    vertices[7] = vertices[8]
    faces[3] = [faces[3, 0], faces[3, 0], faces[3, 1]]
    faces[10] = [faces[10, 0], faces[10, 1], faces[10, 0]]
    return np.vstack([vertices, [[9.0, 9.0, 9.0]]]), faces


def fin_mesh():
    """A box with a fin on one edge: an edge of three faces (non-manifold)."""
    box = trimesh.creation.box()
    vertices = np.vstack([box.vertices, [[0.5, 0.5, 1.5]]])
    a = int(np.flatnonzero((box.vertices == [0.5, 0.5, 0.5]).all(axis=1))[0])
    b = int(np.flatnonzero((box.vertices == [0.5, -0.5, 0.5]).all(axis=1))[0])
    return vertices, np.vstack([box.faces, [[8, a, b]]])


def random_soup():
    rng = np.random.default_rng(9)
    return rng.normal(size=(60, 3)), rng.integers(0, 60, size=(400, 3))


MESHES = {
    "noisy sphere": noisy_sphere,
    "box": lambda: (trimesh.creation.box().vertices, trimesh.creation.box().faces),
    "cylinder": lambda: (trimesh.creation.cylinder(radius=1.0, height=2.0, sections=16).vertices,
                         trimesh.creation.cylinder(radius=1.0, height=2.0, sections=16).faces),
    "degenerate": degenerate_mesh,
    "fin (non-manifold)": fin_mesh,
    "random soup (non-manifold)": random_soup,
}


@pytest.mark.parametrize("name", MESHES)
@pytest.mark.parametrize("crease", [np.radians(20.0), np.radians(60.0), None])
def test_smooth_normals_are_those_of_the_numpy_formulation(name, crease):
    vertices, faces = MESHES[name]()
    expected = numpy_smooth_vertex_normals(vertices, faces, crease)
    assert_identical(smooth_vertex_normals(vertices, faces, crease), expected)


@pytest.mark.parametrize("name", MESHES)
def test_face_normals_and_angles_are_those_of_the_numpy_formulation(name):
    vertices, faces = MESHES[name]()
    faces = np.asarray(faces, dtype=np.intp)
    assert_identical(face_normals_and_corner_angles(vertices, faces),
                     numpy_face_normals_and_corner_angles(vertices, faces))


def test_edge_pairs_report_non_manifold_edges():
    vertices, faces = fin_mesh()
    assert not build_kernels.edge_pairs(faces, len(vertices))[1]
    box = trimesh.creation.box()
    pairs, manifold = build_kernels.edge_pairs(box.faces, len(box.vertices))
    assert manifold and pairs.shape == (2, 18)  # a closed mesh: every edge has two faces


def test_smoothing_rejects_indices_that_are_not_vertices():
    vertices, faces = noisy_sphere()
    for bad in (len(vertices), -1):
        wrong = faces.copy()
        wrong[5, 1] = bad
        with pytest.raises(IndexError):
            smooth_vertex_normals(vertices, wrong)


# ---------------------------------------------------------------- loading
def test_rows_distinct_and_referenced_and_finite():
    rng = np.random.default_rng(3)
    keys = rng.integers(-10**9, 10**9, size=(5000, 3))
    assert build_kernels.rows_distinct(keys)
    keys[4321] = keys[17]
    assert not build_kernels.rows_distinct(keys)
    # rows differing in one column only, and equal sums
    assert build_kernels.rows_distinct(np.array([[1, 2, 3], [1, 2, 4], [3, 2, 1], [2, 1, 3]]))
    assert build_kernels.rows_distinct(np.zeros((0, 3), dtype=np.int64))
    vertices = rng.normal(size=(4, 3))
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    assert build_kernels.referenced_and_finite(vertices, faces)
    assert not build_kernels.referenced_and_finite(vertices, faces[:1])  # vertex 3 unused
    vertices[1, 2] = np.inf
    assert not build_kernels.referenced_and_finite(vertices, faces)


def write_meshes(folder):
    """Files in every non-glTF format: duplicate vertices (STL, a polygon soup as OBJ),
    texture coordinates, a second object, normals in the file, a NaN vertex."""
    sphere = icosphere(2)
    paths = []
    for ext in ("stl", "ply", "off", "obj"):
        path = folder / f"sphere.{ext}"
        sphere.export(path)
        paths.append(path)
    soup = folder / "soup.obj"
    lines = ["mtllib soup.mtl", "o box", "usemtl red"]
    box = trimesh.creation.box()
    lines += ["v %r %r %r" % tuple(map(float, p)) for p in box.vertices]
    lines += ["vt %r %r" % tuple(map(float, p)) for p in np.random.default_rng(0).random((8, 2))]
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in box.faces]
    lines += ["o ball", "usemtl blue"]
    moved = sphere.vertices + [3.0, 0.0, 0.0]
    lines += ["v %r %r %r" % tuple(map(float, moved[i])) for i in sphere.faces.ravel()]
    lines += [f"f {9 + 3 * k} {10 + 3 * k} {11 + 3 * k}" for k in range(len(sphere.faces))]
    lines += ["v nan 0 0", "f 1 2 %d" % (9 + 3 * len(sphere.faces))]
    soup.write_text("\n".join(lines) + "\n")
    (folder / "soup.mtl").write_text("newmtl red\nKd 0.8 0.1 0.1\nnewmtl blue\nKd 0.1 0.1 0.8\n")
    with_normals = folder / "normals.ply"
    with_normals.write_bytes(trimesh.exchange.ply.export_ply(sphere, vertex_normal=True))
    return paths + [soup, with_normals]


def test_loading_gives_the_meshes_trimesh_gives(tmp_path):
    for path in write_meshes(tmp_path):
        expected = trimesh.load(path, force="scene")
        loaded = load_trimesh(path)
        assert list(loaded.geometry) == list(expected.geometry)
        for name, mesh in expected.geometry.items():
            got = loaded.geometry[name]
            assert_identical([got.vertices, got.faces], [mesh.vertices, mesh.faces])
            assert got.metadata.get("processed") == mesh.metadata.get("processed")
            for attribute in ("uv",):
                a, b = getattr(got.visual, attribute, None), getattr(mesh.visual, attribute, None)
                assert (a is None) == (b is None)
                if a is not None:
                    assert_identical([a], [b])
            assert ("vertex_normals" in got._cache.cache) == ("vertex_normals" in mesh._cache.cache)
            if "vertex_normals" in mesh._cache.cache:
                assert_identical([got.vertex_normals], [mesh.vertex_normals])
        # and the parts rtmesh builds from them
        for got, part in zip(parts_from_trimesh(loaded)[0], parts_from_trimesh(expected)[0], strict=True):
            assert_identical([got.vertices, got.faces, got.vertex_normals],
                             [part.vertices, part.faces, part.vertex_normals])


def test_trimesh_processing_runs_only_where_it_changes_something(tmp_path):
    sphere = icosphere(2)
    sphere.export(tmp_path / "sphere.ply")
    sphere.export(tmp_path / "sphere.stl")  # STL repeats each vertex in every face
    unique = trimesh.load(tmp_path / "sphere.ply", process=False)
    assert _merge_keeps_everything(unique)
    assert not _merge_keeps_everything(trimesh.load(tmp_path / "sphere.stl", process=False))
    unused = trimesh.Trimesh(np.vstack([sphere.vertices, [[5.0, 5.0, 5.0]]]), sphere.faces, process=False)
    assert not _merge_keeps_everything(unused)
    # within trimesh's merge tolerance of another vertex
    near = sphere.vertices.copy()
    near[1] = near[0] + 1e-12
    assert not _merge_keeps_everything(trimesh.Trimesh(near, sphere.faces, process=False))


# ---------------------------------------------------------------- placing and flattening parts
@pytest.mark.parametrize("name", ["noisy sphere", "degenerate", "random soup (non-manifold)"])
def test_face_normals_finite_faces_and_unit_normals_match_numpy(name):
    vertices, faces = MESHES[name]()
    vertices = vertices.copy()
    vertices[5] = np.nan
    keep = np.isfinite(vertices).all(axis=1)[faces].all(axis=1)
    assert_identical([build_kernels.finite_faces(vertices, faces)], [keep])
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    normal, length = build_kernels.face_crosses(vertices, faces)
    assert_identical([length], [area2])
    good = area2 > 0.0
    assert_identical([normal[good]], [cross[good] / area2[good][:, None]])
    rng = np.random.default_rng(1)
    vn = rng.normal(size=vertices.shape)
    vn[3] = 0.0
    vn[4, 1] = np.inf
    vn[6] = -0.0
    length = np.linalg.norm(vn, axis=1)
    usable = np.isfinite(length) & (length > 0.0)
    unit = np.where(usable[:, None], vn / np.where(usable, length, 1.0)[:, None], 0.0)
    assert_identical(build_kernels.unit_rows(vn, faces), [unit, usable[faces].all(axis=1)])


def test_finite_without_negative_zero():
    assert build_kernels.finite_without_negative_zero(np.array([[0.0, 1.0, -2.0]]))
    assert not build_kernels.finite_without_negative_zero(np.array([[0.0, -0.0, 1.0]]))
    assert not build_kernels.finite_without_negative_zero(np.array([[np.nan, 0.0, 1.0]]))
    rng = np.random.default_rng(2)
    normals = rng.normal(size=(1000, 3))
    normals[::7, 1] = 0.0
    # what the importer relies on when it skips the identity: the product changes nothing
    assert_identical([normals @ np.eye(3).T], [normals])


# ---------------------------------------------------------------- integrator tables
def test_face_tables_are_the_corner_tables_row_by_row():
    vertices, faces, normals, _ = smooth_vertex_normals(*noisy_sphere())
    parts = [MeshPart("ball", vertices, faces, vertex_normals=normals)]
    scene = Scene.from_parts(parts)
    integrator = Integrator(scene, RenderSettings(width=8, height=8, spp=1))
    expected = np.empty((len(scene.faces), 12))
    expected[:, :9] = integrator.accel.triangles
    expected[:, 9:] = scene.face_normals
    assert_identical([integrator.tables.faces], [expected])
    assert integrator.tables.faces.flags.c_contiguous
    expected = np.ascontiguousarray(corner_table(scene.vertex_normals, scene.faces))
    assert_identical([integrator.tables.vertex_normals], [expected])
    assert integrator.tables.vertex_normals.flags.c_contiguous
