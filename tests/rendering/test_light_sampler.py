"""``light_sampler = "tree"`` (rtmesh.lights.light_tree) in renders: unbiased (the power
sampler's image within noise), less noisy where many emitters lie at different distances,
thread-count independent, and reachable from scene files and the command line."""

import numpy as np
import pytest

from benchmarks._lib import relative_rmse
from benchmarks.bench_instancing import _scene
from rtmesh import api
from rtmesh.cli import main
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings

from scenes import ASSETS


@pytest.fixture(scope="module")
def balls():
    """400 glowing balls of 80 triangles over a floor: 32,000 emissive triangles."""
    return _scene(80, count=400, kind="emitters")[1]


def _render(scene, sampler, seed, spp=8, threads=2):
    settings = RenderSettings(width=48, height=36, spp=spp, integrator="path", light_samples=1, seed=seed,
                              threads=threads, light_sampler=sampler)
    return np.asarray(Integrator(scene, settings).render().image, np.float64)


def test_the_tree_is_unbiased_and_less_noisy_among_many_emitters(balls):
    power = [_render(balls, "power", seed) for seed in (1, 2, 3, 4)]
    tree = [_render(balls, "tree", seed) for seed in (1, 2, 3, 4)]
    # noise: the difference of two seeds (over sqrt 2)
    noise_power = (relative_rmse(power[0], power[1]) + relative_rmse(power[2], power[3])) / 2
    noise_tree = (relative_rmse(tree[0], tree[1]) + relative_rmse(tree[2], tree[3])) / 2
    assert noise_tree < 0.85 * noise_power
    # the means of four seeds agree as block means, within their noise
    mean_power, mean_tree = np.mean(power, axis=0), np.mean(tree, axis=0)
    block_noise = relative_rmse(power[0] + power[1], power[2] + power[3], block=6) / 2
    assert relative_rmse(mean_tree, mean_power, block=6) < 3 * block_noise
    assert np.mean(mean_tree) == pytest.approx(np.mean(mean_power), rel=0.02)


def test_tree_renders_do_not_depend_on_threads(balls):
    np.testing.assert_array_equal(_render(balls, "tree", 5, spp=2, threads=1),
                                  _render(balls, "tree", 5, spp=2, threads=2))


def test_the_light_sampler_from_a_scene_file_and_the_command_line(tmp_path):
    text = open(f"{ASSETS}/cornell_box.toml").read().replace("[render]", '[render]\nlight_sampler = "tree"', 1)
    path = tmp_path / "box.toml"
    path.write_text(text.replace('= "meshes/', f'= "{ASSETS}/meshes/') if '"meshes/' in text else text)
    _, settings = api.load_scene(str(path), width=8, height=6, spp=1, integrator="path")
    assert settings.light_sampler == "tree"
    out = tmp_path / "out.png"
    assert main(["render", f"{ASSETS}/cornell_box.toml", "-o", str(out), "--width", "8", "--height", "6",
                 "--spp", "1", "--integrator", "path", "--light-sampler", "tree", "-q"]) == 0
    assert out.exists()


def test_the_tree_needs_the_path_integrator():
    with pytest.raises(ValueError, match="light_sampler 'tree' needs integrator 'path'"):
        RenderSettings(integrator="whitted", light_sampler="tree").validate()
    with pytest.raises(ValueError, match="light_sampler must be one of power, tree"):
        RenderSettings(integrator="path", light_sampler="bvh").validate()


@pytest.fixture(scope="module")
def two_lamps():
    """A grey floor seen from above under two point lights of equal power far apart: at
    each floor point one lamp gives several times the light the other does."""
    from rtmesh.lights.point_lights import PointLight
    from rtmesh.materials.table import Material
    from rtmesh.scene.camera import Camera
    from rtmesh.scene.model import Scene
    from scenes import floor_quad, part

    lights = [PointLight([-3.0, 0.0, 4.0], 10.0), PointLight([3.0, 0.0, 4.0], 10.0)]
    camera = Camera([0.0, 0.0, 6.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 50.0)
    return Scene.from_parts([part("floor", floor_quad(8.0))], [Material("floor", diffuse=0.5)], lights, camera)


def _direct(scene, sampler, spp, seed=1):
    settings = RenderSettings(width=24, height=24, spp=spp, integrator="path", light_samples=1, max_depth=1,
                              sampler=sampler, seed=seed, threads=1)
    return np.asarray(Integrator(scene, settings).render().image, np.float64)


@pytest.mark.parametrize("sampler", ["sobol", "zsobol", "jittered"])
def test_the_first_vertexs_light_choice_is_stratified_over_a_pixels_samples(two_lamps, sampler):
    # two samples a pixel: a stratified choice takes each lamp once (zsobol.sequence_number),
    # so what is left is the light's change across the pixel; hashed choices (the random
    # sampler) give half the pixels one lamp twice
    reference = _direct(two_lamps, "sobol", 256)
    stratified = relative_rmse(_direct(two_lamps, sampler, 2), reference)
    hashed = relative_rmse(_direct(two_lamps, "random", 2), reference)
    assert hashed > 0.2
    assert stratified < 0.1 * hashed
