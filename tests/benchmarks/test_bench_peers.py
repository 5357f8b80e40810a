"""The pieces of the benchmarks that decide their numbers (benchmarks/_lib.py and
benchmarks/bench_peers.py): the PLY files Mitsuba reads, the error measure, the peer runner
and the time-to-error interpolation."""

import os

import numpy as np
import pytest
import trimesh

from benchmarks import _lib
from benchmarks._lib import relative_rmse, run_peer, sphere_meshes, sphere_scene, write_ply
from benchmarks.bench_peers import time_to_error


def test_ply_for_mitsuba_round_trips_positions_faces_and_normals(tmp_path):
    vertices, faces, normals = sphere_meshes()["sphere"]
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


def test_relative_rmse_of_a_uniform_offset_is_over_the_reference_mean():
    reference = np.full((4, 4, 3), 2.0)
    reference[0, 0] = 6.0  # mean 2.25, RMS larger: the denominator is the mean
    assert np.isclose(relative_rmse(reference + 0.1, reference), 0.1 / 2.25)
    assert relative_rmse(reference, reference) == 0.0


def test_relative_rmse_of_block_means_averages_noise_away():
    rng = np.random.default_rng(1)
    reference = np.ones((64, 64, 3))
    noisy = reference + rng.choice([-0.1, 0.1], size=reference.shape)
    assert np.isclose(relative_rmse(noisy, reference), 0.1)
    # 64 independent +-0.1 pixels a block: about 0.1 / 8
    assert 0.008 < relative_rmse(noisy, reference, block=8) < 0.017
    # a block's mean keeps a bias in full
    assert np.isclose(relative_rmse(reference * 1.02, reference, block=8), 0.02)
    # rows and columns beyond whole blocks are left out
    assert relative_rmse(np.ones((9, 9)), np.ones((9, 9)), block=8) == 0.0


def test_relative_rmse_over_a_mask_and_a_given_mean():
    reference = np.ones((4, 4, 3))
    image = reference.copy()
    image[0] += 1.0  # only the first row differs
    mask = np.zeros((4, 4), bool)
    mask[1:] = True
    assert relative_rmse(image, reference, mask=mask) == 0.0
    assert np.isclose(relative_rmse(image, reference, mask=~mask), 1.0)
    assert np.isclose(relative_rmse(image, reference, mask=~mask, mean=4.0), 0.25)
    with pytest.raises(ValueError, match="shape"):
        relative_rmse(image[:2], reference)
    with pytest.raises(ValueError, match="block"):
        relative_rmse(image, reference, block=2, mask=mask)


def test_the_peer_scene_is_lambert_and_the_core_scene_has_a_highlight():
    peer, core = sphere_scene(), sphere_scene(peer=False)
    np.testing.assert_array_equal(peer.vertices, core.vertices)
    assert len(peer.faces) == 20480 + 2
    assert len(peer.materials) == 1 and not peer.materials.any_specular
    np.testing.assert_array_equal(peer.ambient, 0)
    assert core.materials.any_specular
    np.testing.assert_array_equal(core.ambient, 0.05)
    (light,) = peer.lights
    np.testing.assert_array_equal(light.position, _lib.LIGHT_POSITION)


def test_run_peer_runs_a_worker_module_from_the_root_in_the_venv(tmp_path):
    assert run_peer("peers_mitsuba", [], str(tmp_path / "home"), venv=str(tmp_path / "none")) is None
    # a stand-in venv whose python reports how it was called
    python = tmp_path / "venv" / "bin" / "python"
    python.parent.mkdir(parents=True)
    python.write_text('#!/bin/sh\necho "$PWD|$HOME|$DRJIT_LIBLLVM_PATH|$*"\n')
    python.chmod(0o755)
    done = run_peer("peers_mitsuba", ["a.json", 3], str(tmp_path / "home"), venv=str(tmp_path / "venv"))
    assert done.returncode == 0
    cwd, home, llvm, args = done.stdout.strip().split("|")
    assert os.path.samefile(cwd, _lib.ROOT)
    assert home == str(tmp_path / "home") and os.path.isdir(home)
    assert llvm == _lib.LLVM
    assert args == "-m benchmarks.peers_mitsuba a.json 3"
