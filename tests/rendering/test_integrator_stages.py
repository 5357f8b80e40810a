"""The integrator runs only the stages a scene needs, and each stage counts what it should.

Ray counts in ``stats.rays`` are compared with exact expectations from scenes where every
ray's fate is known; AO is compared with its closed form next to an infinite wall.
"""

import math

import numpy as np
import pytest
from scenes import box, floor_quad, icosphere, part, pixel_centre_rays, quad, render, settings

from rtmesh.core.vecmath import fresnel_dielectric, fresnel_schlick
from rtmesh.lights.point_lights import DirectionalLight, PointLight
from rtmesh.materials.table import Material
from rtmesh.rendering.integrator import Integrator
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene
import wavefront

TOP_DOWN = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 40.0)


def floor_scene(material, lights=(), ambient=None, background=None, camera=TOP_DOWN):
    """A floor filling the whole view of a camera looking straight down."""
    return Scene.from_parts([part("floor", floor_quad(50.0))], [material], list(lights), camera,
                            ambient=ambient, background=background)


# ---------------------------------------------------------------- what runs
def test_diffuse_scene_traces_no_reflection_refraction_or_ao_rays():
    scene = floor_scene(Material("f", diffuse=0.5), [PointLight([0.0, 0.0, 3.0], 10.0)])
    result = render(scene, width=16, height=12, spp=2, sampler="jittered")
    rays = result.stats.rays
    assert rays["camera"] == 16 * 12 * 2
    # one shadow ray per hit for the one point light, all on the lit side
    assert rays["shadow"] == rays["camera"]
    assert rays["reflection"] == rays["refraction"] == rays["ao"] == 0
    enabled = set(result.stats.stages_enabled)
    assert not enabled & {"reflection", "refraction", "absorption", "ao", "specular", "lens",
                          "smooth_normals", "emission", "ambient", "background", "glossy", "motion"}
    assert "lights" in enabled
    assert result.passes == {}


def test_one_shadow_ray_per_point_light_and_none_for_lights_behind_or_black():
    lights = [PointLight([0.0, 0.0, 3.0], 10.0), PointLight([1.0, 1.0, 4.0], 5.0),
              DirectionalLight([0.0, 0.0, 1.0], 1.0),  # shines on the floor from below
              PointLight([0.0, 0.0, 2.0], 0.0)]  # black
    result = render(floor_scene(Material("f", diffuse=0.5), lights), width=10, height=10)
    assert result.stats.rays["shadow"] == 2 * 100


def test_unshaded_material_traces_no_shadow_rays():
    material = Material("emitter", diffuse=0.0, emission=[1.0, 0.5, 0.25])
    result = render(floor_scene(material, [PointLight([0.0, 0.0, 3.0], 10.0)]), width=8, height=8)
    assert result.stats.rays["shadow"] == 0
    np.testing.assert_array_equal(result.image, np.broadcast_to(np.float32([1.0, 0.5, 0.25]), (8, 8, 3)))


def test_mirror_scene_traces_reflection_but_no_refraction_rays():
    parts = [part("floor", floor_quad(10.0), 0), part("ball", icosphere(2, 1.0, (0, 0, 1)), 1)]
    materials = [Material("f", diffuse=0.5), Material("mirror", diffuse=0.0, mirror=0.9)]
    camera = Camera([0.0, -5.0, 3.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], 40.0)
    scene = Scene.from_parts(parts, materials, [PointLight([2, -2, 5], 20.0)], camera)
    result = render(scene, width=24, height=24)
    assert result.stats.rays["reflection"] > 0
    assert result.stats.rays["refraction"] == 0
    assert "reflection" in result.stats.stages_enabled
    assert "refraction" not in result.stats.stages_enabled
    # max_depth 0: the camera hit is all there is
    flat = render(scene, width=24, height=24, max_depth=0)
    assert flat.stats.rays["reflection"] == 0
    assert "reflection" not in flat.stats.stages_enabled


