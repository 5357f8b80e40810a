"""Caustics by photon passes (rtmesh.rendering.caustics, rtmesh.rendering.photon_kernel): the
glass ball of assets/effects/caustics.toml against Mitsuba 3's particle tracer, convergence as
passes go on, no path counted twice, when ``auto`` turns the passes on, determinism."""

import os

import numpy as np
import OpenImageIO as oiio
import pytest
import scenes

from benchmarks.bench_caustics import blocks, regions
from rtmesh import api
from rtmesh.core.errors import SceneError
from rtmesh.io.passes import LIGHT_PATH_PASSES
from rtmesh.rendering import caustics
from rtmesh.rendering.integrator import Integrator

HERE = scenes.TESTS
ROOT = os.path.dirname(HERE)
SCENE = os.path.join(ROOT, "assets", "effects", "caustics.toml")
REFERENCE = os.path.join(HERE, "data", "caustics_ptracer_64x48.exr")
W, H = 64, 48


def _render(path=SCENE, **settings):
    scene, s = api.load_scene(path, **{"width": W, "height": H, "threads": 2, **settings})
    return scene, Integrator(scene, s).render()


@pytest.fixture(scope="module")
def reference():
    return oiio.ImageBuf(REFERENCE).get_pixels(oiio.FLOAT)[:, :, :3].astype(np.float64)


@pytest.fixture(scope="module")
def photon_render():
    """64 photon passes of 16384 photons, with the material and centre-position labels."""
    return _render(spp=64, photons=16384, passes=("material_id", "position_center"))


def _floor_blocks(scene, result):
    """Blocks that see the floor only (a particle tracer cannot render the ball), and among
    them those wholly outside the ball's shadow (lit by next-event estimation alone)."""
    return regions(scene, result, W, H)


def test_caustic_matches_the_particle_tracer(photon_render, reference):
    scene, result = photon_render
    assert result.stats.photon_passes == 64 and result.stats.photons == 16384
    floor, lit = _floor_blocks(scene, result)
    ours, ref = blocks(result.image.astype(np.float64)[..., 0]), blocks(reference[..., 0])
    assert floor.sum() >= 24 and lit.sum() >= 12 and (floor & ~lit).sum() >= 4
    # the floor, the focused spot inside the shadow included, within 5 % as block means
    assert np.abs(ours[floor] / ref[floor] - 1).max() < 0.05
    # the brightest block of the particle tracer's image within 10 %
    brightest = np.unravel_index(np.argmax(np.where(floor, ref, -1.0)), ref.shape)
    assert abs(ours[brightest] / ref[brightest] - 1) < 0.10
    # outside the shadow, next-event estimation alone: within 2 %
    assert np.abs(ours[lit] / ref[lit] - 1).max() < 0.02


def test_without_photons_the_caustic_is_missing(reference):
    """The test above can fail: a path tracer alone leaves the shadow's focused spot dark."""
    scene, result = _render(spp=16, caustics="off", passes=("material_id", "position_center"))
    assert result.stats.photon_passes == 0
    floor, lit = _floor_blocks(scene, result)
    ours, ref = blocks(result.image.astype(np.float64)[..., 0]), blocks(reference[..., 0])
    assert np.abs(ours[floor] / ref[floor] - 1).max() > 0.3


def test_the_caustic_converges_as_passes_go_on(photon_render, reference):
    scene, result = photon_render
    floor, lit = _floor_blocks(scene, result)
    caustic = floor & ~lit
    _, early = _render(spp=4, photons=16384)

    def error(image):
        ours, ref = blocks(image.astype(np.float64)[..., 0]), blocks(reference[..., 0])
        return np.sqrt(np.mean((ours[caustic] / ref[caustic] - 1) ** 2))

    assert error(result.image) < 0.6 * error(early.image)


def test_radius_rule_shrinks_as_knaus_and_zwicker():
    factors = [caustics.radius_factor(k) for k in range(6)]
    assert factors[0] == 1.0
    expected = 1.0
    for k in range(1, 6):
        expected *= (k + caustics.ALPHA) / (k + 1)
        assert factors[k] == pytest.approx(np.sqrt(expected), rel=1e-12)


def test_photon_renders_do_not_depend_on_threads_and_light_paths_sum_to_the_image():
    images = []
    for threads in (1, 2):
        _, result = _render(width=32, height=24, spp=4, photons=4096, threads=threads, chunk_samples=256,
                            passes=LIGHT_PATH_PASSES)
        images.append(result)
    assert np.array_equal(images[0].image, images[1].image)
    total = sum(images[0].passes[name] for name in LIGHT_PATH_PASSES)
    np.testing.assert_allclose(total, images[0].image, atol=1e-5)
    # the caustic comes through the glass: indirect light of the floor's diffuse lobe
    assert images[0].passes["indirect_diffuse"].sum() > 0


