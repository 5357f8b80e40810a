"""Nested dielectrics: the per-ray medium stack (rtmesh.rendering.media) against closed forms.

Glass in water, a camera inside glass (and inside glass inside water), interfaces between
media of equal index, coincident glass/water surfaces, total internal reflection inside a
sphere.  Every render goes through ``scenes.render``, which fails on NaN, Inf or negative
values.
"""

import math
import warnings

import numpy as np
import pytest
from scenes import box, icosphere, part, pixel_centre_rays, quad, ray_sphere_distances, render, settings

from rtmesh.core.vecmath import fresnel_schlick, refract
from rtmesh.geometry.motion import Motion
from rtmesh.materials.table import Material, MaterialTable
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.media import Media, coincident_faces
from rtmesh.scene.background import GradientBackground
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene

GLASS, WATER = 1.5, 1.33


def glass(absorption=0.0, ior=GLASS, name="glass"):
    return Material(name, diffuse=0.0, transmission=1.0, ior=ior, absorption=absorption)


def water(absorption=0.0, ior=WATER):
    return Material("water", diffuse=0.0, transmission=1.0, ior=ior, absorption=absorption)


def normal_incidence_transmittance(eta):
    """1 - F at normal incidence (Schlick is exact there: F = r0)."""
    return 1.0 - ((1.0 - eta) / (1.0 + eta)) ** 2


# ---------------------------------------------------------------- the stack itself
def toy_media():
    """Media over four separate triangles of materials opaque, glass, water, glass2."""
    table = MaterialTable([Material("opaque"), glass(), water(), glass(name="glass2")])
    vertices = np.arange(36, dtype=np.float64).reshape(12, 3) ** 1.5  # no shared positions
    faces = np.arange(12).reshape(4, 3)
    normals = np.tile([0.0, 0.0, 1.0], (4, 1))
    return Media(table, np.arange(4), vertices, faces, normals)


def cross(media, stack, face, entering):
    eta, after = media.cross(np.array([stack], dtype=np.int32), np.array([face]),
                             np.array([entering]))
    return eta[0], [int(m) for m in after[0] if m >= 0]


def test_entering_pushes_and_leaving_pops_with_the_ior_ratio_of_both_sides():
    media = toy_media()
    # air -> water -> glass, and back out
    assert cross(media, [-1, -1, -1, -1], 2, True) == (pytest.approx(1.0 / WATER, rel=1e-15), [2])
    assert cross(media, [2, -1, -1, -1], 1, True) == (pytest.approx(WATER / GLASS, rel=1e-15),
                                                       [1, 2])
    assert cross(media, [1, 2, -1, -1], 1, False) == (pytest.approx(GLASS / WATER, rel=1e-15), [2])
    assert cross(media, [2, -1, -1, -1], 2, False) == (pytest.approx(WATER, rel=1e-15), [])


def test_equal_media_on_both_sides_give_eta_exactly_one():
    media = toy_media()
    # glass2 has the ior of glass: that interface does not exist optically
    assert cross(media, [1, 2, -1, -1], 3, True) == (1.0, [3, 1, 2])
    # glass inside glass of the same material
    assert cross(media, [1, -1, -1, -1], 1, True) == (1.0, [1, 1])


def test_leaving_a_medium_under_the_top_changes_nothing_and_unknown_media_are_left_to_the_top():
    media = toy_media()
    # overlap: water was entered after glass, so the ray is in water; leaving the glass
    # there keeps it in water
    assert cross(media, [2, 1, -1, -1], 1, False) == (1.0, [2])
    # leaving glass that was never entered (a crack, an overflow): it was inside all along
    assert cross(media, [2, -1, -1, -1], 1, False) == (pytest.approx(GLASS / WATER, rel=1e-15), [2])
    assert cross(media, [-1, -1, -1, -1], 1, False) == (GLASS, [])


def test_a_full_stack_drops_its_outermost_medium():
    media = toy_media()
    eta, after = cross(media, [1, 2, 1, 2], 3, True)
    assert after == [3, 1, 2, 1]
    assert eta == 1.0