def test_glass_sphere_traces_refraction_and_fresnel_reflection_rays():
    parts = [part("floor", floor_quad(10.0), 0), part("ball", icosphere(3, 1.0, (0, 0, 1)), 1)]
    materials = [Material("f", diffuse=0.5), Material("glass", diffuse=0.0, transmission=1.0, ior=1.5)]
    camera = Camera([0.0, -5.0, 3.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], 40.0)
    scene = Scene.from_parts(parts, materials, [PointLight([2, -2, 5], 20.0)], camera)
    result = render(scene, width=24, height=24)
    assert result.stats.rays["refraction"] > 0
    assert result.stats.rays["reflection"] > 0
    assert {"reflection", "refraction"} <= set(result.stats.stages_enabled)
    assert "absorption" not in result.stats.stages_enabled


# ---------------------------------------------------------------- depth and cutoff
def mirror_corridor(reflectance):
    """Two huge parallel mirrors at x = -0.5 and x = +0.5, facing each other, camera between."""
    size = 1e3
    left = quad([[-0.5, -size, -size], [-0.5, size, -size], [-0.5, size, size], [-0.5, -size, size]])
    right = quad([[0.5, -size, -size], [0.5, -size, size], [0.5, size, size], [0.5, size, -size]])
    mirror = Material("mirror", diffuse=0.0, mirror=reflectance)
    camera = Camera([0.0, 0.0, 0.0], [1.0, 0.3, 0.1], [0.0, 0.0, 1.0], 30.0)
    return Scene.from_parts([part("left", left), part("right", right)], [mirror], [], camera,
                            background=[1.0, 1.0, 1.0])


@pytest.mark.parametrize("max_depth", [0, 1, 3, 8])
def test_max_depth_bounds_reflections_between_facing_mirrors(max_depth):
    result = render(mirror_corridor(1.0), width=12, height=10, max_depth=max_depth)
    camera_rays = result.stats.rays["camera"]
    # every ray bounces between the mirrors until the depth runs out
    assert result.stats.rays["reflection"] <= max_depth * camera_rays
    assert result.stats.rays["reflection"] == max_depth * camera_rays
    # and never reaches the background: the image is black
    np.testing.assert_array_equal(result.image, 0.0)


def test_paths_stop_when_throughput_falls_below_the_cutoff():
    # throughput 0.5^k after k bounces: with cutoff 0.1 only 3 bounces are worth tracing
    result = render(mirror_corridor(0.5), width=12, height=10, max_depth=8, cutoff=0.1)
    assert result.stats.rays["reflection"] == 3 * result.stats.rays["camera"]


# ---------------------------------------------------------------- total internal reflection
@pytest.mark.parametrize("fresnel", ["exact", "schlick"])
def test_total_internal_reflection_inside_a_glass_cube(fresnel):
    # The camera sits at the centre of a glass cube (ior 1.5) looking at its +x face with a
    # 90 degree field of view, so it sees exactly that face from inside.  Rays meeting it
    # beyond the critical angle asin(1/1.5) are totally reflected and, at max_depth 1, end
    # black; the others leave with weight 1 - F and see the background.
    glass = Material("glass", diffuse=0.0, transmission=1.0, ior=1.5)
    camera = Camera([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], 90.0)
    background = np.array([1.0, 2.0, 4.0])
    scene = Scene.from_parts([part("cube", box((2.0, 2.0, 2.0)))], [glass], [], camera,
                             background=background)
    width = height = 32
    result = render(scene, width=width, height=height, max_depth=1, cutoff=0.0, fresnel=fresnel)
    _, directions = pixel_centre_rays(camera, width, height)
    cos_i = directions[:, 0]  # angle to the +x face's normal
    critical_cos = math.cos(math.asin(1.0 / 1.5))
    escapes = cos_i > critical_cos
    assert 0 < escapes.sum() < width * height  # both cases are in view
    assert result.stats.rays["refraction"] == escapes.sum()
    assert result.stats.rays["reflection"] == width * height  # Fresnel or total reflection
    fresnel_function = fresnel_dielectric if fresnel == "exact" else fresnel_schlick
    expected = np.where(escapes[:, None], (1.0 - fresnel_function(cos_i, 1.5))[:, None] * background, 0.0)
    np.testing.assert_allclose(result.image.reshape(-1, 3), expected, rtol=1e-5, atol=1e-6)


