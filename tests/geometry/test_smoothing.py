"""Smooth vertex normals split at creases (rtmesh.geometry.smoothing) against closed forms and a scalar
reference."""

import math

import numpy as np
import pytest
import trimesh
from scenes import icosphere

from rtmesh.geometry.smoothing import face_normals_and_corner_angles, smooth_vertex_normals
from rtmesh.loaders.trimesh_parts import parts_from_trimesh


def corner_normals(faces, normals):
    """(F, 3, 3): the normal each face corner shades with."""
    return normals[faces]


def scalar_corner_normals(vertices, faces, crease_angle):
    """One corner at a time: the corners at a vertex joined through faces that share an edge
    at that vertex and bend less than ``crease_angle``; normal = angle-weighted mean."""
    face_normal, angle = face_normals_and_corner_angles(vertices, faces)
    result = np.zeros((len(faces), 3, 3))
    for vertex in range(len(vertices)):
        corners = [(f, k) for f in range(len(faces)) for k in range(3) if faces[f][k] == vertex]
        parent = {corner: corner for corner in corners}

        def find(c):
            while parent[c] != c:
                c = parent[c]
            return c

        for a in corners:
            for b in corners:
                shared = set(faces[a[0]]) & set(faces[b[0]])
                if a[0] != b[0] and len(shared) >= 2:
                    cosine = float(np.dot(face_normal[a[0]], face_normal[b[0]]))
                    if cosine > math.cos(crease_angle):
                        parent[find(a)] = find(b)
        for a in corners:
            total = np.zeros(3)
            for b in corners:
                if find(a) == find(b):
                    total += angle[b] * face_normal[b[0]]
            result[a[0], a[1]] = total / np.linalg.norm(total)
    return result


def test_corner_angles_of_a_right_triangle_sum_to_pi():
    vertices = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    normals, angles = face_normals_and_corner_angles(vertices, np.array([[0, 1, 2]]))
    np.testing.assert_allclose(normals, [[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(angles, [[math.pi / 2, math.atan(0.5), math.atan(2.0)]])


def test_icosphere_normals_are_radial_and_match_trimesh():
    sphere = icosphere(4)
    vertices, faces, normals, _ = smooth_vertex_normals(sphere.vertices, sphere.faces)
    # a smooth closed surface: no vertex is split
    assert len(vertices) == len(sphere.vertices)
    np.testing.assert_array_equal(vertices[faces], sphere.vertices[sphere.faces])
    np.testing.assert_allclose(normals[faces], sphere.vertex_normals[sphere.faces], atol=1e-12)
    radial = vertices / np.linalg.norm(vertices, axis=1)[:, None]
    assert np.abs(normals - radial).max() < 5e-3  # the faces only approximate the sphere


def test_box_splits_into_flat_faces_and_smooths_to_diagonals_without_creases():
    box = trimesh.creation.box()
    vertices, faces, normals, _ = smooth_vertex_normals(box.vertices, box.faces)
    assert len(vertices) == 24  # every corner of every side on its own
    np.testing.assert_allclose(corner_normals(faces, normals),
                               np.repeat(box.face_normals[:, None, :], 3, axis=1), atol=1e-15)
    # smoothed everywhere, each corner's three sides weigh a right angle each, whatever
    # their triangulation: the normal is the diagonal
    vertices, faces, normals, _ = smooth_vertex_normals(box.vertices, box.faces, crease_angle=None)
    assert len(vertices) == 8
    np.testing.assert_allclose(normals, np.sign(vertices) / math.sqrt(3.0), atol=1e-15)


def test_cylinder_sides_smooth_and_caps_flat():
    cylinder = trimesh.creation.cylinder(radius=1.0, height=2.0, sections=32)
    vertices, faces, normals, _ = smooth_vertex_normals(cylinder.vertices, cylinder.faces)
    n = corner_normals(faces, normals)
    on_cap = np.abs(cylinder.face_normals[:, 2]) > 0.99
    np.testing.assert_allclose(n[on_cap], np.repeat(cylinder.face_normals[on_cap, None, :], 3, axis=1), atol=1e-12)
    side = n[~on_cap].reshape(-1, 3)
    position = vertices[faces[~on_cap]].reshape(-1, 3)
    np.testing.assert_allclose(side[:, 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(side[:, :2], position[:, :2] / np.linalg.norm(position[:, :2], axis=1)[:, None],
                               atol=1e-12)


@pytest.mark.parametrize("crease_degrees", [8.0, 20.0])
def test_matches_scalar_reference_on_a_bumpy_mesh(crease_degrees):
    sphere = icosphere(1)
    rng = np.random.default_rng(3)
    bumpy = sphere.vertices * (1.0 + 0.15 * rng.random((len(sphere.vertices), 1)))
    vertices, faces, normals, original = smooth_vertex_normals(bumpy, sphere.faces,
                                                               math.radians(crease_degrees))
    expected = scalar_corner_normals(bumpy, sphere.faces, math.radians(crease_degrees))
    np.testing.assert_allclose(corner_normals(faces, normals), expected, atol=1e-12)
    np.testing.assert_array_equal(vertices[faces], bumpy[sphere.faces])
    np.testing.assert_array_equal(vertices, bumpy[original])  # attributes follow the split
    assert len(sphere.vertices) < len(vertices) < 3 * len(sphere.faces)  # some, not all, split


def test_import_smooths_by_angle_and_keeps_the_geometry():
    cylinder = trimesh.creation.cylinder(radius=1.0, height=2.0, sections=16)
    (part,), _ = parts_from_trimesh(cylinder, "cylinder")
    np.testing.assert_allclose(part.vertices[part.faces], cylinder.vertices[cylinder.faces])
    assert len(part.vertices) > len(cylinder.vertices)  # the rims are split
    (flat,), _ = parts_from_trimesh(cylinder, "cylinder", smooth=False)
    assert flat.vertex_normals is None