def test_adaptive_rounds_continue_the_passes_the_same_for_any_thread_count():
    results = [_render(width=32, height=24, spp=4, photons=2048, threads=threads, target_error=0.02, max_spp=16)[1]
               for threads in (1, 2)]
    assert np.array_equal(results[0].image, results[1].image)
    st = results[0].stats
    assert len(st.rounds) > 1 and st.photon_passes > 4
    # the later rounds' pixels took passes beyond the first round's four
    assert results[0].film.count.max() == 16


def test_auto_turns_photons_on_only_where_a_small_light_meets_a_specular_surface(tmp_path):
    def scene_file(light, material):
        text = open(SCENE).read().replace("../meshes/", os.path.join(ROOT, "assets", "meshes") + "/")
        text = text.replace('model = "dielectric"\nior = 1.5', material)
        text = text.replace('type = "point"\nposition = [0.5, 4.0, -2.5]\nintensity = 40', light)
        path = tmp_path / "scene.toml"
        path.write_text(text)
        return str(path)

    def enabled(path, **settings):
        scene, s = api.load_scene(path, **{"width": 16, "height": 12, "spp": 1, **settings})
        return Integrator(scene, s).path_stage.caustics.enabled

    point = 'type = "point"\nposition = [0.5, 4.0, -2.5]\nintensity = 40'
    glass = 'model = "dielectric"\nior = 1.5'
    assert enabled(SCENE)
    assert not enabled(SCENE, caustics="off")
    # a diffuse ball: nothing to focus light
    assert not enabled(scene_file(point, 'model = "lambert"\ndiffuse = 0.5'))
    # a rough ball: no delta lobe
    assert not enabled(scene_file(point, 'model = "dielectric"\nior = 1.5\nroughness = 0.5'))
    # a large area light: a path tracer finds its caustics
    big = 'type = "quad"\nposition = [0, 3, 0]\nedge1 = [6, 0, 0]\nedge2 = [0, 0, 6]\nradiance = 1'
    assert not enabled(scene_file(big, glass))
    assert enabled(scene_file(big, glass), caustics="photons")
    small = 'type = "quad"\nposition = [0.5, 4, -2.5]\nedge1 = [0.2, 0, 0]\nedge2 = [0, 0, 0.2]\nradiance = 100'
    assert enabled(scene_file(small, glass))


def test_a_scene_without_caustics_renders_as_with_caustics_off():
    path = os.path.join(ROOT, "assets", "cornell_box.toml")  # diffuse walls, no mirror or glass
    _, auto = _render(path, width=32, height=24, spp=2, integrator="path")
    _, off = _render(path, width=32, height=24, spp=2, integrator="path", caustics="off")
    assert auto.stats.photon_passes == 0
    assert np.array_equal(auto.image, off.image)


def test_photons_with_moving_objects_is_refused():
    path = os.path.join(ROOT, "assets", "effects", "motion_blur.toml")
    scene, s = api.load_scene(path, width=16, height=12, spp=1, integrator="path", caustics="photons")
    with pytest.raises(SceneError, match="moving objects"):
        Integrator(scene, s)


def test_the_summary_line_reports_the_photon_passes(capsys, tmp_path):
    from rtmesh.cli import main

    out = tmp_path / "c.png"
    assert main(["render", SCENE, "-o", str(out), "--width", "16", "--height", "12", "--spp", "2",
                 "--photons", "1000"]) == 0
    line = capsys.readouterr().out
    assert "caustics: 2 photon passes of 1000 photons" in line


@pytest.mark.slow
def test_photons_and_path_tracing_agree_under_an_area_light(tmp_path):
    """No path counted twice: under a quad light a path tracer finds the caustic too (slowly);
    with photons carrying the caustic paths the image must be the same."""
    text = open(SCENE).read().replace("../meshes/", os.path.join(ROOT, "assets", "meshes") + "/")
    text = text.replace('type = "point"\nposition = [0.5, 4.0, -2.5]\nintensity = 40',
                        'type = "quad"\nposition = [0.5, 4.0, -2.5]\nedge1 = [1, 0, 0]\nedge2 = [0, 0, 1]\n'
                        'radiance = 40')
    path = tmp_path / "quad.toml"
    path.write_text(text)
    scene, photons = _render(str(path), width=32, height=24, spp=2048, photons=4096, caustics="photons",
                             passes=("material_id",))
    # the path tracer's caustic through the ball is noisy (its blocks vary by about 2.5 %
    # between seeds at 2048 spp): eight times the samples
    _, off = _render(str(path), width=32, height=24, spp=16384, caustics="off")
    assert photons.stats.photon_passes == 2048
    a, b = blocks(photons.image.astype(np.float64)[..., 0]), blocks(off.image.astype(np.float64)[..., 0])
    # the floor's blocks, the caustic's included (those seeing the glass are the path
    # tracer's noisiest: light through the ball to the floor and back through it)
    names = [m.name for m in scene.materials.materials]
    floor = blocks((photons.passes["material_id"].reshape(24, 32) == names.index("floor")).astype(float)) == 1
    assert floor.sum() >= 6
    assert np.abs(a[floor] / b[floor] - 1).max() < 0.02
