"""The pieces of tools/bench_peers.py that decide its numbers: the PLY files Mitsuba reads,
the error measure and the time-to-error interpolation."""

import os
import sys

import numpy as np
import trimesh

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tools"))
from bench_peers import peer_meshes, relative_rmse, time_to_error, write_ply  # noqa: E402


def test_ply_for_mitsuba_round_trips_positions_faces_and_normals(tmp_path):
    vertices, faces, normals = peer_meshes()["sphere"]
    path = tmp_path / "sphere.ply"
    write_ply(path, vertices, faces, normals)
    mesh = trimesh.load(path, process=False)
    np.testing.assert_array_equal(mesh.vertices, vertices)  # float32-exact on both sides
    np.testing.assert_array_equal(mesh.faces, faces)
    np.testing.assert_allclose(mesh.vertex_normals, normals, atol=1e-6)


def test_time_to_error_is_exact_on_a_power_law():
    # Monte Carlo: error = c / sqrt(time); log-log interpolation is exact on it
    times = [0.1, 0.4, 1.6, 6.4]
    errors = [0.05 / np.sqrt(t) for t in times]
    assert np.isclose(time_to_error([1, 4, 16, 64], times, errors, 0.05 / np.sqrt(0.8)), 0.8)
    assert time_to_error([1, 4, 16, 64], times, errors, 1.0) is None  # not bracketed
    assert time_to_error([1, 4, 16, 64], times, errors, 1e-4) is None


def test_relative_rmse_of_a_uniform_offset():
    reference = np.full((4, 4, 3), 2.0)
    assert np.isclose(relative_rmse(reference + 0.1, reference), 0.05)