# ---------------------------------------------------------------- ambient occlusion
def test_ao_rays_run_only_when_something_uses_them():
    light = PointLight([0.0, 0.0, 3.0], 10.0)
    no_ambient = render(floor_scene(Material("f"), [light]), width=8, height=8, ao_samples=8)
    assert no_ambient.stats.rays["ao"] == 0
    assert "ao" not in no_ambient.stats.stages_enabled
    with_ambient = render(floor_scene(Material("f"), [light], ambient=[0.2] * 3), width=8, height=8,
                          ao_samples=8)
    # every camera ray hits the floor and sends ao_samples rays
    assert with_ambient.stats.rays["ao"] == 8 * 64
    as_pass = render(floor_scene(Material("f"), [light]), width=8, height=8, passes=("ao",))
    assert as_pass.stats.rays["ao"] == 16 * 64  # the pass alone asks for 16 rays per hit


def test_ao_of_an_open_plane_is_one():
    scene = floor_scene(Material("f", diffuse=0.5), ambient=[0.3, 0.3, 0.3])
    result = render(scene, width=16, height=16, ao_samples=16, passes=("ao",), ao_distance=100.0)
    np.testing.assert_array_equal(result.passes["ao"], 1.0)
    # ambient light alone, unoccluded: ka * ambient everywhere
    np.testing.assert_allclose(result.image, 0.5 * 0.3, rtol=1e-6)


def unoccluded_fraction_beside_wall(distance_to_wall, ao_distance):
    """Cosine-weighted fraction of the hemisphere not blocked by an infinite wall.

    With cosine-weighted sampling the horizontal part of the direction is uniform on the unit
    disk.  Rays toward the wall (dx < 0) reach it after distance_to_wall / |dx|, so they
    count as occluded when |dx| > c = distance_to_wall / ao_distance: a circular segment
    of area acos(c) - c sqrt(1 - c^2) out of pi.  At the foot of the wall (c -> 0): 1/2.
    """
    c = np.minimum(distance_to_wall / ao_distance, 1.0)
    return 1.0 - (np.arccos(c) - c * np.sqrt(1.0 - c * c)) / np.pi


def test_ao_beside_a_wall_matches_the_closed_form():
    ao_distance = 1.0
    big = 6.0 * ao_distance  # far larger than any AO ray: the wall is effectively infinite
    floor = quad([[0.0, -big, 0.0], [big, -big, 0.0], [big, big, 0.0], [0.0, big, 0.0]])
    wall = quad([[0.0, -big, 0.0], [0.0, big, 0.0], [0.0, big, big], [0.0, -big, big]])
    camera = Camera([0.7, 0.0, 4.0], [0.7, 0.0, 0.0], [0.0, 1.0, 0.0], 25.0)
    scene = Scene.from_parts([part("floor", floor), part("wall", wall)], [Material("f")], [], camera)
    width = height = 64
    result = render(scene, width=width, height=height, ao_samples=64, passes=("ao",),
                    ao_distance=ao_distance)
    ao = result.passes["ao"].reshape(-1)
    origins, directions = pixel_centre_rays(camera, width, height)
    t = -origins[:, 2] / directions[:, 2]
    x = origins[:, 0] + t * directions[:, 0]  # distance of each floor point from the wall
    on_floor = x > 1e-3
    expected = unoccluded_fraction_beside_wall(x, ao_distance)
    # per-pixel noise of 64 samples is at most 0.5 / 8; compare averages over bands of x
    bands = np.digitize(x, np.linspace(0.0, 1.2, 13))
    for band in np.unique(bands[on_floor]):
        members = on_floor & (bands == band)
        if members.sum() < 50:
            continue
        error = ao[members].mean() - expected[members].mean()
        sigma = 0.5 / math.sqrt(64 * members.sum())
        assert abs(error) < 5.0 * sigma + 1e-3, f"band {band}: {error:+.4f}"
    # right at the foot of the wall half the cosine-weighted hemisphere is blocked
    foot = on_floor & (x < 0.05)
    assert foot.sum() >= 64
    assert ao[foot].mean() == pytest.approx(0.5, abs=0.04)
    # and beyond ao_distance nothing is blocked
    np.testing.assert_array_equal(ao[x > ao_distance + 0.01], 1.0)


