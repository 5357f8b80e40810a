"""assets/cornell_box.toml: the published Cornell box loads with its camera, materials and light."""

from pathlib import Path

import numpy as np
import pytest

from rtmesh.loaders.scene_file import read_scene_file

SCENE = Path(__file__).resolve().parents[1] / "assets" / "cornell_box.toml"


@pytest.fixture(scope="module")
def cornell():
    return read_scene_file(SCENE)


def _material(scene, name):
    names = [m.name for m in scene.materials.materials]
    return names.index(name), scene.materials.materials[names.index(name)]


def test_cornell_box_geometry_is_the_published_box_in_millimetres(cornell):
    scene, _ = cornell
    np.testing.assert_allclose(scene.bounds, [[0, 0, 0], [556, 548.8, 559.2]])
    assert scene.object_names == ["white", "red", "green", "light"]
    # floor, ceiling, back wall and two five-sided blocks; one quad per other part
    counts = np.bincount(scene.object_id, minlength=4)
    assert counts.tolist() == [26, 2, 2, 2]


def test_cornell_box_materials_are_the_published_reflectances(cornell):
    scene, _ = cornell
    expected = {"white": [0.725, 0.71, 0.68], "red": [0.63, 0.065, 0.05],
                "green": [0.14, 0.45, 0.091], "light": [0.78, 0.78, 0.78]}
    for name, diffuse in expected.items():
        index, material = _material(scene, name)
        np.testing.assert_array_equal(material.diffuse, diffuse)
        np.testing.assert_array_equal(material.specular, 0)
        np.testing.assert_array_equal(material.mirror, 0)
        assert (scene.material_id[np.asarray(scene.object_id) == scene.object_names.index(name)] == index).all()


def test_cornell_box_is_lit_only_by_the_emissive_ceiling_light(cornell):
    scene, _ = cornell
    assert scene.lights == []
    np.testing.assert_array_equal(scene.ambient, 0)
    emissive = np.flatnonzero((scene.materials.emission > 0).any(axis=1))
    index, light = _material(scene, "light")
    assert emissive.tolist() == [index]
    np.testing.assert_array_equal(light.emission, [17, 12, 4])
    faces = scene.faces[scene.material_id == index]
    corners = scene.vertices[faces]
    np.testing.assert_allclose(corners[..., 1], 548.7)          # 0.1 mm under the ceiling
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert (cross[:, 1] < 0).all()                              # wound to face the floor
    np.testing.assert_allclose(0.5 * np.linalg.norm(cross, axis=1).sum(), 130 * 105)


def test_cornell_box_camera_is_the_published_one(cornell):
    scene, settings = cornell
    camera = scene.camera
    np.testing.assert_array_equal(camera.position, [278, 273, -800])
    direction = camera.look_at - camera.position
    np.testing.assert_allclose(direction / np.linalg.norm(direction), [0, 0, 1])
    np.testing.assert_array_equal(camera.up, [0, 1, 0])
    assert camera.fov == 39.3 and camera.aperture == 0 and camera.projection == "perspective"
    assert settings.width == settings.height
