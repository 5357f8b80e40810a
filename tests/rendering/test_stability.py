"""Numerically hard cases: far from the origin, tiny and huge scales, grazing light,
lights in odd places, index-matched and energy-conserving glass, near-coplanar geometry.

Every render goes through ``scenes.render``, which fails on any NaN, Inf or negative value.
"""

import numpy as np
import pytest
from scenes import floor_quad, icosphere, part, quad, render

from rtmesh.lights.point_lights import DirectionalLight, PointLight
from rtmesh.materials.table import Material
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene


def sphere_on_floor(shift=0.0, scale=1.0):
    """A smooth glossy sphere on a floor, light and camera, all scaled then shifted.

    The light's intensity scales with scale^2, so irradiance (and the image) is the same at
    every scale.
    """
    shift = np.full(3, shift)

    def place(p):
        return np.asarray(p, dtype=np.float64) * scale + shift

    sphere = icosphere(4, 1.0, (0.0, 0.0, 1.0))
    floor_v, floor_f = floor_quad(6.0)
    parts = [part("sphere", (place(sphere.vertices), sphere.faces), 0),
             part("floor", (place(floor_v), floor_f), 1)]
    parts[0].vertex_normals = sphere.vertex_normals
    materials = [Material("s", diffuse=[0.7, 0.4, 0.2], specular=0.5, shininess=40, mirror=0.2),
                 Material("f", diffuse=0.5)]
    lights = [PointLight(place([2.0, -2.0, 5.0]), 30.0 * scale * scale)]
    camera = Camera(place([0.0, -6.0, 3.0]), place([0.0, 0.0, 0.8]), [0.0, 0.0, 1.0], 45.0)
    return Scene.from_parts(parts, materials, lights, camera, ambient=np.full(3, 0.05))


@pytest.mark.parametrize("shift", [1e3, 1e4, 1e5, 1e6])
def test_far_from_origin_matches_origin(shift):
    reference = render(sphere_on_floor(), width=48, height=36).image
    image = render(sphere_on_floor(shift=shift), width=48, height=36).image
    # the renderer re-centres the scene before float32: only float64 rounding of the shift
    # remains, far below anything visible
    np.testing.assert_allclose(image, reference, rtol=0, atol=1e-4)


@pytest.mark.parametrize("scale", [1e-4, 1e-2, 1e2, 1e4])
def test_tiny_and_huge_scales_match_unit_scale(scale):
    reference = render(sphere_on_floor(), width=48, height=36).image
    image = render(sphere_on_floor(scale=scale), width=48, height=36).image
    # mismatches are confined to silhouette pixels whose centre flips by float32 rounding
    differs = np.abs(image - reference).max(axis=2) > 1e-3
    assert differs.mean() < 0.01


def grazing_plane_scene(light, shift=0.0):
    vertices, faces = floor_quad(100.0)
    camera = Camera(np.array([0.0, -100.0, 0.5]) + shift, np.array([0.0, 0.0, 0.0]) + shift,
                    [0.0, 0.0, 1.0], 30.0)
    return Scene.from_parts([part("plane", (vertices + shift, faces))], [Material(diffuse=0.8)],
                            [light], camera)


def test_light_exactly_in_the_plane_gives_black_not_nan():
    result = render(grazing_plane_scene(DirectionalLight([1.0, 0.0, 0.0], 1.0)), width=32, height=32)
    assert result.image.max() == 0.0
    assert result.stats.rays["shadow"] == 0  # no light can reach: no shadow rays


@pytest.mark.parametrize("shift", [0.0, 1e5])
def test_grazing_light_and_view_on_large_plane_show_no_acne(shift):
    # light 1 degree above the horizon: cos(89 deg) * kd on every plane pixel; a single
    # self-shadowed pixel (acne) would break the equality
    direction = [0.0, np.cos(np.radians(1.0)), -np.sin(np.radians(1.0))]
    result = render(grazing_plane_scene(DirectionalLight(direction, 1.0), shift), width=32, height=32)
    lit = result.image[..., 0][result.image[..., 0] > 0]
    expected = 0.8 * np.sin(np.radians(1.0))
    assert lit.size > 0.3 * 32 * 32
    np.testing.assert_allclose(lit, expected, rtol=1e-6)


