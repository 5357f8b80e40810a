"""--denoise: Intel Open Image Denoise on the beauty image, guided by albedo and normals."""

import sys

import numpy as np
import pytest
from scenes import render, sphere_on_floor_scene

from rtmesh.cli import main
from rtmesh.core.errors import MissingExtraError
from rtmesh.io import denoising
from rtmesh.lights.area_lights import QuadLight
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings


def soft_shadow_scene():
    """The sphere on the floor under a quad light: one light sample a pixel is very noisy."""
    scene = sphere_on_floor_scene()
    scene.lights = [QuadLight([1.0, -1.0, 5.0], [0.0, 3.0, 0.0], [3.0, 0.0, 0.0], 4.0)]  # emits down
    return scene


def test_denoising_brings_a_noisy_render_closer_to_the_converged_image():
    scene = soft_shadow_scene()
    reference = render(scene, width=48, height=48, spp=64, light_samples=16, sampler="jittered").image
    noisy = render(scene, width=48, height=48, spp=1, light_samples=1, sampler="random", seed=3)
    denoised = render(scene, width=48, height=48, spp=1, light_samples=1, sampler="random", seed=3,
                      denoise=True)
    # the noisy image is kept beside the denoised one, and is the render without denoising
    np.testing.assert_array_equal(denoised.noisy, noisy.image)
    assert denoised.passes == {}  # the guides are computed but not returned unless asked for

    def rmse(image):
        return float(np.sqrt(np.mean((image - reference) ** 2)))

    assert rmse(denoised.image) < 0.5 * rmse(noisy.image)


def test_a_missing_denoiser_is_one_line_naming_the_extra(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "pyoidn", None)  # import pyoidn raises ImportError
    with pytest.raises(MissingExtraError, match=r"pip install 'rtmesh\[denoise\]'"):
        Integrator(sphere_on_floor_scene(), RenderSettings(width=8, height=8, denoise=True))
    out = tmp_path / "x.png"
    code = main(["render", "assets/showcase.toml", "-o", str(out), "--width", "8", "--height", "8", "--denoise"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "rtmesh[denoise]" in err[0] and not out.exists()


def test_the_denoiser_keeps_a_clean_image_nearly_unchanged():
    rng = np.random.default_rng(2)
    image = np.full((32, 32, 3), 0.4, dtype=np.float32)
    albedo = np.full((32, 32, 3), 0.8, dtype=np.float32)
    normal = np.zeros((32, 32, 3), dtype=np.float32)
    normal[..., 2] = 1.0
    out = denoising.denoise(image + rng.normal(0, 1e-4, image.shape).astype(np.float32), albedo, normal)
    assert out.dtype == np.float32 and out.shape == image.shape
    # away from the image border (where the filter's support is cut) a flat image stays flat
    np.testing.assert_allclose(out[4:-4, 4:-4], image[4:-4, 4:-4], atol=0.01)
    assert abs(float(out.mean()) - 0.4) < 0.004
