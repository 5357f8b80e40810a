"""assets/cornell_box.toml: the published Cornell box loads with its camera, materials and light."""

from pathlib import Path

import numpy as np
import pytest
import scenes

from rtmesh.loaders.scene_file import read_scene_file

SCENE = Path(scenes.ASSETS) / "cornell_box.toml"


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


DATA = Path(scenes.DATA)


@pytest.fixture(scope="module")
def references():
    from rtmesh.io.images import read_image

    images = {}
    for name in ("cornell_mitsuba_128", "cornell_mitsuba_128_direct"):
        image, channels = read_image(DATA / f"{name}.exr")
        assert channels == ["R", "G", "B"] and image.shape == (128, 128, 3)
        images[name] = image.astype(np.float64)
    return images


def test_cornell_references_are_linear_radiance_with_row_0_at_the_top(references):
    full, direct = references["cornell_mitsuba_128"], references["cornell_mitsuba_128_direct"]
    for image in (full, direct):
        assert np.isfinite(image).all() and image.min() >= 0
    # seen directly, the light shows its radiance: exactly (17, 12, 4) with direct light only
    # (nothing lights the light's own surface), a little more with its reflection of the box
    bright = direct[..., 0] > 16
    assert 40 < bright.sum() < 150
    # pixels whose eight neighbours see the light too lie wholly on it
    lit = bright.copy()
    lit[1:-1, 1:-1] &= np.all([np.roll(bright, (dy, dx), axis=(0, 1))[1:-1, 1:-1]
                               for dy in (-1, 0, 1) for dx in (-1, 0, 1)], axis=0)
    assert lit.sum() > 10
    np.testing.assert_allclose(direct[lit], np.tile([17, 12, 4], (lit.sum(), 1)), rtol=1e-5)
    assert (full[lit] > direct[lit]).all()
    # the light is in the top rows, centred; the red wall on the left, the green one on the right
    rows, cols = np.nonzero(bright)
    assert 12 < rows.min() and rows.max() < 24 and abs(cols.mean() - 63.5) < 2
    middle = full[40:90]
    assert (middle[:, 2:10, 0] > 3 * middle[:, 2:10, 1]).all()
    assert (middle[:, -10:-2, 1] > 1.5 * middle[:, -10:-2, 0]).all()  # a warm light on green
    # indirect light adds about a third to the direct image
    ratio = full.mean(axis=(0, 1)) / direct.mean(axis=(0, 1))
    assert ((ratio > 1.1) & (ratio < 1.6)).all()


def test_cornell_box_direct_light_matches_the_mitsuba_reference(cornell, references):
    """The scene file and the reference show the same box: rtmesh's render (whose Lambert
    term has no 1/pi) over pi is Mitsuba's direct light (Lambert albedo / pi), pixel by pixel,
    away from the light's edge (seen directly, emission is not divided)."""
    import dataclasses

    from benchmarks._lib import block_means, relative_rmse
    from rtmesh.rendering.integrator import Integrator

    scene, settings = cornell
    settings = dataclasses.replace(settings, width=32, height=32, spp=64, sampler="sobol", light_samples=4,
                                   threads=2)
    image = Integrator(scene, settings).render().image[..., :3].astype(np.float64)
    direct = references["cornell_mitsuba_128_direct"]
    reference = block_means(direct, 4)  # a box-filtered 32 x 32 pixel is the mean of 4 x 4 at 128
    on_light = block_means((direct[..., 0] > 1).astype(np.float64), 4) > 0
    whole_light = block_means((direct[..., 0] > 16.9).astype(np.float64), 4) == 1
    assert whole_light.sum() >= 4
    np.testing.assert_allclose(image[whole_light], np.tile([17, 12, 4], (whole_light.sum(), 1)), rtol=1e-6)
    away = ~on_light
    scaled = np.where(away[..., None], image / np.pi, reference)
    for c in range(3):  # each channel on its own: blue is a small part of the whole
        assert scaled[away, c].mean() == pytest.approx(reference[away, c].mean(), rel=0.005)  # measured <= 0.1 %
        assert relative_rmse(scaled[..., c], reference[..., c], block=2) < 0.01  # 8 x 8 blocks at 128; 0.2-0.3 %


def _render_path(scene, settings, size, spp, max_depth):
    import dataclasses

    from rtmesh.rendering.integrator import Integrator

    settings = dataclasses.replace(settings, width=size, height=size, spp=spp, integrator="path",
                                   max_depth=max_depth, threads=2)
    return Integrator(scene, settings).render().image[..., :3].astype(np.float64)


@pytest.mark.parametrize("name, max_depth", [("cornell_mitsuba_128", -1), ("cornell_mitsuba_128_direct", 1)])
def test_path_integrator_has_the_mitsuba_references_means(cornell, references, name, max_depth):
    """Under path, the image mean of every channel is Mitsuba's (max_depth -1, and 1 = its 2);
    32 x 32 at 64 spp is about 0.1 s and its mean within 0.2 % here (a 32 x 32 pixel is the
    mean of 4 x 4 of the reference's: box filters)."""
    image = _render_path(*cornell, size=32, spp=64, max_depth=max_depth)
    np.testing.assert_allclose(image.mean(axis=(0, 1)), references[name].mean(axis=(0, 1)), rtol=0.01)


@pytest.mark.slow
def test_path_integrator_matches_the_mitsuba_reference_in_8x8_blocks(cornell, references):
    """The issue's Cornell box criterion: at 128 x 128, image mean within 1 %, 8 x 8 block
    means within 2 % relative RMSE (256 spp: 0.02 % and 0.53 % measured)."""
    from benchmarks._lib import relative_rmse

    image = _render_path(*cornell, size=128, spp=256, max_depth=-1)
    reference = references["cornell_mitsuba_128"]
    assert image.mean() == pytest.approx(reference.mean(), rel=0.01)
    assert relative_rmse(image, reference, block=8) < 0.02
