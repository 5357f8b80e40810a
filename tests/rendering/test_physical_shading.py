"""The physically based stage: glTF metallic-roughness surfaces lit by lights and the
environment, path traced with multiple importance sampling (tests/wavefront/physical_shading.py)."""

import math

import numpy as np
import pytest
import trimesh
from scenes import part, render
from trimesh.visual.material import PBRMaterial

from rtmesh.api import load_scene
from rtmesh.lights.area_lights import QuadLight
from rtmesh.lights.point_lights import PointLight
from rtmesh.materials import metallic_roughness as brdf
from rtmesh.materials.table import Material
from rtmesh.rendering.integrator import Integrator
from wavefront.physical_shading import bsdf_weight
from wavefront.stage import Wavefront
from rtmesh.scene.background import SolidBackground
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene
from rtmesh.scene.studio import STUDIO_PATH, studio_rotation
import wavefront


def physical(name="pbr", base=1.0, metallic=1.0, roughness=0.5, **fields):
    return Material(name, model="metallic_roughness", base_color=base, metallic=metallic,
                    perceptual_roughness=roughness, diffuse=np.asarray(base) * (1.0 - metallic), **fields)


def tilted_quad(theta_degrees, half=1.0):
    """A square through the origin whose normal makes ``theta`` with +Z (tilted about +X)."""
    t = math.radians(theta_degrees)
    n = np.array([0.0, -math.sin(t), math.cos(t)])
    u = np.array([1.0, 0.0, 0.0])
    v = np.cross(n, u)
    corners = np.array([-u - v, u - v, u + v, -u + v]) * half
    return corners, np.array([[0, 1, 2], [0, 2, 3]])


def furnace_scene(material, theta, background=1.0):
    """``material`` on a flat square seen by an orthographic camera along +Z, its normal
    ``theta`` degrees from the view: every pixel sees the surface at the same angle."""
    camera = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], projection="orthographic",
                    ortho_height=0.6)
    sky = SolidBackground(np.full(3, background))
    sky.lighting = True
    return Scene.from_parts([part("quad", tilted_quad(theta))], [material], [], camera, ambient=0.0,
                            background=sky)


def directional_albedo(cos_theta, base, metallic, roughness, n=400_000):
    """``integral f cos dw`` over the hemisphere, (3,): the mean of ``f cos / pdf`` over
    directions drawn by :func:`rtmesh.materials.metallic_roughness.sample` (whose agreement
    with its pdf and with ``evaluate`` is tested in test_metallic_roughness.py); its
    weights are at most about 1, so the mean of 400k of them is good to ~0.1 %."""
    rng = np.random.default_rng(11)
    wo = np.tile([math.sqrt(1.0 - cos_theta ** 2), 0.0, cos_theta], (n, 1))
    ns = np.tile([0.0, 0.0, 1.0], (n, 1))
    _, weight, _ = brdf.sample(wo, ns, rng.uniform(size=(n, 3)), np.tile(base, (n, 1)), np.full(n, metallic),
                               brdf.alpha_from_roughness(np.full(n, roughness)))
    return weight.mean(axis=0)


@pytest.mark.parametrize("metallic, roughness, theta", [(1.0, 0.1, 0.0), (1.0, 0.7, 30.0), (1.0, 1.0, 0.0),
                                                        (0.0, 0.3, 0.0), (0.0, 0.7, 60.0)])
def test_white_furnace_reflects_the_directional_albedo_and_never_more(metallic, roughness, theta):
    """A white surface under a uniform white sky returns exactly its directional albedo:
    1 minus what single-scattering GGX loses (metals) or the glTF mix's loss (dielectrics)."""
    material = physical(base=1.0, metallic=metallic, roughness=roughness)
    result = render(furnace_scene(material, theta), width=24, height=24, spp=16, light_samples=2, max_depth=2,
                    sampler="jittered")
    image = result.image.reshape(-1, 3)
    expected = directional_albedo(math.cos(math.radians(theta)), np.ones(3), metallic, roughness)
    assert result.stats.rays["bsdf"] > 0 and result.stats.rays["environment"] > 0
    np.testing.assert_allclose(image.mean(axis=0), expected, rtol=0.01)
    assert expected.max() <= 1.0 + 1e-3
    # every pixel has the same expected value: they scatter about it with the estimator's
    # noise and none stands out (a weight above the light received would show as a firefly)
    spread = image[:, 0].std()
    assert image.max() <= expected.max() + 5.0 * spread and spread < 0.1


