"""Surface and light models against scalar formulas, and rendered values known exactly."""

import math

import numpy as np
import pytest
from scenes import box, floor_quad, part, pixel_centre_rays, render

from rtmesh.lights.point_lights import DirectionalLight, PointLight, SpotLight
from rtmesh.materials.blinn_phong import blinn_phong
from rtmesh.materials.table import Material, MaterialTable
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene


# ---------------------------------------------------------------- scalar references
def unit(vector):
    length = math.sqrt(sum(x * x for x in vector))
    return [x / length for x in vector]


def dot3(a, b):
    return sum(a[i] * b[i] for i in range(3))


def blinn_phong_reference(normal, to_viewer, to_light, diffuse, specular, shininess):
    """Classic Blinn-Phong for one colour channel and unit incident light."""
    cos_incidence = dot3(normal, to_light)
    if cos_incidence <= 0.0:
        return 0.0  # the light is behind the surface: neither diffuse nor highlight
    halfway = unit([to_viewer[i] + to_light[i] for i in range(3)])
    cos_halfway = max(0.0, dot3(normal, halfway))
    return diffuse * cos_incidence + specular * cos_halfway ** shininess


def smoothstep_reference(edge0, edge1, x):
    t = min(max((x - edge0) / (edge1 - edge0), 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t)


def direction_at(theta_degrees, phi_degrees=0.0):
    """Unit direction at polar angle theta from +z and azimuth phi."""
    theta, phi = math.radians(theta_degrees), math.radians(phi_degrees)
    return [math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)]


# ---------------------------------------------------------------- Blinn-Phong
LIGHT_ANGLES = [0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 89.0, 91.0, 120.0, 180.0]


def test_lambert_term_is_kd_times_cosine_at_set_angles():
    n = np.tile([[0.0, 0.0, 1.0]], (len(LIGHT_ANGLES), 1))
    wi = np.array([direction_at(a) for a in LIGHT_ANGLES])
    wo = np.tile([direction_at(20.0, 180.0)], (len(LIGHT_ANGLES), 1))
    kd = np.tile([[0.2, 0.5, 0.9]], (len(LIGHT_ANGLES), 1))
    value = blinn_phong(n, wo, wi, kd, None, None)
    cosines = np.maximum(np.cos(np.radians(LIGHT_ANGLES)), 0.0)
    np.testing.assert_allclose(value, kd * cosines[:, None], rtol=1e-12, atol=1e-15)
    assert (value[np.array(LIGHT_ANGLES) > 90.0] == 0.0).all()


def test_blinn_phong_matches_scalar_reference_at_many_angles():
    rows = []
    for light_theta in LIGHT_ANGLES:
        for view_theta in (0.0, 10.0, 40.0, 70.0, 85.0):
            for view_phi in (0.0, 90.0, 180.0):
                for shininess in (1.0, 8.0, 64.0):
                    rows.append((direction_at(light_theta, 30.0), direction_at(view_theta, view_phi),
                                 shininess))
    wi = np.array([r[0] for r in rows])
    wo = np.array([r[1] for r in rows])
    shininess = np.array([r[2] for r in rows])
    n = np.tile([[0.0, 0.0, 1.0]], (len(rows), 1))
    kd = np.tile([[0.3, 0.6, 0.1]], (len(rows), 1))
    ks = np.tile([[0.5, 0.2, 0.8]], (len(rows), 1))
    value = blinn_phong(n, wo, wi, kd, ks, shininess)
    for i, (to_light, to_viewer, exponent) in enumerate(rows):
        for channel in range(3):
            expected = blinn_phong_reference([0.0, 0.0, 1.0], to_viewer, to_light,
                                             kd[i, channel], ks[i, channel], exponent)
            assert value[i, channel] == pytest.approx(expected, rel=1e-10, abs=1e-14)


