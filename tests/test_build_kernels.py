"""The compiled scene-build passes (rtmesh.build_kernels) give the arrays the NumPy code they
replace gave, to the bit (zero signs included), so that no image changes."""

import numpy as np
import pytest
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from rtmesh import build_kernels
from rtmesh.smoothing import face_normals_and_corner_angles, smooth_vertex_normals
from scenes import icosphere


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
