"""Environment lighting: the background lights the scene, importance-sampled, with shadows."""

import math

import numpy as np
import pytest
from scenes import floor_quad, part, render, settings, sun_sky

from rtmesh.core.errors import SceneError
from rtmesh.lights.environment import EnvironmentLighting
from rtmesh.loaders.scene_file import scene_from_dict
from rtmesh.materials.table import Material
from rtmesh.rendering.integrator import Integrator
from rtmesh.sampling.warps import direction_to_latlong
from rtmesh.scene.background import GradientBackground, SolidBackground
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene


def floor_under(background, kd=0.5, extra_parts=(), extra_materials=()):
    """A wide diffuse floor z = 0 seen from straight above, lit only by ``background``."""
    vertices, faces = floor_quad(1000.0)
    camera = Camera([0.0, 0.0, 3.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 40.0)
    background.lighting = True
    return Scene.from_parts([part("floor", (vertices, faces)), *extra_parts],
                            [Material("floor", diffuse=kd), *extra_materials], [], camera, ambient=0.0,
                            background=background)


def test_a_uniform_sky_gives_a_diffuse_floor_pi_times_its_radiance():
    """kd x E with E = pi L under a uniform sky of radiance L filling the hemisphere (rtmesh's
    Blinn-Phong has no 1/pi: a white surface under such a sky reflects pi L)."""
    result = render(floor_under(SolidBackground([1.0, 0.5, 0.25])), width=24, height=24, spp=4,
                    light_samples=64, sampler="jittered")
    assert "environment_lighting" in result.stats.stages_enabled and result.stats.rays["environment"] > 0
    expected = 0.5 * math.pi * np.array([1.0, 0.5, 0.25])
    np.testing.assert_allclose(result.image.reshape(-1, 3).mean(axis=0), expected, rtol=0.01)


def test_sampling_density_is_a_density_and_pdf_matches_sample():
    lighting = EnvironmentLighting(sun_sky(), accel=None, settings=settings(light_samples=1), offset_scale=1.0)
    rng = np.random.default_rng(5)
    wi, pdf = lighting.sample(rng.uniform(size=(400_000, 2)))
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, rtol=1e-12)
    # E[1 / pdf] is the sphere's solid angle
    assert abs(np.mean(1.0 / pdf) / (4.0 * math.pi) - 1.0) < 0.01
    # the density evaluated at the sampled directions is the one sample reported
    inside = np.isfinite(pdf)
    np.testing.assert_allclose(lighting.pdf(wi[inside][:2000]), pdf[inside][:2000], rtol=1e-6)
    # texels are drawn in proportion to luminance x sin(theta): the sun's share of samples is
    # its share of that mass (about 2/3, from 0.3 % of the sphere)
    uv = direction_to_latlong(wi, lighting.rotation)
    row = np.clip(((1.0 - uv[:, 1]) * lighting.height).astype(int), 0, lighting.height - 1)
    column = np.clip((uv[:, 0] * lighting.width).astype(int), 0, lighting.width - 1)
    sun = lighting._func > 10.0 * np.median(lighting._func)
    share = lighting._func[sun].sum() / lighting._func.sum()
    assert 0.5 < share and abs(sun[row, column].mean() - share) < 0.01


def test_a_floor_under_an_environment_image_matches_quadrature_of_its_irradiance():
    """The environment has +Y up: tilt the floor's frame so its normal is +Y."""
    sky = sun_sky()
    vertices, faces = floor_quad(1000.0)
    vertices = vertices[:, [0, 2, 1]] * [1.0, 1.0, -1.0]  # z = 0 plane facing +z -> y = 0 plane facing +y
    faces = faces[:, [0, 2, 1]]
    camera = Camera([0.0, 3.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -1.0], 30.0)
    sky.lighting = True
    scene = Scene.from_parts([part("floor", (vertices, faces))], [Material("floor", diffuse=0.5)], [], camera,
                             ambient=0.0, background=sky)
    image = render(scene, width=16, height=16, spp=16, light_samples=32, sampler="jittered").image
    # reference: irradiance on an upward surface by midpoint quadrature over the hemisphere
    n_theta, n_phi = 600, 1200
    theta = (np.arange(n_theta) + 0.5) / n_theta * (math.pi / 2)
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2 * math.pi
    t, f = np.meshgrid(theta, phi, indexing="ij")
    directions = np.stack([np.sin(t) * np.cos(f), np.cos(t), np.sin(t) * np.sin(f)], axis=-1).reshape(-1, 3)
    weights = (np.cos(t) * np.sin(t)).reshape(-1) * (math.pi / 2 / n_theta) * (2 * math.pi / n_phi)
    irradiance = (sky.radiance(directions) * weights[:, None]).sum(axis=0)
    np.testing.assert_allclose(image.reshape(-1, 3).mean(axis=0), 0.5 * irradiance, rtol=0.02)


def test_objects_cast_shadows_of_the_sky():
    from scenes import box

    wall = box((0.2, 6.0, 6.0), (0.5, 0.0, 3.0))  # a tall wall right of the image centre
    scene = floor_under(SolidBackground([1.0, 1.0, 1.0]), extra_parts=[part("wall", wall, material=1)],
                        extra_materials=[Material("wall", diffuse=0.0)])
    image = render(scene, width=32, height=32, spp=4, light_samples=32).image[..., 0]
    # unoccluded, the floor would show 0.5 pi; 0.57 units from a wall 6 high about half the
    # sky is hidden there, less farther away
    unoccluded = 0.5 * math.pi
    assert image[16, 13] < 0.6 * unoccluded and image[16, 13] < image[16, 2] < 0.7 * unoccluded


def test_scene_files_switch_environment_lighting_on_and_off():
    base = {"objects": [{"primitive": "plane", "size": [4, 4]}],
            "camera": {"position": [0, 3, 3], "look_at": [0, 0, 0]}}
    scene, _ = scene_from_dict({**base, "background": {"type": "gradient", "top": 1, "bottom": 0, "lighting": True}})
    assert isinstance(scene.background, GradientBackground) and scene.background.lighting
    assert Integrator(scene, settings()).plan.environment_lighting
    scene, _ = scene_from_dict({**base, "background": {"colour": 0.5}})
    assert not scene.background.lighting and not Integrator(scene, settings()).plan.environment_lighting
    with pytest.raises(SceneError, match=r"background\.lighting: does not apply to a transparent background"):
        scene_from_dict({**base, "background": {"type": "transparent", "lighting": True}})


def test_environment_lighting_is_bit_identical_across_thread_counts():
    scene = floor_under(sun_sky())
    one = render(scene, width=20, height=20, spp=2, light_samples=4, threads=1, chunk_samples=100)
    two = render(scene, width=20, height=20, spp=2, light_samples=4, threads=2, chunk_samples=100)
    np.testing.assert_array_equal(one.image, two.image)