def test_blinn_phong_highlight_peaks_at_the_mirror_direction():
    # viewer exactly at the mirror direction of the light: the halfway vector is the normal
    for theta in (0.0, 20.0, 50.0, 80.0):
        wi = np.array([direction_at(theta, 0.0)])
        wo = np.array([direction_at(theta, 180.0)])
        n = np.array([[0.0, 0.0, 1.0]])
        value = blinn_phong(n, wo, wi, np.zeros((1, 3)), np.full((1, 3), 0.25), np.array([100.0]))
        np.testing.assert_allclose(value, 0.25, rtol=1e-12)
    # halfway vector at angle alpha from n: highlight ks cos^s(alpha)
    alpha, s = 10.0, 32.0
    wi = np.array([direction_at(40.0 + alpha, 0.0)])
    wo = np.array([direction_at(40.0 - alpha, 180.0)])
    value = blinn_phong(np.array([[0.0, 0.0, 1.0]]), wo, wi, np.zeros((1, 3)), np.ones((1, 3)),
                        np.array([s]))
    np.testing.assert_allclose(value, math.cos(math.radians(alpha)) ** s, rtol=1e-12)


def test_blinn_phong_with_opposite_view_and_light_is_finite():
    wi = np.array([direction_at(30.0, 0.0)])
    wo = -wi  # halfway vector of zero length
    value = blinn_phong(np.array([[0.0, 0.0, 1.0]]), wo, wi, np.full((1, 3), 0.5), np.ones((1, 3)),
                        np.array([10.0]))
    assert np.isfinite(value).all()
    np.testing.assert_allclose(value, 0.5 * math.cos(math.radians(30.0)), rtol=1e-12)