@pytest.mark.parametrize("kernel", [False, True], ids=["wavefront", "kernel"])
def test_ao_darkens_ambient_light_in_the_image(kernel, monkeypatch):
    from rtmesh.rendering import integrator as integrator_module

    monkeypatch.setattr(integrator_module, "REFERENCE_STAGE", None if kernel else wavefront.attach)
    ao_distance = 1.0
    big = 6.0
    floor = quad([[0.0, -big, 0.0], [big, -big, 0.0], [big, big, 0.0], [0.0, big, 0.0]])
    wall = quad([[0.0, -big, 0.0], [0.0, big, 0.0], [0.0, big, big], [0.0, -big, big]])
    camera = Camera([0.7, 0.0, 4.0], [0.7, 0.0, 0.0], [0.0, 1.0, 0.0], 25.0)
    scene = Scene.from_parts([part("floor", floor), part("wall", wall)], [Material("f", diffuse=0.5)],
                             [], camera, ambient=[1.0, 1.0, 1.0])
    result = render(scene, width=24, height=24, ao_samples=8, passes=("ao",), ao_distance=ao_distance)
    assert result.passes["ao"].min() < 0.8
    if not kernel:
        # the image is ka * ambient * ao, with ao the same estimate as the pass (depth 0)
        np.testing.assert_allclose(result.image[..., 0], 0.5 * result.passes["ao"][..., 0], rtol=1e-6)
    else:
        # the kernel's occlusion rays are its own, independent of the pass's: the image is
        # ka * ambient * ao in the mean (4608 rays: ~0.8 % of noise), darker by the wall
        assert result.image[..., 0].mean() == pytest.approx(0.5 * result.passes["ao"][..., 0].mean(), rel=0.03)
        near, far = result.image[:, :4, 0].mean(), result.image[:, -4:, 0].mean()
        assert near < 0.9 * far


# ---------------------------------------------------------------- settings
def test_invalid_settings_are_rejected_before_rendering():
    scene = floor_scene(Material("f"))
    for bad in (dict(spp=0), dict(sampler="halton"), dict(max_depth=-1), dict(threads=0),
                dict(fresnel="fast"), dict(passes=("normals",)), dict(ao_distance=0.0)):
        with pytest.raises(ValueError):
            Integrator(scene, settings(**bad))


@pytest.mark.slow
def test_ao_beside_a_wall_matches_the_closed_form_pixel_by_pixel():
    # statistical: 1024 AO rays per pixel bring each pixel within ~0.016 (1 sigma) of the
    # closed form, so every pixel can be checked on its own at 5 sigma
    ao_distance, big = 1.0, 6.0
    floor = quad([[0.0, -big, 0.0], [big, -big, 0.0], [big, big, 0.0], [0.0, big, 0.0]])
    wall = quad([[0.0, -big, 0.0], [0.0, big, 0.0], [0.0, big, big], [0.0, -big, big]])
    camera = Camera([0.7, 0.0, 4.0], [0.7, 0.0, 0.0], [0.0, 1.0, 0.0], 25.0)
    scene = Scene.from_parts([part("floor", floor), part("wall", wall)], [Material("f")], [], camera)
    width = height = 64
    result = render(scene, width=width, height=height, ao_samples=1024, passes=("ao",),
                    ao_distance=ao_distance, threads=2)
    ao = result.passes["ao"].reshape(-1)
    origins, directions = pixel_centre_rays(camera, width, height)
    t = -origins[:, 2] / directions[:, 2]
    x = origins[:, 0] + t * directions[:, 0]
    on_floor = x > 1e-3
    expected = unoccluded_fraction_beside_wall(x, ao_distance)
    sigma = np.sqrt(expected * (1.0 - expected) / 1024) + 1e-6
    assert (np.abs(ao[on_floor] - expected[on_floor]) < 5.0 * sigma[on_floor] + 1e-3).all()