def test_zero_intensity_light_traces_no_shadow_rays():
    scene = sphere_on_floor()
    scene.lights.append(PointLight([0.0, 0.0, 4.0], 0.0))
    base = render(sphere_on_floor(), width=24, height=18)
    result = render(scene, width=24, height=18)
    assert result.stats.rays["shadow"] == base.stats.rays["shadow"]
    np.testing.assert_array_equal(result.image, base.image)


def test_light_on_the_surface_is_finite():
    scene = sphere_on_floor()
    scene.lights = [PointLight([0.0, 0.0, 0.0], 5.0)]  # on the floor, under the sphere
    render(scene, width=24, height=18)  # the helper asserts finite, non-negative values


def glass_sphere_scene(ior, absorption=0.0, background=(0.2, 0.5, 0.8)):
    sphere = icosphere(4, 1.0)
    glass = Material("glass", diffuse=0.0, specular=0.0, transmission=1.0, ior=ior, absorption=absorption)
    camera = Camera([0.0, -4.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 40.0)
    p = part("glass", sphere)
    p.vertex_normals = sphere.vertex_normals
    return Scene.from_parts([p], [glass], [], camera, background=np.array(background))


def test_index_matched_glass_is_invisible():
    result = render(glass_sphere_scene(ior=1.0), width=32, height=32)
    background = np.array([0.2, 0.5, 0.8], dtype=np.float32)
    np.testing.assert_array_equal(result.image, np.broadcast_to(background, result.image.shape))
    assert result.stats.rays["refraction"] > 0


def test_index_matched_glass_shows_only_its_absorption():
    result = render(glass_sphere_scene(ior=1.0, absorption=0.5), width=33, height=33)
    # the centre ray crosses a diameter (2 units) of the tessellated sphere
    centre = result.image[16, 16]
    np.testing.assert_allclose(centre, np.array([0.2, 0.5, 0.8]) * np.exp(-0.5 * 2.0), rtol=2e-3)


@pytest.mark.parametrize("fresnel", ["schlick", "exact"])
@pytest.mark.parametrize("ior", [1.33, 1.5, 2.4])
def test_glass_never_creates_energy(ior, fresnel):
    # under a uniform background, reflected + transmitted light can never exceed it
    result = render(glass_sphere_scene(ior=ior), width=32, height=32, max_depth=12, fresnel=fresnel, cutoff=0.0)
    assert (result.image <= np.array([0.2, 0.5, 0.8], dtype=np.float32) * (1 + 1e-6)).all()
    # and with enough bounces little is lost: the sphere is not a dark disc
    assert result.image[16, 16, 2] > 0.8 * 0.8


def test_nearly_coplanar_quads_are_deterministic():
    # two quads 1e-5 apart (z-fighting): whichever wins, it wins the same way every time
    low = quad([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    high = quad([[-1, -1, 1e-5], [1, -1, 1e-5], [1, 1, 1e-5], [-1, 1, 1e-5]])
    camera = Camera([0.3, -2.0, 2.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 40.0)
    scene = Scene.from_parts([part("low", low, 0), part("high", high, 1)],
                             [Material(diffuse=[1, 0, 0]), Material(diffuse=[0, 0, 1])],
                             [DirectionalLight([0, 0, -1], 1.0)], camera)
    first = render(scene, width=40, height=40).image
    for threads in (1, 2):
        np.testing.assert_array_equal(render(scene, width=40, height=40, threads=threads).image, first)
    # the top quad is 1e-5 above: every covered pixel is lit by one of them, none is black
    covered = first.max(axis=2) > 0
    assert covered.sum() > 0.3 * first.shape[0] * first.shape[1]