@pytest.mark.parametrize("roughness", [0.05, 0.3, 0.7, 1.0])
def test_sampled_metal_weights_never_exceed_one(roughness):
    """``f cos / pdf`` of a white metal's visible-normal samples is ``F G2 / G1 <= 1``: a
    sampled bounce never returns more than it received."""
    n = 20_000
    rng = np.random.default_rng(3)
    wo = rng.normal(size=(n, 3))
    wo[:, 2] = np.abs(wo[:, 2]) + 1e-3
    wo /= np.linalg.norm(wo, axis=1)[:, None]
    ns = np.tile([0.0, 0.0, 1.0], (n, 1))
    _, weight, pdf = brdf.sample(wo, ns, rng.uniform(size=(n, 3)), np.ones((n, 3)), np.ones(n),
                                 brdf.alpha_from_roughness(np.full(n, roughness)))
    assert (pdf > 0).mean() > 0.5 and weight.max() <= 1.0 + 1e-9


def test_studio_default_rig_for_bare_gltf_and_lighting_default(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=2)
    sphere.visual = trimesh.visual.TextureVisuals(
        material=PBRMaterial(name="copper", baseColorFactor=[0.95, 0.64, 0.54, 1.0], metallicFactor=1.0,
                             roughnessFactor=0.3))
    path = tmp_path / "sphere.glb"
    sphere.export(path)
    scene, _ = load_scene(path)
    m = scene.materials.materials[0]
    assert m.model == "metallic_roughness" and m.perceptual_roughness == pytest.approx(0.3)
    assert scene.lights == [] and not scene.ambient.any()
    assert scene.background.lighting is True and scene.background.name == STUDIO_PATH
    # the studio's front (-Z) is turned toward the camera's view
    forward = scene.camera.frame()[0]
    assert scene.background.rotation == pytest.approx(studio_rotation(forward))
    turned = math.radians(scene.background.rotation)
    front = np.array([-math.sin(turned), 0.0, -math.cos(turned)])
    horizontal = np.array([forward[0], 0.0, forward[2]])
    np.testing.assert_allclose(front, horizontal / np.linalg.norm(horizontal), atol=1e-9)


def test_a_background_with_lighting_unset_lights_physical_scenes_only():
    quad = tilted_quad(0.0)
    camera = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 30.0)
    for material, lit in ((physical(metallic=0.0), True), (Material("plain", diffuse=0.5), False)):
        sky = SolidBackground(np.ones(3))
        assert sky.lighting is None
        scene = Scene.from_parts([part("quad", quad)], [material], [], camera, ambient=0.0, background=sky)
        integrator = Integrator(scene, Integrator(scene, _settings()).settings)
        assert (integrator.environment_lighting is not None) is lit


def _settings(**overrides):
    from scenes import settings
    return settings(**overrides)


def test_mis_weights_sum_to_one_and_handle_the_edges():
    bsdf_pdf = np.array([0.5, 2.0, np.inf, 0.0, 3.0, 1e-300])
    env_pdf = np.array([1.0, 0.1, 1.0, 1.0, np.inf, 1e300])
    w = bsdf_weight(bsdf_pdf, env_pdf, 4)
    np.testing.assert_allclose(w[:2], [0.25 / (0.25 + 16.0), 4.0 / (4.0 + 0.16)])
    assert w[2] == 1.0 and w[3] == 0.0 and w[4] == 0.0 and w[5] < 1e-200
    assert np.all((w >= 0.0) & (w <= 1.0))


