"""The Whitted integrator as a configuration of the path kernel (rtmesh.rendering.whitted_rows,
``integrator.REFERENCE_STAGE`` unset) against the general wavefront (tests/wavefront) on every Whitted scene
in assets/: the same image within noise.

Scenes whose Whitted image is a deterministic function of the camera samples (point, spot
and directional lights, mirrors and smooth glass split into both rays) must agree to
rounding; the others (area lights, emitters and glossy lobes, which the two sample
differently) must differ from the wavefront by no more than the wavefront differs from
itself under another seed, as 4 x 4 block means.
"""

import dataclasses

import numpy as np
import pytest

import rtmesh.rendering.integrator as integrator_module
from rtmesh.api import load_scene
from rtmesh.rendering.integrator import Integrator

from scenes import ASSETS
import wavefront

# (a pass keeps the depth-of-field scene off the fused direct stage, which takes thin lenses)
DETERMINISTIC = [("showcase", {}), ("passes", {}), ("effects/dof", {"passes": ("depth",)}), ("effects/motion_blur", {})]
SAMPLED = [("glass_edges", {}), ("effects/glossy", {}), ("effects/soft_shadow", {}), ("cornell_box", {}),
           # ambient occlusion: the ambient term over rays that escape within ao_distance
           ("showcase", {"ao_samples": 4})]


def _render(scene, settings, kernel, seed=0):
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(integrator_module, "REFERENCE_STAGE", None if kernel else wavefront.attach)
        integrator = Integrator(scene, dataclasses.replace(settings, seed=seed))
        assert (integrator.path_stage is not None) == kernel and integrator.direct_stage is None
        return np.asarray(integrator.render().image, dtype=np.float64)


def _blocks(image, size=4):
    h, w = (s // size * size for s in image.shape[:2])
    return image[:h, :w].reshape(h // size, size, w // size, size, 3).mean(axis=(1, 3))


def _relative_rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.mean(a))


@pytest.mark.parametrize("name,overrides", DETERMINISTIC)
def test_deterministic_whitted_scenes_agree_to_rounding(name, overrides):
    scene, settings = load_scene(f"{ASSETS}/{name}.toml", width=40, height=30, spp=4, threads=2, **overrides)
    wavefront, kernel = _render(scene, settings, False), _render(scene, settings, True)
    assert _relative_rmse(wavefront, kernel) < 2e-4


@pytest.mark.parametrize("name,overrides", SAMPLED)
def test_sampled_whitted_scenes_agree_within_noise(name, overrides):
    scene, settings = load_scene(f"{ASSETS}/{name}.toml", width=40, height=32, spp=16, threads=2, **overrides)
    wavefront, other_seed = _render(scene, settings, False), _render(scene, settings, False, seed=7)
    kernel = _render(scene, settings, True)
    noise = _relative_rmse(_blocks(wavefront), _blocks(other_seed))
    assert noise > 0
    assert _relative_rmse(_blocks(wavefront), _blocks(kernel)) < 1.5 * noise
    assert np.mean(kernel) == pytest.approx(np.mean(wavefront), rel=max(2 * noise, 0.01))


def test_the_kernels_ambient_occlusion_darkens_as_the_wavefronts_does():
    """The ambient term's occlusion rays: the kernel's image with AO is nearer the
    wavefront's with AO than to its own without (the occlusion is traced, not dropped)."""
    scene, settings = load_scene(f"{ASSETS}/showcase.toml", width=40, height=32, spp=16, threads=2, ao_samples=4)
    wavefront, kernel = _render(scene, settings, False), _render(scene, settings, True)
    open_sky = _render(scene, dataclasses.replace(settings, ao_samples=0), True)
    effect = _relative_rmse(_blocks(wavefront), _blocks(open_sky))
    assert effect > 0.005
    assert _relative_rmse(_blocks(wavefront), _blocks(kernel)) < 0.2 * effect
    assert kernel.mean() < open_sky.mean()


def test_whitted_kernel_renders_are_the_same_for_any_thread_count():
    scene, settings = load_scene(f"{ASSETS}/glass_edges.toml", width=32, height=24, spp=4, threads=1)
    one = _render(scene, settings, True)
    two = _render(scene, dataclasses.replace(settings, threads=2), True)
    np.testing.assert_array_equal(one, two)