def test_material_table_stacks_colours_and_flags_what_is_used():
    table = MaterialTable([Material("a", diffuse=0.5), Material("b", diffuse=[0.1, 0.2, 0.3], mirror=0.9),
                           Material("c", transmission=1.0, absorption=[0.0, 1.0, 0.0])])
    np.testing.assert_array_equal(table.diffuse[1], [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(table.ambient[1], [0.1, 0.2, 0.3])  # defaults to diffuse
    assert table.any_mirror and table.any_transmission and table.any_absorption
    assert not table.any_specular and not table.any_emission
    assert not MaterialTable([Material(absorption=1.0)]).any_absorption  # opaque: no interior


# ---------------------------------------------------------------- lights
def test_point_light_falls_off_with_inverse_square():
    light = PointLight([1.0, 2.0, 3.0], [10.0, 20.0, 40.0])
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(50, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    distances = rng.uniform(0.01, 100.0, 50)
    points = light.position - directions * distances[:, None]
    wi, distance, incident = light.illuminate(points)
    np.testing.assert_allclose(distance, distances, rtol=1e-12)
    np.testing.assert_allclose(wi, directions, atol=1e-12)
    np.testing.assert_allclose(incident, light.intensity / distances[:, None] ** 2, rtol=1e-12)
    # twice as far, a quarter of the light
    _, _, near = light.illuminate(np.array([[1.0, 2.0, 1.0]]))
    _, _, far = light.illuminate(np.array([[1.0, 2.0, -1.0]]))
    np.testing.assert_allclose(far, near / 4.0, rtol=1e-14)


def test_point_light_on_the_shading_point_gives_no_light_and_no_nan():
    light = PointLight([0.0, 0.0, 0.0], 5.0)
    wi, distance, incident = light.illuminate(np.zeros((1, 3)))
    assert np.isfinite(wi).all() and np.isfinite(incident).all()
    np.testing.assert_array_equal(incident, 0.0)
    assert distance[0] == 0.0


def test_directional_light_is_constant_and_infinitely_far():
    light = DirectionalLight([0.0, 0.0, -2.0], [1.0, 0.5, 0.25])
    points = np.random.default_rng(1).normal(size=(10, 3)) * 1000.0
    wi, distance, incident = light.illuminate(points)
    np.testing.assert_allclose(wi, np.tile([0.0, 0.0, 1.0], (10, 1)))
    assert np.isinf(distance).all()
    np.testing.assert_array_equal(incident, np.tile([1.0, 0.5, 0.25], (10, 1)))
    with pytest.raises(ValueError):
        DirectionalLight([0.0, 0.0, 0.0], 1.0)


def test_spot_light_falloff_inside_between_and_outside_the_cone():
    inner, outer = 20.0, 35.0
    light = SpotLight([0.0, 0.0, 0.0], [0.0, 0.0, -3.0], 8.0, inner, outer)
    angles = np.array([0.0, 5.0, 19.9, 20.0, 22.0, 27.5, 33.0, 35.0, 36.0, 90.0, 150.0])
    distance = 2.0
    # points at those angles from the axis (-z), at distance 2
    points = np.column_stack([np.sin(np.radians(angles)), np.zeros_like(angles),
                              -np.cos(np.radians(angles))]) * distance
    wi, d, incident = light.illuminate(points)
    np.testing.assert_allclose(d, distance, rtol=1e-12)
    cos_inner, cos_outer = math.cos(math.radians(inner)), math.cos(math.radians(outer))
    expected = np.array([smoothstep_reference(cos_outer, cos_inner, math.cos(math.radians(a)))
                         for a in angles]) * 8.0 / distance ** 2
    np.testing.assert_allclose(incident[:, 0], expected, rtol=1e-10, atol=1e-15)
    # full intensity inside the inner cone, none outside the outer one
    np.testing.assert_allclose(incident[angles <= inner, 0], 8.0 / distance ** 2, rtol=1e-12)
    np.testing.assert_array_equal(incident[angles > outer, 0], 0.0)
    assert incident[angles == outer, 0] < 1e-20  # on the edge, up to rounding of the cosine
    between = (angles > inner) & (angles < outer)
    assert ((incident[between, 0] > 0.0) & (incident[between, 0] < 2.0)).all()
    assert (np.diff(incident[:, 0]) <= 0.0).all()


def test_spot_light_with_equal_angles_has_a_hard_edge():
    light = SpotLight([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], 1.0, 30.0, 30.0)
    angles = np.radians([0.0, 29.9, 30.1, 60.0])
    points = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(4)])
    _, _, incident = light.illuminate(points)
    np.testing.assert_allclose(incident[:, 0], [1.0, 1.0, 0.0, 0.0], rtol=1e-14, atol=0)


def test_spot_light_rejects_bad_angles():
    with pytest.raises(ValueError):
        SpotLight([0, 0, 0], [0, 0, 1], 1.0, 40.0, 30.0)


# ---------------------------------------------------------------- rendered values
def plane_hits(camera, width, height, height_z=0.0):
    """Per-pixel floor hit points (z = height_z) of pixel-centre rays, and a hit mask."""
    origins, directions = pixel_centre_rays(camera, width, height)
    with np.errstate(divide="ignore"):
        t = (height_z - origins[:, 2]) / directions[:, 2]
    hit = t > 0
    points = origins + np.where(hit, t, 0.0)[:, None] * directions
    return points, directions, hit


def test_rendered_plane_under_directional_light_matches_blinn_phong():
    light = DirectionalLight([1.0, -0.5, -2.0], [1.0, 0.8, 0.6])
    material = Material("floor", diffuse=[0.6, 0.5, 0.4], specular=[0.3, 0.3, 0.3], shininess=12.0)
    camera = Camera([0.5, -3.0, 2.5], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 60.0)
    scene = Scene.from_parts([part("floor", floor_quad(50.0))], [material], [light], camera)
    width, height = 24, 16
    image = render(scene, width=width, height=height).image.reshape(-1, 3)
    points, directions, hit = plane_hits(camera, width, height)
    assert hit.all()
    to_light = -light.direction
    for i in range(len(points)):
        for channel in range(3):
            expected = light.irradiance[channel] * blinn_phong_reference(
                [0.0, 0.0, 1.0], (-directions[i]).tolist(), to_light.tolist(),
                material.diffuse[channel], material.specular[channel], material.shininess)
            assert image[i, channel] == pytest.approx(expected, rel=1e-5)


def test_rendered_plane_under_point_light_follows_inverse_square_and_cosine():
    light_position = np.array([0.3, 0.2, 2.0])
    light = PointLight(light_position, [5.0, 10.0, 20.0])
    camera = Camera([0.0, -0.5, 4.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 70.0)
    scene = Scene.from_parts([part("floor", floor_quad(50.0))], [Material("f", diffuse=0.5)], [light],
                             camera)
    width, height = 20, 20
    image = render(scene, width=width, height=height).image.reshape(-1, 3)
    points, _, hit = plane_hits(camera, width, height)
    to_light = light_position - points
    distance = np.linalg.norm(to_light, axis=1)
    cosine = to_light[:, 2] / distance
    expected = 0.5 * light.intensity[None, :] * (cosine / distance ** 2)[:, None]
    np.testing.assert_allclose(image[hit], expected[hit], rtol=1e-5)


def test_rendered_spot_light_lights_only_its_cone():
    light = SpotLight([0.0, 0.0, 2.0], [0.0, 0.0, -1.0], 4.0, 15.0, 25.0)
    camera = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 60.0)
    scene = Scene.from_parts([part("floor", floor_quad(4.0))], [Material("f", diffuse=1.0)], [light],
                             camera)
    width = height = 32
    image = render(scene, width=width, height=height).image.reshape(-1, 3)
    points, _, _ = plane_hits(camera, width, height)
    to_light = light.position - points
    distance = np.linalg.norm(to_light, axis=1)
    cos_axis = to_light[:, 2] / distance  # angle from the downward axis
    cone = np.array([smoothstep_reference(math.cos(math.radians(25.0)), math.cos(math.radians(15.0)), c)
                     for c in cos_axis])
    expected = 4.0 * cone * cos_axis / distance ** 2
    # hit points carry float32 rounding, which the steep smoothstep amplifies at the rim
    np.testing.assert_allclose(image[:, 0], expected, rtol=1e-5, atol=1e-5)
    angle = np.degrees(np.arccos(cos_axis))
    assert (image[angle > 25.0] == 0.0).all() and (image[angle < 15.0] > 0.0).all()


@pytest.mark.parametrize("fresnel", ["schlick", "exact"])
def test_beer_lambert_attenuation_through_an_absorbing_slab(fresnel):
    # glass of index 1.0 does not bend rays and reflects nothing head-on, so a ray crossing a
    # slab of thickness T at angle theta to its normal keeps exp(-sigma T / cos theta) of the
    # background behind it
    thickness = 0.8
    sigma = np.array([0.0, 0.5, 2.0])
    background = np.array([2.0, 3.0, 4.0])
    slab = box((6.0, 6.0, thickness), (0.0, 0.0, 0.0))
    glass = Material("absorbing glass", diffuse=0.0, transmission=1.0, ior=1.0, absorption=sigma)
    camera = Camera([0.0, 0.0, 10.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 12.0)
    scene = Scene.from_parts([part("slab", slab)], [glass], [], camera, background=background)
    width = height = 16
    result = render(scene, width=width, height=height, max_depth=3, fresnel=fresnel)
    _, directions = pixel_centre_rays(camera, width, height)
    path_length = thickness / np.abs(directions[:, 2])
    expected = background[None, :] * np.exp(-sigma[None, :] * path_length[:, None])
    np.testing.assert_allclose(result.image.reshape(-1, 3), expected, rtol=2e-5)
    assert result.stats.rays["refraction"] == 2 * width * height


def test_absorbing_slab_needs_enough_depth_to_see_through():
    # with max_depth 1 the ray dies inside the slab: nothing of the background comes through
    slab = box((6.0, 6.0, 0.5))
    glass = Material("glass", diffuse=0.0, transmission=1.0, ior=1.0, absorption=0.1)
    camera = Camera([0.0, 0.0, 10.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 12.0)
    scene = Scene.from_parts([part("slab", slab)], [glass], [], camera, background=[1.0, 1.0, 1.0])
    result = render(scene, width=8, height=8, max_depth=1)
    np.testing.assert_array_equal(result.image, 0.0)