def test_mis_estimate_matches_bsdf_sampling_alone(monkeypatch):
    """Under a sky with a bright region, the MIS estimate of a rough metal equals the estimate
    of BSDF sampling alone (no environment light sampling, background weight 1).  The Whitted
    stages' MIS (rendering/physical_shading.py, which renders with ambient occlusion take),
    not the path kernel's (tests/rendering/test_path_integrator.py)."""
    from scenes import sun_sky

    from rtmesh.rendering import integrator as integrator_module

    monkeypatch.setattr(integrator_module, "REFERENCE_STAGE", wavefront.attach)

    material = physical(base=[0.9, 0.7, 0.5], metallic=1.0, roughness=0.4)
    sky = sun_sky(64)
    camera = Camera([0.0, 2.0, 3.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 35.0)
    sphere = trimesh.creation.icosphere(subdivisions=3)
    scene = Scene.from_parts([part("ball", sphere, smooth=True)], [material], [], camera, ambient=0.0,
                             background=sky)
    sky.lighting = True
    mis = render(scene, width=20, height=20, spp=64, light_samples=1, max_depth=1).image
    sky.lighting = False
    monkeypatch.setattr(Wavefront, "background_weight", lambda self, pdf, directions: np.ones(len(pdf)))
    alone = render(scene, width=20, height=20, spp=256, light_samples=1, max_depth=1).image
    np.testing.assert_allclose(mis.mean(axis=(0, 1)), alone.mean(axis=(0, 1)), rtol=0.03)


@pytest.mark.parametrize("emitter", ["mesh", "quad"])
def test_emitters_are_counted_once_by_both_strategies(emitter):
    """A rough physical floor under an emissive panel (triangles, or a quad light): the
    panel reflects nothing, so one bounce deeper adds nothing and max_depth 0 (light
    sampling alone) and 1 (light sampling and BSDF rays meeting the panel, MIS-weighted)
    agree; and the MIS weights actually split the light (BSDF rays do meet the panel)."""
    floor = tilted_quad(0.0, half=3.0)
    panel_vertices = np.array([[-0.5, -0.5, 1.0], [0.5, -0.5, 1.0], [0.5, 0.5, 1.0], [-0.5, 0.5, 1.0]])
    camera = Camera([0.0, -2.5, 2.5], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 40.0)
    materials = [physical(base=0.8, metallic=0.3, roughness=0.4)]
    parts = [part("floor", floor)]
    lights = []
    if emitter == "mesh":
        materials.append(Material("panel", diffuse=0.0, emission=4.0))
        parts.append(part("panel", (panel_vertices, np.array([[0, 2, 1], [0, 3, 2]])), material=1))
    else:
        lights.append(QuadLight([0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], 4.0))  # facing -Z
    scene = Scene.from_parts(parts, materials, lights, camera, ambient=0.0)
    direct = render(scene, width=16, height=16, spp=64, light_samples=2, max_depth=0)
    traced = render(scene, width=16, height=16, spp=64, light_samples=2, max_depth=1)
    assert traced.stats.rays["bsdf"] > 0
    np.testing.assert_allclose(traced.image.mean(), direct.image.mean(), rtol=0.02)


def test_point_light_on_a_diffuse_physical_plane_is_lambert_with_one_over_pi():
    """Base colour b, metallic 0, at normal incidence under a point light of intensity I at
    height h: ``(1 - F) b / pi x I / h^2`` plus the specular peak (evaluated by the BRDF)."""
    h, intensity = 2.0, 10.0
    camera = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], projection="orthographic",
                    ortho_height=0.02)
    material = physical(base=[0.5, 0.25, 0.125], metallic=0.0, roughness=1.0)
    scene = Scene.from_parts([part("quad", tilted_quad(0.0))], [material],
                             [PointLight([0.0, 0.0, h], intensity=np.full(3, intensity))], camera, ambient=0.0)
    image = render(scene, width=4, height=4, spp=1, max_depth=0).image
    k = 1
    up = np.tile([0.0, 0.0, 1.0], (k, 1))
    expected = brdf.evaluate(up, up, up, np.array([[0.5, 0.25, 0.125]]), np.zeros(k),
                             brdf.alpha_from_roughness(np.ones(k)))[0] * intensity / h ** 2
    np.testing.assert_allclose(image.reshape(-1, 3).mean(axis=0), expected, rtol=1e-3)
    # the Lambert part dominates a roughness-1 dielectric: about (1 - 0.04) b / pi
    assert np.all(expected / (intensity / h ** 2) > 0.9 * np.array([0.5, 0.25, 0.125]) / math.pi)