def test_refraction_from_water_into_glass_follows_snell_at_known_angles():
    media = toy_media()
    angles = np.radians([0.0, 10.0, 30.0, 50.0, 70.0, 85.0])
    k = len(angles)
    in_water = np.tile(np.int32([2, -1, -1, -1]), (k, 1))
    eta, _ = media.cross(in_water, np.full(k, 1), np.ones(k, bool))
    normal = np.tile([0.0, 0.0, 1.0], (k, 1))
    wo = np.stack([np.sin(angles), np.zeros(k), np.cos(angles)], axis=1)
    wt, tir = refract(wo, normal, eta)
    assert not tir.any()
    for i, angle in enumerate(angles):
        # scalar reference: n_water sin(i) = n_glass sin(t), continuing away from wo
        sin_t = WATER * math.sin(angle) / GLASS
        expected = [-sin_t, 0.0, -math.sqrt(1.0 - sin_t * sin_t)]
        np.testing.assert_allclose(wt[i], expected, atol=1e-14)


# ---------------------------------------------------------------- glass in water, rendered
# radiance 1 straight ahead (+y), 0 straight back: light reflected back toward the camera
# from the first surfaces sees nothing, so the head-on transmittance can be read alone
AHEAD = GradientBackground([1.0, 1.0, 1.0], [0.0, 0.0, 0.0])


def glass_in_water_scene(absorption_glass, absorption_water, coincident=False, camera=None,
                         background=AHEAD):
    """A glass ball of radius 1 centred in a water ball of radius 2 (smooth icospheres).

    ``coincident``: the water is a shell whose inner surface is the glass ball's own
    triangles turned inside out, touching the glass everywhere.
    """
    inner, outer = icosphere(4, 1.0), icosphere(4, 2.0)
    parts = [part("glass", inner, 0, smooth=True), part("water", outer, 1, smooth=True)]
    if coincident:
        shell = part("water-inside", (inner.vertices.copy(), inner.faces[:, ::-1].copy()), 1)
        shell.vertex_normals = -inner.vertex_normals
        # listed first or last: Embree reports one of two coincident faces, which one
        # depends on the build; both must give the same result
        parts.insert(0 if coincident == "shell-first" else len(parts), shell)
    camera = camera or Camera([0.0, -6.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 30.0)
    return Scene.from_parts(parts, [glass(absorption_glass), water(absorption_water)], [], camera,
                            background=background)


@pytest.mark.parametrize("coincident", [False, "shell-first", "shell-last"])
def test_ray_through_glass_in_water_matches_the_closed_form(coincident):
    sigma_glass, sigma_water = np.array([0.3, 0.0, 0.0]), np.array([0.0, 0.0, 0.2])
    scene = glass_in_water_scene(sigma_glass, sigma_water, coincident)
    # air -> water -> glass -> water -> air: four refractions, so at max depth 4 a path with
    # a reflection reaches only the black half of the sky (behind the camera); the centre
    # ray meets every surface head on
    result = render(scene, width=33, height=33, max_depth=4, cutoff=0.0)
    transmittance = (normal_incidence_transmittance(1.0 / WATER) ** 2
                     * normal_incidence_transmittance(WATER / GLASS) ** 2)
    # the centre ray crosses 2 units of glass and 2 of water
    expected = transmittance * np.exp(-2.0 * sigma_glass - 2.0 * sigma_water)
    np.testing.assert_allclose(result.image[16, 16], expected, rtol=2e-3)
    # the stack-free rule (leaving glass returns to air) would see no water behind the glass
    stack_free = transmittance * np.exp(-2.0 * sigma_glass - 1.0 * sigma_water)
    assert abs(result.image[16, 16, 2] - stack_free[2]) > 0.1


@pytest.mark.parametrize("coincident", [False, "shell-first", "shell-last"])
def test_path_through_glass_in_water_matches_the_closed_form(coincident):
    # the path integrator's media stack and touching faces (path_media.cross_interface):
    # a narrow view (every pixel head on), Fresnel sampled per path, so the image mean
    # converges to the transmittance (paths with two extra reflections add about 4e-4)
    sigma_glass, sigma_water = np.array([0.3, 0.0, 0.0]), np.array([0.0, 0.0, 0.2])
    camera = Camera([0.0, -6.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 1.0)
    scene = glass_in_water_scene(sigma_glass, sigma_water, coincident, camera=camera)
    result = render(scene, width=8, height=8, spp=64, integrator="path")
    transmittance = (normal_incidence_transmittance(1.0 / WATER) ** 2
                     * normal_incidence_transmittance(WATER / GLASS) ** 2)
    expected = transmittance * np.exp(-2.0 * sigma_glass - 2.0 * sigma_water)
    mean = result.image.reshape(-1, 3).mean(axis=0)
    # 4096 paths: a relative standard error of about 0.4 % (Russian roulette decides on the
    # throughput without the crossings' radiance scaling 1 / eta^2; with it, 1.4 %)
    np.testing.assert_allclose(mean, expected, rtol=0.02)
    # without the touching faces, a path entering the glass through the water's inner face
    # would stay in water (no glass absorption); stack-free, it would leave the water early
    stack_free = transmittance * np.exp(-2.0 * sigma_glass - 1.0 * sigma_water)
    assert abs(mean[2] - stack_free[2]) > 0.1


def test_roulette_inside_glass_adds_no_noise():
    # Russian roulette decides on the throughput without the radiance scaling of the
    # crossings (pbrt-v4's etaScale): inside water and glass the scaled throughput is 1/1.33^2
    # and 1/1.5^2 of the light the path carries, so paths ended there only added noise.
    # Pixel standard deviation over seeds, relative to the mean: measured 0.044-0.050 with,
    # 0.20-0.21 without
    camera = Camera([0.0, -6.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 20.0)
    scene = glass_in_water_scene(np.array([0.3, 0.0, 0.0]), np.array([0.0, 0.0, 0.2]), camera=camera)
    images = np.array([render(scene, width=16, height=16, spp=16, integrator="path", seed=seed).image
                       for seed in range(4)])
    assert images.std(axis=0, ddof=1).mean() / images.mean() < 0.1


def test_coincident_faces_pair_up_exactly():
    inner = icosphere(2, 1.0)
    vertices = np.concatenate([inner.vertices, inner.vertices])
    faces = np.concatenate([inner.faces, inner.faces[:, ::-1] + len(inner.vertices)])
    n = len(inner.faces)
    twin = coincident_faces(vertices, faces, np.ones(2 * n, bool))
    np.testing.assert_array_equal(twin, np.concatenate([np.arange(n) + n, np.arange(n)]))
    # only candidates pair up
    assert (coincident_faces(vertices, faces, np.arange(2 * n) < n) == -1).all()


def test_interface_between_media_of_equal_index_is_invisible():
    sky = GradientBackground([0.2, 0.4, 1.0], [0.9, 0.6, 0.3])
    camera = Camera([0.0, -6.0, 0.5], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 40.0)
    nested = glass_in_water_scene(0.0, 0.0, camera=camera)
    nested.materials = MaterialTable([glass(ior=WATER), water()])
    nested.background = sky
    alone = Scene.from_parts([part("water", icosphere(4, 2.0), 0, smooth=True)], [water()], [],
                             camera, background=sky)
    # the inner ball's surfaces still count toward max_depth: enough depth for both
    a = render(nested, width=32, height=32, max_depth=16)
    b = render(alone, width=32, height=32, max_depth=16)
    # the inner ball is crossed
    assert a.stats.rays["refraction"] > b.stats.rays["refraction"] + 200
    # only the origin offsets at the extra interfaces differ
    np.testing.assert_allclose(a.image, b.image, rtol=0, atol=1e-5)


@pytest.mark.parametrize("fresnel", ["schlick", "exact"])
def test_glass_in_water_never_creates_energy(fresnel):
    background = np.array([0.2, 0.5, 0.8])
    scene = glass_in_water_scene(0.0, 0.0, background=np.array(background))
    result = render(scene, width=24, height=24, max_depth=10, cutoff=0.0, fresnel=fresnel)
    assert (result.image <= background.astype(np.float32) * (1 + 1e-6)).all()
    # and with ten bounces little is lost in the middle of the ball
    assert result.image[12, 12, 2] > 0.9 * 0.8


# ---------------------------------------------------------------- camera inside a medium
@pytest.mark.parametrize("coincident", [False, "shell-first", "shell-last"])
def test_camera_inside_glass_inside_water_finds_both_media(coincident):
    sigma_glass, sigma_water = np.array([0.5, 0.0, 0.0]), np.array([0.0, 0.0, 0.5])
    camera = Camera([0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], 40.0)
    scene = glass_in_water_scene(sigma_glass, sigma_water, coincident, camera=camera)
    # glass inside water; a water shell touching the glass does not reach the camera (its
    # inner surface faces the glass): the water begins at the glass surface
    expected_stack = [0, -1, -1, -1] if coincident else [0, 1, -1, -1]
    assert list(Integrator(scene, settings())._camera_medium) == expected_stack
    # glass -> water -> air head on: two refractions, one unit of each medium
    result = render(scene, width=9, height=9, max_depth=2, cutoff=0.0)
    expected = (normal_incidence_transmittance(GLASS / WATER)
                * normal_incidence_transmittance(WATER) * np.exp(-sigma_glass - sigma_water))
    np.testing.assert_allclose(result.image[4, 4], expected, rtol=2e-3)


def test_camera_outside_every_medium_has_an_empty_stack():
    scene = glass_in_water_scene(0.0, 0.0)
    assert (Integrator(scene, settings())._camera_medium == -1).all()
    # between the glass and the water surface: water only
    scene.camera = Camera([0.0, 1.5, 0.2], [0.0, 0.0, 0.2], [0.0, 0.0, 1.0], 40.0)
    assert list(Integrator(scene, settings())._camera_medium) == [1, -1, -1, -1]


def test_camera_inside_absorbing_glass_sees_the_world_refracted_and_absorbed():
    # Off-centre camera in a smooth glass ball; one bounce: every pixel is
    # (1 - F) * exp(-sigma * t) * sky(refracted direction), computed on the exact sphere.
    sigma = np.array([0.4, 0.2, 0.1])
    sky = GradientBackground([0.1, 0.3, 1.0], [1.0, 0.5, 0.1])
    position = np.array([0.85, -0.1, 0.1])
    camera = Camera(position, position + [-1.2, 0.2, 1.0], [0.0, 1.0, 0.0], 70.0)
    ball = part("glass", icosphere(5, 1.0), 0, smooth=True)
    scene = Scene.from_parts([ball], [glass(sigma)], [], camera, background=sky)
    width = height = 32
    result = render(scene, width=width, height=height, max_depth=1, cutoff=0.0)
    origins, directions = pixel_centre_rays(camera, width, height)
    t = ray_sphere_distances(origins, directions, np.zeros(3), 1.0)
    normal = origins + t[:, None] * directions  # outward unit normal of the exact sphere
    wt, tir = refract(-directions, -normal, GLASS)
    cos_i = np.einsum("ij,ij->i", directions, normal)
    expected = ((1.0 - fresnel_schlick(cos_i, GLASS))[:, None] * np.exp(-sigma * t[:, None])
                * sky.radiance(wt))
    # away from the critical angle, where the tessellation can tip a ray either way
    clear = np.abs(GLASS * np.sqrt(1.0 - cos_i ** 2) - 1.0) > 0.1
    assert clear.sum() > 0.75 * width * height
    assert (tir & clear).sum() > 300 and (~tir & clear).sum() > 300
    image = result.image.reshape(-1, 3)
    np.testing.assert_allclose(image[clear], expected[clear], rtol=0.01, atol=2e-3)
    np.testing.assert_array_equal(image[tir & clear], 0.0)


def test_trapped_rays_inside_a_glass_ball_keep_all_their_energy():
    # From inside a ball every hit of a ray's path meets the surface at the same angle
    # (sin i = impact parameter / radius).  Beyond the critical angle the total internal
    # reflection keeps weight exactly 1, so with an ambient term a at each hit a trapped
    # ray gathers exactly (max_depth + 1) * a; an escaping one sum_k F^k * a.
    max_depth, ambient = 6, 0.1
    position = np.array([0.0, -0.85, 0.0])
    camera = Camera(position, position + [1.0, 0.7, 0.0], [0.0, 0.0, 1.0], 100.0)
    material = Material("glass", diffuse=0.0, ambient=1.0, transmission=1.0, ior=GLASS)
    ball = part("glass", icosphere(5, 1.0), 0, smooth=True)
    scene = Scene.from_parts([ball], [material], [], camera, ambient=np.full(3, ambient))
    width = height = 32
    result = render(scene, width=width, height=height, max_depth=max_depth, cutoff=0.0)
    _, directions = pixel_centre_rays(camera, width, height)
    impact = np.linalg.norm(np.cross(position, directions), axis=1)  # sin i on a unit ball
    image = result.image[..., 0].reshape(-1)
    trapped = impact > 1.0 / GLASS + 0.05
    escaping = impact < 1.0 / GLASS - 0.05
    assert trapped.sum() > 100 and escaping.sum() > 100
    np.testing.assert_allclose(image[trapped], (max_depth + 1) * ambient, rtol=1e-6)
    f = fresnel_schlick(np.sqrt(1.0 - impact[escaping] ** 2), GLASS)
    expected = ambient * (1.0 - f ** (max_depth + 1)) / (1.0 - f)
    np.testing.assert_allclose(image[escaping], expected, rtol=0.01)
    assert (image <= (max_depth + 1) * ambient * (1 + 1e-6)).all()  # never more than all of it


# ---------------------------------------------------------------- parallel slabs
def test_slabs_of_glass_in_water_shift_the_floor_by_snells_law():
    # A glass slab (z 0.5..1.5) inside a water slab (z 0..2) over a floor at z = -0.5 whose
    # halves x < 0 and x > 0 glow red and blue.  Through parallel interfaces a ray keeps its
    # horizontal direction and, in a medium of index n, sin(theta_n) = sin(theta_air) / n:
    # where it lands on the floor is a closed form.
    floor_left = part("left", quad([[-9, -9, -0.5], [0, -9, -0.5], [0, 9, -0.5], [-9, 9, -0.5]]), 2)
    floor_right = part("right", quad([[0, -9, -0.5], [9, -9, -0.5], [9, 9, -0.5], [0, 9, -0.5]]), 3)
    slabs = [part("water", box((8.0, 8.0, 2.0), (0.0, 0.0, 1.0)), 1),
             part("glass", box((6.0, 6.0, 1.0), (0.0, 0.0, 1.0)), 0)]
    materials = [glass(), water(), Material("red", diffuse=0.0, ambient=[1, 0, 0]),
                 Material("blue", diffuse=0.0, ambient=[0, 0, 1])]
    camera = Camera([-3.0, 0.2, 4.0], [0.4, 0.0, 0.0], [0.0, 0.0, 1.0], 25.0)
    scene = Scene.from_parts(slabs + [floor_left, floor_right], materials, [], camera,
                             ambient=np.ones(3))
    width, height = 48, 32
    result = render(scene, width=width, height=height, max_depth=5, cutoff=0.0)
    origins, directions = pixel_centre_rays(camera, width, height)

    def landing_x(layers):
        """x on the floor after (thickness, index) layers below z = 2 (from the top)."""
        t = (2.0 - origins[:, 2]) / directions[:, 2]
        x = origins[:, 0] + t * directions[:, 0]
        sin_air = np.hypot(directions[:, 0], directions[:, 1])
        along_x = directions[:, 0] / sin_air
        for thickness, index in layers:
            sin_n = sin_air / index
            x = x + thickness * sin_n / np.sqrt(1.0 - sin_n ** 2) * along_x
        return x

    x = landing_x([(0.5, WATER), (1.0, GLASS), (0.5, WATER), (0.5, 1.0)])
    # every ray enters through the top and stays within the slabs' footprints
    top_x = origins[:, 0] + (2.0 - origins[:, 2]) / directions[:, 2] * directions[:, 0]
    assert (np.abs(top_x) < 2.5).all() and (np.abs(x) < 2.5).all()
    image = result.image.reshape(-1, 3)
    red, blue = image[:, 0] > image[:, 2], image[:, 2] > image[:, 0]
    clear = np.abs(x) > 0.03
    assert (x[clear] < 0).sum() > 100 and (x[clear] > 0).sum() > 100
    np.testing.assert_array_equal(red[clear], x[clear] < 0)
    np.testing.assert_array_equal(blue[clear], x[clear] > 0)
    # the test can tell: with the water under the glass taken for air, many pixels flip
    stack_free = landing_x([(0.5, WATER), (1.0, GLASS), (0.5, 1.0), (0.5, 1.0)])
    assert ((stack_free < 0) != (x < 0)).sum() > 50


def test_camera_inside_a_moving_glass_ball_is_found_where_the_shutter_opens():
    # the ball rests at the origin, but moves 3 units along x and turns half a turn per unit
    # time: when the shutter opens at t = 1 it is centred at x = 3, around the camera, and
    # its faces point the other way round from their rest pose
    ball = part("glass", icosphere(3, 1.0), 0)
    ball.motion = Motion([3.0, 0.0, 0.0], [0.0, 0.0, 1.0], 180.0, centre=[0.0, 0.0, 0.0])
    camera = Camera([3.0, 0.1, 0.2], [3.0, 1.0, 0.2], [0.0, 0.0, 1.0], 40.0, shutter=(1.0, 1.2))
    scene = Scene.from_parts([ball], [glass(0.5)], [], camera, background=np.ones(3))
    assert list(Integrator(scene, settings())._camera_medium) == [0, -1, -1, -1]
    scene.camera = Camera([0.0, 0.1, 0.2], [0.0, 1.0, 0.2], [0.0, 0.0, 1.0], 40.0, shutter=(1.0, 1.2))
    assert (Integrator(scene, settings())._camera_medium == -1).all()


def test_camera_inside_clear_glass_with_an_absorbing_ball_in_view():
    # Regression: camera rays start in the clear glass box, so their throughput is the
    # shared read-only unit row; the absorption step must leave the rows of media that do
    # not absorb alone (it raised "assignment destination is read-only").  Head on, the
    # centre ray leaves the box and crosses 2 units of the absorbing ball: three refractions.
    sigma = np.array([0.3, 0.1, 0.0])
    camera = Camera([0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], 40.0)
    parts = [part("clear", box((2.0, 2.0, 2.0)), 0),
             part("ball", icosphere(4, 1.0, (0.0, 4.0, 0.0)), 1, smooth=True)]
    scene = Scene.from_parts(parts, [glass(name="clear"), glass(sigma, name="tinted")], [], camera,
                             background=AHEAD)
    integrator = Integrator(scene, settings())
    assert list(integrator._camera_medium) == [0, -1, -1, -1] and not integrator._camera_absorbs
    # max depth 3: a path with a reflection cannot turn ahead again, so it sees the black sky
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = render(scene, width=33, height=33, max_depth=3, cutoff=0.0)
    assert result.image.max() > 0.5
    expected = normal_incidence_transmittance(GLASS) ** 3 * np.exp(-2.0 * sigma)
    np.testing.assert_allclose(result.image[16, 16], expected, rtol=2e-3)