def test_a_gltf_primitive_without_material_gets_the_formats_default(tmp_path):
    """glTF 2.0: "If material is undefined, then a default material MUST be used": white,
    metallic 1, roughness 1; other formats keep rtmesh's grey Blinn-Phong default."""
    box = trimesh.creation.box()
    path = tmp_path / "bare.glb"
    box.export(path)
    scene, _ = load_scene(path)
    m = scene.materials.materials[0]
    assert m.model == "metallic_roughness" and m.metallic == 1.0 and m.perceptual_roughness == 1.0
    np.testing.assert_allclose(m.base_color, 1.0)
    box.export(tmp_path / "bare.ply")
    ply, _ = load_scene(tmp_path / "bare.ply")
    assert ply.materials.materials[0].model == "blinn_phong"


def test_mis_tames_the_reflection_of_a_small_light_in_a_smooth_metal(monkeypatch):
    """A smooth metal floor mirroring a small quad light: light sampling alone finds the
    narrow lobe rarely (fireflies), BSDF sampling finds the light every time.  MIS keeps the
    mean of BSDF sampling alone, and its noise (the RMS difference of two seeds) is a
    fraction of light sampling's.  The Whitted stages' strategies, as above."""
    from rtmesh.rendering import integrator as integrator_module
    from wavefront import local_shading, physical_shading, stage

    monkeypatch.setattr(integrator_module, "REFERENCE_STAGE", wavefront.attach)

    floor = tilted_quad(0.0, half=3.0)
    camera = Camera([0.0, -2.0, 1.5], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 50.0)
    light = QuadLight([0.0, 1.5, 1.2], [0.0, 0.3, 0.0], [0.3, 0.0, 0.0], 40.0)
    scene = Scene.from_parts([part("floor", floor)], [physical(base=0.9, metallic=1.0, roughness=0.08)], [light],
                             camera, ambient=0.0)

    def two_seeds(spp):
        a, b = (render(scene, width=24, height=24, spp=spp, light_samples=1, max_depth=1, sampler="jittered",
                       seed=seed).image for seed in (1, 2))
        return 0.5 * (a.mean() + b.mean()), float(np.sqrt(np.mean((a - b) ** 2)))

    mis_mean, mis_noise = two_seeds(64)

    def strategy(weight):
        for module in (stage, local_shading, physical_shading):
            monkeypatch.setattr(module, "bsdf_weight", lambda bsdf_pdf, light_pdf, samples: np.full(len(bsdf_pdf),
                                                                                                   weight))

    strategy(1.0)  # BSDF sampling alone: light samples weigh 0
    bsdf_mean, _ = two_seeds(64)
    strategy(0.0)  # light sampling alone
    _, light_noise = two_seeds(64)
    np.testing.assert_allclose(mis_mean, bsdf_mean, rtol=0.05)
    assert mis_noise < 0.25 * light_noise


def test_a_clear_physical_glass_ball_in_a_white_furnace_is_nearly_invisible():
    """KHR_materials_transmission 1, white, no absorption, under a uniform white sky: what
    the ball does not reflect (GGX lobe) it refracts through (smooth dielectric), so its
    centre returns nearly the light it receives (less GGX's small loss at roughness 0.2,
    and the paths cut at max_depth)."""
    material = physical(base=1.0, metallic=0.0, roughness=0.2, transmission_factor=1.0,
                        transmission=np.ones(3), ior=1.5)
    sky = SolidBackground(np.ones(3))
    sky.lighting = True
    camera = Camera([0.0, 0.0, 6.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], projection="orthographic",
                    ortho_height=0.6)
    ball = trimesh.creation.icosphere(subdivisions=4)
    scene = Scene.from_parts([part("ball", ball, smooth=True)], [material], [], camera, ambient=0.0,
                             background=sky)
    result = render(scene, width=12, height=12, spp=32, light_samples=1, max_depth=8)
    assert result.stats.rays["refraction"] > 0 and result.stats.rays["bsdf"] > 0
    assert abs(float(result.image.mean()) - 1.0) < 0.03
