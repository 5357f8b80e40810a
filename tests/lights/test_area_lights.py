"""Area lights and soft shadows against closed forms.

The shading model's diffuse value under a light is ``kd * E`` with ``E`` the physical
irradiance (for a point light ``E = I cos / d^2``, no 1/pi; see rtmesh.materials.table).  An area
light of radiance ``L`` is a sum of point lights ``dI = L cos_l dA``, so under it the
diffuse value is ``kd * integral L cos_s cos_l / d^2 dA``: on the axis of a disk of radius
``r`` at height ``h``, ``kd * pi * L * r^2 / (r^2 + h^2)``.

Statistical tolerances come from the variance of one light sample (uniform area sampling),
computed by quadrature, divided by the number of samples: jittered (stratified) sampling never
has more variance than independent sampling, so the bound holds for every sampler.
"""

import math

import numpy as np
import pytest
from scenes import floor_quad, part, pixel_centre_rays, quad, render, settings
import scenes

from rtmesh.core.errors import SceneError
from rtmesh.geometry.accel import Accel
from rtmesh.lights.area_lighting import AreaLighting
from rtmesh.lights.area_lights import DiskLight, QuadLight
from rtmesh.lights.mesh_lights import emissive_mesh_light
from rtmesh.lights.point_lights import PointLight
from rtmesh.loaders.scene_file import scene_from_dict
from rtmesh.materials.blinn_phong import blinn_phong
from rtmesh.materials.table import Material
from rtmesh.rendering.stats import RenderStats
from rtmesh.sampling.patterns import Dim, decorrelated_points
from rtmesh.sampling.sampler import light_dimension
from rtmesh.sampling.warps import square_to_uniform_triangle, uniform_triangle_to_square
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene
import wavefront

DOWN = np.array([0.0, 0.0, -1.0])


# ---------------------------------------------------------------- references
def rectangle_integral(x1, x2, y1, y2, h):
    """``integral cos_s cos_l / d^2 dA`` over ``[x1, x2] x [y1, y2]`` at height ``h`` above a
    point at the origin, both planes horizontal (the point faces up, the light down).

    The corner rectangle ``[0, a] x [0, b]`` has the classic closed form (pi times the form
    factor from a differential area to a parallel rectangle); the integrand is even in x and
    y, so the corner form is odd in a and b and any rectangle is a signed sum of four.
    """
    def corner(a, b):
        sa, sb = math.sqrt(a * a + h * h), math.sqrt(b * b + h * h)
        return 0.5 * (a / sa * math.atan(b / sa) + b / sb * math.atan(a / sb))
    return corner(x2, y2) - corner(x1, y2) - corner(x2, y1) + corner(x1, y1)


def rectangle_moments(x1, x2, y1, y2, h, n=400, visible_from=-np.inf):
    """Mean and variance of one uniform-area sample ``V A cos_s cos_l / d^2`` by the midpoint
    rule on an ``n x n`` grid (the mean doubles as a check of :func:`rectangle_integral`).

    ``V`` is 1 on the part of the rectangle with ``x >= visible_from`` and 0 elsewhere.
    """
    x = x1 + (np.arange(n) + 0.5) * (x2 - x1) / n
    y = y1 + (np.arange(n) + 0.5) * (y2 - y1) / n
    d2 = x[:, None] ** 2 + y[None, :] ** 2 + h * h
    f = (x2 - x1) * (y2 - y1) * h * h / (d2 * d2) * (x[:, None] >= visible_from)
    return f.mean(), f.var()


class _NoClock:
    def lap(self, stage):
        pass


def direct_light(lights, points, normal=(0.0, 0.0, 1.0), blockers=(), samples=64,
                 sampler="jittered", seed=0, kd=1.0):
    """The area-light estimate (diffuse only) at ``points`` facing ``normal``, as rendering
    would compute it for hits at those points, one pixel per point.

    Returns
    -------
    value : (k,) float
        First channel of ``kd * estimate``.
    stats : RenderStats
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    k = len(points)
    if blockers:
        vertices = np.concatenate([np.asarray(v, float) for v, _ in blockers])
        offsets = np.cumsum([0] + [len(v) for v, _ in blockers[:-1]])
        faces = np.concatenate([np.asarray(f) + o for (_, f), o in zip(blockers, offsets)])
    else:  # nothing to hit: one tiny triangle far away
        vertices = np.array([[1e3, 1e3, 1e3], [1e3 + 1e-3, 1e3, 1e3], [1e3, 1e3 + 1e-3, 1e3]])
        faces = np.array([[0, 1, 2]])
    accel = Accel(vertices, faces)
    scale = 10.0
    ng = np.broadcast_to(np.asarray(normal, dtype=np.float64), (k, 3))
    lighting = AreaLighting(lights, accel, settings(light_samples=samples, sampler=sampler, seed=seed), scale)
    diffuse = np.full((k, 3), kd)

    def reflectance(wi, lit, pdf):
        return blinn_phong(ng, ng, wi, diffuse, None, None)  # Lambert: no highlight

    stats = RenderStats()
    value = lighting.direct(points, ng, reflectance, np.arange(k), np.zeros(k, np.int64), 0,
                            stats, _NoClock())
    return (np.zeros(k) if value is None else value[:, 0]), stats


def ceiling_quad(half=1.0, height=2.0, radiance=1.0, **kw):
    """A square light of side ``2 * half`` centred above the origin, facing down."""
    return QuadLight([0.0, 0.0, height], [0.0, 2.0 * half, 0.0], [2.0 * half, 0.0, 0.0], radiance, **kw)


# ---------------------------------------------------------------- closed forms
def test_rectangle_closed_form_matches_quadrature():
    for box in [(-1, 1, -1, 1, 2.0), (0.3, 1.7, -0.4, 2.2, 0.8), (-3, -1, 0.5, 1.0, 1.5)]:
        mean, _ = rectangle_moments(*box, n=1000)
        area = (box[1] - box[0]) * (box[3] - box[2])
        assert rectangle_integral(*box) == pytest.approx(mean / area * area, rel=1e-5)


def test_quad_light_normal_follows_the_right_hand_rule():
    light = ceiling_quad()
    np.testing.assert_allclose(light.normal, DOWN)
    assert light.area == pytest.approx(4.0)


@pytest.mark.parametrize("sampler", ["random", "jittered", "sobol"])
def test_disk_light_on_its_axis_matches_the_closed_form(sampler):
    # a floor seen straight down through a very narrow lens: every pixel is within 0.01 of
    # the disk's axis, where the irradiance differs from the axis value by < 1e-5
    radius, height, radiance, kd = 1.0, 2.0, 3.0, 0.5
    camera = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0.2)
    light = DiskLight([0.0, 0.0, height], DOWN, radius, radiance, visible=False)
    scene = Scene.from_parts([part("floor", floor_quad(50.0))], [Material("f", diffuse=kd)], [light], camera)
    spp, n = 4, 16
    result = render(scene, width=4, height=4, spp=spp, sampler=sampler, light_samples=n)
    expected = kd * math.pi * radiance * radius ** 2 / (radius ** 2 + height ** 2)
    # one uniform-area sample is kd L A h^2 / (h^2 + s)^2 with s = rho^2 uniform on [0, r^2]:
    # its second moment has a closed form too
    c = kd * radiance * math.pi * radius ** 2 * height ** 2
    second = c * c / (3 * radius ** 2) * (height ** -6 - (height ** 2 + radius ** 2) ** -3)
    sigma = math.sqrt(second - expected ** 2) / math.sqrt(16 * spp * n)
    assert result.image.mean() == pytest.approx(expected, abs=5 * sigma)
    assert sigma < 0.01 * expected  # the test can tell a wrong constant (pi, 1/pi, 2) apart
    assert result.stats.rays["area_shadow"] == 16 * spp * n


@pytest.mark.parametrize("point", [(0.0, 0.0), (0.4, -0.3), (1.5, 0.2), (-2.5, 1.5)])
def test_quad_light_irradiance_matches_the_rectangle_closed_form(point):
    light = ceiling_quad(half=1.0, height=2.0, radiance=2.0)
    n = 64
    value, _ = direct_light([light], [[point[0], point[1], 0.0]], samples=n, kd=0.5)
    box = (-1 - point[0], 1 - point[0], -1 - point[1], 1 - point[1], 2.0)
    expected = 0.5 * 2.0 * rectangle_integral(*box)
    _, variance = rectangle_moments(*box)
    sigma = 0.5 * 2.0 * math.sqrt(variance / n)
    assert value[0] == pytest.approx(expected, abs=5 * sigma + 1e-12)


def test_many_points_under_a_quad_light_match_in_aggregate():
    # 400 points, each an independent estimate: their standardised errors must look like
    # draws of mean 0 and spread <= 1 (the bound is the independent-sampling variance)
    rng = np.random.default_rng(1)
    xy = rng.uniform(-2.0, 2.0, size=(400, 2))
    light = ceiling_quad(half=0.7, height=1.3)
    n = 8
    value, _ = direct_light([light], np.column_stack([xy, np.zeros(400)]), samples=n, sampler="random")
    z = []
    for (x, y), v in zip(xy, value):
        box = (-0.7 - x, 0.7 - x, -0.7 - y, 0.7 - y, 1.3)
        _, variance = rectangle_moments(*box, n=100)
        z.append((v - rectangle_integral(*box)) / math.sqrt(variance / n))
    z = np.array(z)
    assert abs(z.mean()) < 5 / math.sqrt(400)
    assert z.std() < 1.2


# ---------------------------------------------------------------- shadows
PLATE = quad([[-50.0, -50.0, 1.0], [0.0, -50.0, 1.0], [0.0, 50.0, 1.0], [-50.0, 50.0, 1.0]])
"""A blocker covering x < 0 at height 1: from a point (x0, 0, 0) it hides the parts of the
light at height 2 with x < -x0, so the light (|x|, |y| <= 1) is hidden for x0 <= -1 (umbra),
half hidden at x0 = 0 and fully visible for x0 >= 1."""


def test_a_point_half_covered_by_an_edge_on_blocker_sees_exactly_half():
    light = ceiling_quad()
    n = 16
    full = rectangle_integral(-1, 1, -1, 1, 2.0)
    _, variance = rectangle_moments(-1, 1, -1, 1, 2.0, visible_from=0.0)
    for sampler in ("jittered", "sobol"):
        # the blocker's edge splits every 4 x 4 stratified set of the light in two halves
        u = decorrelated_points(sampler, 0, np.zeros(n, np.int64), np.zeros(n, np.int64), 1,
                                light_dimension(0, 0, 1), np.arange(n), n)
        points, *_ = light.sample(u)
        assert (points[:, 0] < 0.0).sum() == n // 2
        free, _ = direct_light([light], [[0.0, 0.0, 0.0]], samples=n, sampler=sampler)
        blocked, stats = direct_light([light], [[0.0, 0.0, 0.0]], blockers=[PLATE], samples=n,
                                      sampler=sampler)
        assert stats.rays["area_shadow"] == n
        # by symmetry the unoccluded part carries exactly half of the light
        assert blocked[0] == pytest.approx(0.5 * full, abs=5 * math.sqrt(variance / n))
        assert 0.0 < blocked[0] < free[0]


def test_umbra_is_black_full_light_is_unshadowed_and_penumbra_lies_between():
    light = ceiling_quad()
    x0 = np.linspace(-2.0, 2.0, 81)
    points = np.column_stack([x0, np.zeros_like(x0), np.zeros_like(x0)])
    n = 64
    free, _ = direct_light([light], points, samples=n)
    shadowed, _ = direct_light([light], points, blockers=[PLATE], samples=n)
    umbra, lit = x0 < -1.0 - 1e-9, x0 > 1.0 + 1e-9
    penumbra = (x0 > -0.95) & (x0 < 0.95)
    np.testing.assert_array_equal(shadowed[umbra], 0.0)
    # the same samples with no ray blocked: the same value
    np.testing.assert_array_equal(shadowed[lit], free[lit])
    assert ((shadowed[penumbra] > 0.0) & (shadowed[penumbra] < free[penumbra])).all()
    # and the penumbra follows the visible rectangle [-x0, 1] x [-1, 1]
    for x, v in zip(x0[penumbra], shadowed[penumbra]):
        # visible part [-x, 1] x [-1, 1] of the light, relative to the point (x, 0, 0)
        expected = rectangle_integral(-x - x, 1 - x, -1.0, 1.0, 2.0)
        _, variance = rectangle_moments(-1 - x, 1 - x, -1.0, 1.0, 2.0, n=100, visible_from=-x - x)
        assert v == pytest.approx(expected, abs=5 * math.sqrt(variance / n))
    # the shadow darkens monotonically into the umbra (on average over the noise)
    assert np.all(np.diff(shadowed[penumbra][::8]) > 0)


def test_soft_shadow_render_has_umbra_penumbra_and_full_light():
    # the plate hangs at height 1; the camera sits below it and sees the floor on both sides.
    # The regular sampler puts camera rays through pixel centres (and jitters light samples)
    kd = 0.5
    camera = Camera([0.0, -4.0, 0.6], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 60.0)
    materials = [Material("floor", diffuse=kd), Material("plate", diffuse=0.5)]
    floor = part("floor", floor_quad(20.0), 0)
    plate = part("plate", PLATE, 1)
    light = ceiling_quad(radiance=1.0, visible=False)
    width, height = 40, 30
    shadowed = render(Scene.from_parts([floor, plate], materials, [light], camera), width=width,
                      height=height, light_samples=16, threads=2)
    origins, directions = pixel_centre_rays(camera, width, height)
    down = directions[:, 2] < -0.05
    t = -origins[:, 2] / np.where(down, directions[:, 2], -1.0)
    x0 = origins[:, 0] + t * directions[:, 0]
    y0 = origins[:, 1] + t * directions[:, 1]
    value = shadowed.image[..., 0].reshape(-1).astype(np.float64)
    # umbra, exactly black
    umbra = down & (x0 < -1.05) & (np.abs(y0) < 15)
    assert umbra.sum() > 20
    np.testing.assert_array_equal(value[umbra], 0.0)
    # full light equals the unshadowed closed form, to the same sampling tolerance
    lit = down & (x0 > 1.05) & (np.abs(y0) < 15)
    penumbra = down & (np.abs(x0) < 0.9) & (np.abs(y0) < 0.5)
    assert lit.sum() > 20 and penumbra.sum() > 5
    for x, y, v in zip(x0[lit], y0[lit], value[lit]):
        box = (-1 - x, 1 - x, -1 - y, 1 - y, 2.0)
        _, variance = rectangle_moments(*box, n=60)
        assert v == pytest.approx(kd * rectangle_integral(*box), abs=5 * kd * math.sqrt(variance / 16) + 1e-6)
    for x, y, v in zip(x0[penumbra], y0[penumbra], value[penumbra]):
        assert 0.0 < v < kd * rectangle_integral(-1 - x, 1 - x, -1 - y, 1 - y, 2.0)


# ---------------------------------------------------------------- point-light limit
def test_small_or_distant_area_light_converges_to_a_point_light():
    # a tilted quad seen off-axis: the point light it tends to has I = L A cos_l
    point = np.array([0.3, -0.2, 0.0])
    errors = []
    for size, height in [(1.0, 1.0), (0.3, 1.0), (0.1, 1.0), (0.03, 1.0), (0.3, 10.0)]:
        centre = np.array([0.0, 0.0, height])
        edge1 = np.array([size, 0.0, 0.2 * size])
        edge2 = np.array([0.0, size, 0.0])
        light = QuadLight(centre, edge2, edge1, 1.5)  # emits down and slightly sideways
        value, _ = direct_light([light], [point], samples=16)
        to_light = centre - point
        d = np.linalg.norm(to_light)
        wi = to_light / d
        intensity = 1.5 * light.area * float(-wi @ light.normal)
        point_value = intensity * wi[2] / d ** 2
        errors.append(abs(value[0] / point_value - 1.0))
    # the error falls like (size / distance)^2
    assert errors[0] > errors[1] > errors[2] > errors[3]
    assert errors[3] < 2e-3
    assert errors[4] < 2e-3


def test_tiny_quad_light_renders_like_the_equivalent_point_light_highlight_included():
    camera = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 40.0)
    centre = np.array([0.4, -0.3, 1.5])
    # 1 mm square (faces down) of intensity L A = 1: bias ~ (size / distance)^2 ~ 1e-6, and
    # 16 stratified samples of an integrand varying by ~0.2 % leave noise far below 1e-4
    quad_light = QuadLight(centre, [0.0, 1e-3, 0.0], [1e-3, 0.0, 0.0], 1e6, visible=False)
    floor = [part("floor", floor_quad(10.0))]
    # a Blinn-Phong highlight too: it is evaluated per light sample like the diffuse term
    material = [Material("f", diffuse=0.6, specular=0.8, shininess=30)]
    width = height = 16
    area = render(Scene.from_parts(floor, material, [quad_light], camera), width=width, height=height,
                  light_samples=16).image[..., 0].reshape(-1)
    point = render(Scene.from_parts(floor, material, [PointLight(centre, 1.0)], camera),
                   width=width, height=height).image[..., 0].reshape(-1)
    # the point light is isotropic; the quad's intensity is L A cos_l toward each floor point
    origins, directions = pixel_centre_rays(camera, width, height)
    floor_points = origins + (-origins[:, 2] / directions[:, 2])[:, None] * directions
    to_light = centre - floor_points
    cos_light = to_light[:, 2] / np.linalg.norm(to_light, axis=1)
    np.testing.assert_allclose(area, point * cos_light, rtol=2e-4)


# ---------------------------------------------------------------- emissive meshes
def test_emissive_mesh_lights_like_the_equivalent_quad_light():
    # the same 1 x 1 square at height 1.5 as a quad light and as an emissive mesh (the mesh
    # is also in Embree: its own shadow rays must not stop on it); camera from the side,
    # below the emitter, so only the floor is seen
    camera = Camera([0.0, -3.0, 0.4], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 40.0)
    floor = part("floor", floor_quad(20.0), 0)
    radiance = 2.0
    corners = [[-0.5, -0.5, 1.5], [-0.5, 0.5, 1.5], [0.5, 0.5, 1.5], [0.5, -0.5, 1.5]]  # faces down
    emitter = part("lamp", quad(corners), 1)
    materials = [Material("floor", diffuse=0.5),
                 Material("lamp", diffuse=0.0, ambient=0.0, emission=radiance)]
    light = QuadLight([0.0, 0.0, 1.5], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], radiance, visible=False)
    n = 32
    options = dict(width=24, height=16, light_samples=n)  # regular: rays through pixel centres
    as_mesh = render(Scene.from_parts([floor, emitter], materials, [], camera), **options)
    as_quad = render(Scene.from_parts([floor], materials, [light], camera), **options)
    origins, directions = pixel_centre_rays(camera, 24, 16)
    down = directions[:, 2] < -0.02
    assert down.sum() > 100
    t = -origins[:, 2] / np.where(down, directions[:, 2], -1.0)
    x0, y0 = (origins[:, :2] + t[:, None] * directions[:, :2])[down].T
    mesh_value = as_mesh.image[..., 0].reshape(-1)[down]
    quad_value = as_quad.image[..., 0].reshape(-1)[down]
    assert (mesh_value > 0).all()
    # both are unbiased estimates of the same closed form, with the same sample variance
    # (uniform by area over the same square): each pixel within 5 sigma, and the sum of all
    # pixels' errors within 5 sigma of the sum (which detects a few % of bias)
    expected, sigma = [], []
    for x, y in zip(x0, y0):
        box = (-0.5 - x, 0.5 - x, -0.5 - y, 0.5 - y, 1.5)
        _, variance = rectangle_moments(*box, n=50)
        expected.append(0.5 * radiance * rectangle_integral(*box))
        sigma.append(0.5 * radiance * math.sqrt(variance / n))
    expected, sigma = np.array(expected), np.array(sigma)
    for value in (mesh_value, quad_value):
        assert (np.abs(value - expected) < 5 * sigma + 1e-6).all()
        assert abs((value - expected).sum()) < 5 * math.sqrt((sigma ** 2).sum())
    assert "area_lights" in as_mesh.stats.stages_enabled
    assert as_mesh.stats.rays["area_shadow"] == as_quad.stats.rays["area_shadow"] > 0


def test_all_emitters_form_one_light_sharing_samples_by_power():
    # two emissive squares at height 1.5, radiance 1 and 3: one light, so light_samples rays
    # per point in all, a quarter of them to the dim square; the estimate is the sum of both
    tri = []  # rows [v0, v1 - v0, v2 - v0], as Accel.triangles
    for x0 in (-1.0, 0.2):
        v0, v1, v2, v3 = np.array([[x0, -0.5, 1.5], [x0, 0.5, 1.5], [x0 + 1.0, 0.5, 1.5],
                                   [x0 + 1.0, -0.5, 1.5]])
        tri += [np.concatenate([v0, v1 - v0, v2 - v0]), np.concatenate([v0, v2 - v0, v3 - v0])]
    emission = np.repeat([[1.0] * 3, [3.0] * 3], 2, axis=0)
    light = emissive_mesh_light(np.array(tri), np.tile(DOWN, (4, 1)), emission)
    assert light.area == pytest.approx(2.0)
    xs = np.linspace(-1.5, 1.7, 41)
    n = 256
    value, stats = direct_light([light], np.column_stack([xs, np.zeros(41), np.zeros(41)]), samples=n)
    assert stats.rays["area_shadow"] == 41 * n
    radiance, share = (1.0, 3.0), (0.25, 0.75)
    expected, sigma = [], []
    for x in xs:
        boxes = [(-1.0 - x, 0.0 - x, -0.5, 0.5, 1.5), (0.2 - x, 1.2 - x, -0.5, 0.5, 1.5)]
        mean = sum(L * rectangle_integral(*b) for L, b in zip(radiance, boxes))
        # one sample: lamp i with probability share_i, then L_i (A_i g) / share_i
        moments = [rectangle_moments(*b, n=100) for b in boxes]
        second = sum(L * L / p * (var + m * m) for L, p, (m, var) in zip(radiance, share, moments))
        expected.append(mean)
        sigma.append(math.sqrt((second - mean ** 2) / n))
    expected, sigma = np.array(expected), np.array(sigma)
    assert (np.abs(value - expected) < 5 * sigma).all()
    assert abs((value - expected).sum()) < 5 * math.sqrt((sigma ** 2).sum())


def test_an_emitter_never_shadows_its_own_samples_even_at_grazing_angles():
    # the emissive square in Embree or not: no shadow ray may stop on the triangle it aims
    # at, so the estimates are identical, down to points 1e-3 below the emitter's plane
    # and 1000 units away (seen at 0.1 degree)
    v = np.array([[-0.5, -0.5, 1.5], [-0.5, 0.5, 1.5], [0.5, 0.5, 1.5], [0.5, -0.5, 1.5]])
    tri = np.array([np.concatenate([v[0], v[1] - v[0], v[2] - v[0]]),
                    np.concatenate([v[0], v[2] - v[0], v[3] - v[0]])])
    light = emissive_mesh_light(tri, np.tile(DOWN, (2, 1)), np.ones((2, 3)))
    x = np.concatenate([np.linspace(-3.0, 3.0, 25), [10.0, 100.0, 1000.0]])
    for z in (0.0, 1.5 - 1e-3):
        points = np.column_stack([x, 0.3 * np.ones_like(x), np.full_like(x, z)])
        alone, _ = direct_light([light], points, samples=16)
        with_itself, _ = direct_light([light], points, blockers=[(v, [[0, 1, 2], [0, 2, 3]])], samples=16)
        assert (alone > 0).all()
        np.testing.assert_array_equal(with_itself, alone)


def test_a_light_flush_with_a_ceiling_lights_the_room_and_is_seen():
    # the light lies exactly in the plane of a ceiling (facing down): the ceiling neither
    # shadows it nor hides it from the camera
    ceiling = quad([[-5.0, -5.0, 2.0], [-5.0, 5.0, 2.0], [5.0, 5.0, 2.0], [5.0, -5.0, 2.0]])  # faces down
    light = ceiling_quad(half=0.5, height=2.0, radiance=3.0)
    x = np.linspace(-3.0, 3.0, 13)
    points = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    open_sky, _ = direct_light([light], points, samples=16)
    under_ceiling, _ = direct_light([light], points, blockers=[ceiling], samples=16)
    np.testing.assert_array_equal(under_ceiling, open_sky)
    camera = Camera([0.0, 0.0, 0.5], [0.0, 0.0, 2.0], [0.0, 1.0, 0.0], 10.0)
    scene = Scene.from_parts([part("floor", floor_quad(5.0)), part("ceiling", ceiling)], [Material("f")],
                             [light], camera)
    np.testing.assert_array_equal(render(scene, width=4, height=4).image, np.float32(3.0))


def test_emissive_mesh_emission_is_seen_from_both_sides_and_lights_both():
    # an emissive square floating between two floors lights both
    materials = [Material("floor", diffuse=0.5), Material("lamp", diffuse=0.0, emission=1.0)]
    lamp = part("lamp", quad([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]]), 1)
    lower = part("lower", floor_quad(5.0, height=-1.0), 0)
    upper_vertices, upper_faces = floor_quad(5.0, height=1.0)
    upper = part("upper", (upper_vertices, upper_faces[:, ::-1]), 0)  # facing down
    values = []
    for eye in (3.0, -3.0):
        camera = Camera([2.0, 0.0, eye * 0.3], [2.0, 0.0, -np.sign(eye)], [0.0, 1.0, 0.0], 10.0)
        result = render(Scene.from_parts([lamp, lower, upper], materials, [], camera), width=4, height=4,
                        light_samples=16, sampler="jittered")
        values.append(result.image.mean())
    assert values[0] > 0 and values[1] > 0
    assert values[0] == pytest.approx(values[1], rel=0.05)


# ---------------------------------------------------------------- sampling machinery
@pytest.mark.parametrize("sampler", ["jittered", "sobol"])
def test_each_stratum_of_the_light_holds_exactly_one_sample(sampler):
    light = QuadLight([1.0, 2.0, 3.0], [2.0, 0.0, 0.0], [0.5, 0.0, 1.5], 1.0)  # a parallelogram
    n, pixels = 16, 200
    pixel = np.repeat(np.arange(pixels), n)
    sample = np.full(pixels * n, 3)  # pixel sample 3 of each pixel (of 4)
    u = decorrelated_points(sampler, 5, pixel, sample, 4, 1 << 24, np.tile(np.arange(n), pixels), n)
    points, *_ = light.sample(u)
    # coordinates of the points along the two edges, from the corner
    a, b = light.to_square(points).T
    assert ((a >= 0) & (a < 1) & (b >= 0) & (b < 1)).all()
    cell = (np.floor(b * 4) * 4 + np.floor(a * 4)).astype(int).reshape(pixels, n)
    for row in cell:
        np.testing.assert_array_equal(np.sort(row), np.arange(n))
    # and the sets of different pixels differ
    assert np.unique(np.round(a, 6)).size > pixels


@pytest.mark.parametrize("sampler", ["jittered", "regular", "sobol", "zsobol"])
def test_area_light_and_ao_points_of_a_pixel_are_one_stratified_set(sampler, monkeypatch):
    # spp = 4 camera samples per pixel x 4 rays per hit: the 16 points a pixel's samples
    # send to the light (and the 16 ambient-occlusion directions) fill every stratum of the
    # 4 x 4 grid once (for Sobol every elementary interval), as the general wavefront draws
    # them (the path kernel's Whitted configuration draws a pixel's light points and AO
    # directions from Owen-scrambled Sobol sets under every sampler but random)
    import rtmesh.sampling.sampler
    from rtmesh.rendering import integrator as integrator_module

    monkeypatch.setattr(integrator_module, "REFERENCE_STAGE", wavefront.attach)
    drawn = []

    def recording(module):
        original = module.decorrelated_points

        def draw(sampler, seed, pixel, sample, spp, dimension, ray=0, rays=1, resolution=None):
            u = original(sampler, seed, pixel, sample, spp, dimension, ray, rays, resolution)
            drawn.append((dimension, np.array(pixel), np.array(sample), ray, np.array(u)))
            return u
        monkeypatch.setattr(module, "decorrelated_points", draw)
    recording(rtmesh.sampling.sampler)  # every stage draws its points through the render's Sampler
    camera = Camera([0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 30.0)
    scene = Scene.from_parts([part("floor", floor_quad(20.0))], [Material("f")], [ceiling_quad()], camera)
    width = height = 3
    render(scene, width=width, height=height, spp=4, sampler=sampler, light_samples=4, ao_samples=4,
           passes=("ao",))
    for dimension in (Dim.AO, light_dimension(0, 0, 1)):
        calls = [c for c in drawn if c[0] == dimension]
        assert sorted(c[3] for c in calls) == [0, 1, 2, 3]  # one call per ray of the hits
        pixel = np.concatenate([c[1] for c in calls])
        sample = np.concatenate([c[2] for c in calls])
        u = np.concatenate([c[4] for c in calls])
        assert len(u) == width * height * 16
        for p in range(width * height):
            mine = u[pixel == p]
            assert sorted(sample[pixel == p].tolist()) == sorted(list(range(4)) * 4)
            grids = [(4, 4)] if sampler not in ("sobol", "zsobol") else [(1, 16), (2, 8), (4, 4), (8, 2), (16, 1)]
            for nx, ny in grids:
                cells = np.floor(mine[:, 0] * nx) * ny + np.floor(mine[:, 1] * ny)
                assert sorted(cells.astype(int).tolist()) == list(range(16))


def test_quad_and_disk_light_samples_round_trip_and_have_density_one_over_area():
    quad_light = QuadLight([1.0, 2.0, 3.0], [2.0, 0.0, 0.0], [0.5, 0.0, 1.5], 1.0)  # a parallelogram
    disk_light = DiskLight([0.5, -1.0, 2.0], [1.0, 2.0, -0.5], 0.7, 1.0)
    rng = np.random.default_rng(7)
    u = rng.uniform(1e-3, 1.0 - 1e-3, size=(2000, 2))
    u = u[(np.abs(u[:, 0] - u[:, 1]) > 1e-3) & (np.abs(u[:, 0] + u[:, 1] - 1.0) > 1e-3)]
    points, _, _, inverse_pdf = quad_light.sample(u)
    np.testing.assert_allclose(quad_light.to_square(points), u, rtol=0, atol=1e-12)
    # the density the points follow, 1 / |dy/du0 x dy/du1|, is the pdf the estimator divides by
    h = 1e-6
    for light in (quad_light, disk_light):
        d0 = (light.sample(u + [h, 0.0])[0] - light.sample(u - [h, 0.0])[0]) / (2 * h)
        d1 = (light.sample(u + [0.0, h])[0] - light.sample(u - [0.0, h])[0]) / (2 * h)
        area_scale = np.linalg.norm(np.cross(d0, d1), axis=1)
        np.testing.assert_allclose(area_scale, light.sample(u)[3], rtol=1e-6)
        # and the points lie in the light's plane
        offset = light.sample(u)[0] - light.position
        np.testing.assert_allclose(offset @ light.normal, 0.0, atol=1e-12)


def test_mesh_light_pdf_integrates_to_one_and_matches_its_jacobian():
    # two triangles of different areas and emissions, not in one plane
    v = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0],
                  [0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 0.5, 1.5]])
    tris = np.array([np.concatenate([v[i], v[i + 1] - v[i], v[i + 2] - v[i]]) for i in (0, 3)])
    normals = np.cross(tris[:, 3:6], tris[:, 6:9])
    area = 0.5 * np.linalg.norm(normals, axis=1)
    normals /= 2.0 * area[:, None]
    light = emissive_mesh_light(tris, normals, np.array([[1.0, 2.0, 3.0], [0.5, 0.5, 0.5]]))
    # pdf per unit area on each face (1 / inverse_pdf) times the face's area sums to one
    power = area * np.array([2.0, 0.5])
    share = power / power.sum()
    # u0 picks the face by its share of the power: the middle of each face's interval
    _, _, _, inverse_pdf = light.sample(np.column_stack([np.cumsum(share) - 0.5 * share, [0.5, 0.5]]))
    assert (1.0 / inverse_pdf * area).sum() == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(1.0 / inverse_pdf * area, share, rtol=1e-12)
    # the points' density, 1 / |dy/du0 x dy/du1|, is that pdf (away from the seam between
    # the faces in u0)
    rng = np.random.default_rng(8)
    u = rng.uniform(1e-3, 1.0 - 1e-3, size=(2000, 2))
    u = u[np.abs(u[:, 0] - share[0]) > 1e-3]
    h = 1e-7
    d0 = (light.sample(u + [h, 0.0])[0] - light.sample(u - [h, 0.0])[0]) / (2 * h)
    d1 = (light.sample(u + [0.0, h])[0] - light.sample(u - [0.0, h])[0]) / (2 * h)
    area_scale = np.linalg.norm(np.cross(d0, d1), axis=1)
    np.testing.assert_allclose(area_scale, light.sample(u)[3], rtol=1e-5)


@pytest.mark.parametrize("sampler, smooth_slope, penumbra_slope", [
    ("random", (-0.6, -0.4), (-0.6, -0.4)),  # Monte Carlo: N^-1/2
    ("jittered", (-1.2, -0.85), (-0.9, -0.7)),  # stratified in 2D: N^-1, N^-3/4 across an edge
    ("sobol", (-1.7, -1.2), (-1.2, -0.9)),  # Owen-scrambled: N^-3/2, N^-1 across an edge
])
def test_light_sample_error_falls_at_the_rate_of_the_sampler(sampler, smooth_slope, penumbra_slope):
    # RMSE over 300 points against the closed form, for N = 4 .. 256 light samples, with
    # the light in full view (a smooth integrand) and half hidden by the plate (an edge)
    rng = np.random.default_rng(0)
    xy = rng.uniform(-1.5, 1.5, size=(300, 2))
    points = np.column_stack([xy, np.zeros(300)])
    full = np.array([rectangle_integral(-1 - x, 1 - x, -1 - y, 1 - y, 2.0) for x, y in xy])
    # behind the plate only the part of the light with x > -x0 is seen from (x0, y0)
    part_seen = np.array([rectangle_integral(max(-1.0, -x) - x, 1 - x, -1 - y, 1 - y, 2.0) if x > -1 else 0.0
                          for x, y in xy])
    counts = [4, 16, 64, 256]
    for blockers, expected, (low, high) in [((), full, smooth_slope), ((PLATE,), part_seen, penumbra_slope)]:
        rmse = [np.sqrt(np.mean((direct_light([ceiling_quad()], points, blockers=list(blockers), samples=n,
                                              sampler=sampler)[0] - expected) ** 2)) for n in counts]
        slope = np.polyfit(np.log(counts), np.log(rmse), 1)[0]
        assert low < slope < high, f"{sampler}, blockers={len(blockers)}: slope {slope:.2f}"


def test_light_samples_are_decorrelated_across_lights_depths_and_pixel_samples():
    # every (depth, light) pair has its own dimensions, from Dim.LIGHT up to below Dim.GLOSSY
    dims = [light_dimension(depth, i, 3) for depth in range(4) for i in range(3)]
    assert len(set(dims)) == 12 and min(dims) == Dim.LIGHT and max(dims) < 1 << 25
    assert all(d % 2 == 0 for d in dims)  # pairs never overlap
    pixel, ray = np.zeros(4, np.int64), np.arange(4)
    a = decorrelated_points("jittered", 0, pixel, np.zeros(4, np.int64), 2, 1 << 24, ray, 4)
    b = decorrelated_points("jittered", 0, pixel, np.ones(4, np.int64), 2, 1 << 24, ray, 4)
    c = decorrelated_points("jittered", 0, pixel, np.zeros(4, np.int64), 2, (1 << 24) + 2, ray, 4)
    assert not np.allclose(a, b) and not np.allclose(a, c)


def test_triangle_warp_is_uniform_and_round_trips():
    rng = np.random.default_rng(3)
    u = rng.random((20000, 2))
    b = square_to_uniform_triangle(u)
    assert ((b >= 0).all() and (b.sum(axis=1) <= 1 + 1e-12).all())
    np.testing.assert_allclose(uniform_triangle_to_square(b), u, atol=1e-12)
    # uniform: each of the 4 sub-triangles of the midpoint subdivision gets a quarter
    corner = (b[:, 0] > 0.5).astype(int) + 2 * (b[:, 1] > 0.5) + 3 * (b.sum(axis=1) < 0.5)
    counts = np.bincount(corner, minlength=4)
    assert (np.abs(counts / len(u) - 0.25) < 0.015).all()


def test_soft_shadow_image_is_identical_for_any_thread_count_and_chunk_size():
    camera = Camera([0.0, -4.0, 0.6], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 60.0)
    scene = Scene.from_parts([part("floor", floor_quad(20.0)), part("plate", PLATE)], [Material("f")],
                             [ceiling_quad(), DiskLight([1.0, 1.0, 2.5], DOWN, 0.5, 2.0)], camera)
    a = render(scene, width=20, height=14, spp=2, sampler="sobol", light_samples=4, threads=1)
    b = render(scene, width=20, height=14, spp=2, sampler="sobol", light_samples=4, threads=2,
               chunk_samples=37)
    np.testing.assert_array_equal(a.image, b.image)
    assert a.stats.rays == b.stats.rays


# ---------------------------------------------------------------- stages and visibility
def test_area_light_stages_run_only_for_scenes_with_area_lights():
    camera = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 30.0)
    floor = [part("floor", floor_quad(50.0))]
    plain = render(Scene.from_parts(floor, [Material("f")], [PointLight([0, 0, 3], 5.0)], camera),
                   width=8, height=8)
    assert plain.stats.rays["area_shadow"] == 0
    assert not {"area_lights", "area_light_visibility"} & set(plain.stats.stages_enabled)
    lit = render(Scene.from_parts(floor, [Material("f")], [ceiling_quad(height=3.0)], camera),
                 width=8, height=8, light_samples=5)
    # every floor point sees the whole light: light_samples rays per camera hit
    assert lit.stats.rays["area_shadow"] == 5 * 64
    assert lit.stats.rays["shadow"] == 0
    assert {"area_lights", "area_light_visibility"} <= set(lit.stats.stages_enabled)


def test_light_intersection_agrees_with_embree_on_the_same_quad():
    # a tilted parallelogram light, and the same shape as two triangles traced by Embree:
    # the light answers only for rays coming at its emitting side
    light = QuadLight([0.3, -0.2, 1.0], [1.2, 0.1, 0.3], [-0.2, 0.9, 0.1], 1.0)
    corners = light.corner + np.array([[0, 0], [1, 0], [1, 1], [0, 1]]) @ np.stack([light.edge1, light.edge2])
    accel = Accel(corners, np.array([[0, 1, 2], [0, 2, 3]]))
    rng = np.random.default_rng(7)
    origins = rng.uniform(-3.0, 3.0, size=(4000, 3))
    targets = light.corner + rng.uniform(-0.2, 1.2, size=(4000, 2)) @ np.stack([light.edge1, light.edge2])
    directions = targets - origins
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    directions[:10] = np.cross(light.edge1, light.normal) / np.linalg.norm(light.edge1)  # parallel
    with np.errstate(all="raise"):
        t = light.intersect(origins, directions)
    embree = accel.intersect(origins, directions).t
    front = directions @ light.normal < 0.0
    # away from the edges (where float32 Embree may round either way) and from grazing
    # angles (where its float32 t error grows like 1 / cos) they agree
    local = targets - light.corner
    a, b = local @ light._dual1, local @ light._dual2
    clear = (np.minimum(np.abs(a - np.round(a)), np.abs(b - np.round(b))) > 1e-3) & \
        (np.abs(directions @ light.normal) > 0.05)
    expected = np.where(front, embree, np.inf)
    assert np.isfinite(expected[clear]).sum() > 500
    np.testing.assert_allclose(t[clear], expected[clear], rtol=1e-5)
    assert np.isinf(t[:10]).all()
    disk = DiskLight([0.0, 0.0, 1.0], DOWN, 0.5, 1.0)
    with np.errstate(all="raise"):
        t = disk.intersect(origins, directions)
    hit_point = origins + np.where(np.isfinite(t), t, 0.0)[:, None] * directions
    seen = np.isfinite(t)
    assert seen.sum() > 100
    np.testing.assert_allclose(hit_point[seen, 2], 1.0, atol=1e-12)
    assert (np.hypot(hit_point[seen, 0], hit_point[seen, 1]) <= 0.5 + 1e-12).all()
    assert (directions[seen, 2] > 0).all()  # only from below, the side it emits to
    # and every ray from below through the disk is seen
    z_hit = (1.0 - origins[:, 2]) / directions[:, 2]
    crossing = origins + z_hit[:, None] * directions
    through = (directions[:, 2] > 0) & (z_hit > 0) & (np.hypot(crossing[:, 0], crossing[:, 1]) < 0.5 - 1e-9)
    assert (seen == through).all()


def test_visible_area_light_is_seen_from_its_front_only_and_in_mirrors():
    radiance = np.array([4.0, 3.0, 2.0])
    light = ceiling_quad(half=5.0, height=2.0, radiance=radiance)  # faces down
    floor = [part("floor", floor_quad(50.0))]
    up = Camera([0.0, 0.0, 0.5], [0.0, 0.0, 3.0], [0.0, 1.0, 0.0], 30.0)
    seen = render(Scene.from_parts(floor, [Material("f")], [light], up), width=6, height=6)
    np.testing.assert_array_equal(seen.image, np.broadcast_to(radiance.astype(np.float32), (6, 6, 3)))
    invisible = ceiling_quad(half=5.0, height=2.0, radiance=radiance, visible=False)
    dark = render(Scene.from_parts(floor, [Material("f")], [invisible], up, background=[0.1] * 3),
                  width=6, height=6)
    np.testing.assert_array_equal(dark.image, np.float32(0.1))
    # from above, the light is seen from behind: invisible, the lit floor shows through
    down = Camera([0.0, 0.0, 4.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 10.0)
    behind = render(Scene.from_parts(floor, [Material("f", diffuse=0.5)], [light], down), width=6,
                    height=6, light_samples=4)
    unseen = render(Scene.from_parts(floor, [Material("f", diffuse=0.5)], [invisible], down), width=6,
                    height=6, light_samples=4)
    assert behind.image.min() > 0.0
    np.testing.assert_array_equal(behind.image, unseen.image)
    # in a mirror floor, the light is reflected (times the mirror's reflectance)
    mirror = Material("m", diffuse=0.0, mirror=0.5)
    tilted = Camera([0.0, -1.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 20.0)
    reflected = render(Scene.from_parts(floor, [mirror], [light], tilted), width=6, height=6)
    np.testing.assert_allclose(reflected.image, np.broadcast_to(0.5 * radiance, (6, 6, 3)), rtol=1e-6)


# ---------------------------------------------------------------- scene files
def test_scene_file_area_lights_and_light_samples():
    doc = {
        "render": {"light_samples": 9},
        "objects": [{"primitive": "plane", "size": [4, 4]}],
        "lights": [
            {"type": "quad", "position": [0, 0, 2], "edge1": [0, 1, 0], "edge2": [1, 0, 0],
             "radiance": [1, 2, 3]},
            {"type": "disk", "position": [0, 0, 3], "look_at": [0, 0, 0], "radius": 0.5,
             "radiance": 4, "visible": False},
        ],
    }
    scene, s = scene_from_dict(doc, source="s.toml")
    assert s.light_samples == 9
    quad_light, disk = scene.lights
    assert isinstance(quad_light, QuadLight) and isinstance(disk, DiskLight)
    np.testing.assert_allclose(quad_light.normal, DOWN)
    np.testing.assert_allclose(disk.normal, DOWN)
    assert disk.visible is False and quad_light.visible is True
    np.testing.assert_array_equal(quad_light.radiance, [1, 2, 3])


@pytest.mark.parametrize("light, where", [
    ({"type": "quad", "position": [0, 0, 1], "edge1": [1, 0, 0], "radiance": 1}, "lights[0].edge2: missing"),
    ({"type": "quad", "position": [0, 0, 1], "edge1": [1, 0, 0], "edge2": [2, 0, 0], "radiance": 1},
     "lights[0]: quad light edges are zero or parallel"),
    ({"type": "quad", "position": [0, 0, 1], "edge1": [1, 0, 0], "edge2": [0, 1, 0], "radiance": 1,
      "radius": 1}, "lights[0].radius: does not apply to a quad light"),
    ({"type": "disk", "position": [0, 0, 1], "radius": 1, "radiance": 1},
     "lights[0]: a disk light needs exactly one"),
    ({"type": "disk", "position": [0, 0, 1], "direction": [0, 0, -1], "radius": 0, "radiance": 1},
     "lights[0].radius: expected a number > 0"),
    ({"type": "disk", "position": [0, 0, 1], "direction": [0, 0, -1], "radius": 1, "radiance": 1,
      "visible": "yes"}, "lights[0].visible: expected true or false"),
    ({"type": "point", "position": [0, 0, 1], "intensity": 1, "radiance": 1},
     "lights[0].radiance: does not apply to a point light"),
])
def test_invalid_area_light_names_file_and_key(light, where):
    doc = {"objects": [{"primitive": "plane"}], "lights": [light]}
    with pytest.raises(SceneError) as info:
        scene_from_dict(doc, source="s.toml")
    assert str(info.value).startswith(f"s.toml: {where}")


def test_light_samples_must_be_positive():
    doc = {"objects": [{"primitive": "plane"}], "render": {"light_samples": 0}}
    with pytest.raises(SceneError, match="s.toml: render: light_samples must be >= 1"):
        scene_from_dict(doc, source="s.toml")


# ---------------------------------------------------------------- ambient occlusion
def test_stratified_ao_at_the_foot_of_a_wall_and_in_a_corner_is_exact():
    # with jittered (or Sobol) AO rays the cosine-weighted hemisphere splits exactly: the
    # concentric map sends u0 < 1/2 to x < 0 and u1 < 1/2 to y < 0, so a wall at x = 0
    # blocks exactly half of every even stratified set and two walls a quarter.  The points
    # are 0.05 from walls 1000 high: only directions within 5e-5 of the wall's plane (an
    # area fraction of ~6e-5 of the disk) could pass over it
    big = 1e3
    floor = quad([[0.0, 0.0, 0.0], [big, 0.0, 0.0], [big, big, 0.0], [0.0, big, 0.0]])
    wall_x = quad([[0.0, 0.0, 0.0], [0.0, big, 0.0], [0.0, big, big], [0.0, 0.0, big]])
    wall_y = quad([[0.0, 0.0, 0.0], [0.0, 0.0, big], [big, 0.0, big], [big, 0.0, 0.0]])
    for sampler in ("jittered", "sobol"):
        # near the foot of the wall x = 0, far from the wall y = 0
        camera = Camera([0.05, 50.0, 1.0], [0.05, 50.0, 0.0], [0.0, 1.0, 0.0], 0.05)
        scene = Scene.from_parts([part("floor", floor), part("wall", wall_x)], [Material("f")], [], camera)
        ao = render(scene, width=4, height=4, spp=2, sampler=sampler, ao_samples=16, passes=("ao",),
                    ao_distance=1e4).passes["ao"]
        np.testing.assert_array_equal(ao, 0.5)
        # in the corner of both walls
        camera = Camera([0.05, 0.05, 1.0], [0.05, 0.05, 0.0], [0.0, 1.0, 0.0], 0.05)
        scene = Scene.from_parts([part("floor", floor), part("wall_x", wall_x), part("wall_y", wall_y)],
                                 [Material("f")], [], camera)
        ao = render(scene, width=4, height=4, spp=2, sampler=sampler, ao_samples=16, passes=("ao",),
                    ao_distance=1e4).passes["ao"]
        np.testing.assert_array_equal(ao, 0.25)


# ---------------------------------------------------------------- command line and assets
AREA_SCENE = """
[render]
width = 12
height = 9
spp = 1

[camera]
position = [0, 3, 4]
look_at = [0, 0, 0]

[[objects]]
primitive = "plane"
size = [6, 6]
rotate = [-90, 0, 0]

[[lights]]
type = "quad"
position = [0, 2, 0]
edge1 = [1, 0, 0]
edge2 = [0, 0, 1]
radiance = 5
"""


def test_light_samples_flag_sets_the_shadow_rays_per_hit(tmp_path, capsys):
    from rtmesh.api import load_scene
    from rtmesh.cli import main

    path = tmp_path / "area.toml"
    path.write_text(AREA_SCENE)
    _, loaded = load_scene(path, light_samples=7)
    assert loaded.light_samples == 7
    assert main(["render", str(path), "-o", str(tmp_path / "a.png"), "--light-samples", "7", "-q"]) == 0
    # a zero or a non-number is refused by the parser: exit status 2, no image
    for bad in ("0", "many"):
        with pytest.raises(SystemExit) as info:
            main(["render", str(path), "-o", str(tmp_path / "b.png"), "--light-samples", bad])
        assert info.value.code == 2
    assert "--light-samples" in capsys.readouterr().err
    assert not (tmp_path / "b.png").exists()


def test_shipped_soft_shadow_scene_renders():
    import os

    from rtmesh.loaders.scene_file import read_scene_file

    path = os.path.join(scenes.ASSETS, "effects", "soft_shadow.toml")
    scene, _ = read_scene_file(path)
    result = render(scene, width=24, height=18, spp=1, light_samples=2)
    assert {"area_lights", "area_light_visibility", "emission"} <= set(result.stats.stages_enabled)
    assert result.stats.rays["area_shadow"] > 0 and result.stats.rays["shadow"] == 0
    # the visible quad light is in the top-left corner of the frame, at its full radiance
    assert result.image[:4, :6].max() == pytest.approx(9.0, rel=1e-6)


# ---------------------------------------------------------------- emission textures
def _textured_lamp(texels, height=1.5):
    """A 1 x 1 emissive square facing down at ``height`` whose UVs are (x + 0.5, y + 0.5),
    with an emission texture of ``texels`` ((h, w) image, clamped)."""
    from rtmesh.io.texture_images import Texture
    from rtmesh.scene.model import MeshPart

    corners = np.array([[-0.5, -0.5, height], [-0.5, 0.5, height], [0.5, 0.5, height], [0.5, -0.5, height]])
    uv = corners[:, :2] + 0.5
    lamp = MeshPart("lamp", corners, np.array([[0, 1, 2], [0, 2, 3]]), 1, uv=uv)
    texture = Texture(np.asarray(texels, dtype=np.float64), wrap="clamp")
    return lamp, texture


def test_a_textured_emitter_is_seen_and_lights_with_its_texels():
    # radiance 2 x a texture that is 0 at -x and 2 at +x (mean 1): seen from below, each
    # half shows its texel; on the floor the light matches the integral of the textured
    # radiance (midpoint rule), within 5 sigma of one sample's variance
    lamp, texture = _textured_lamp([[0.0, 0.0, 2.0, 2.0]])
    radiance = 2.0
    materials = [Material("floor", diffuse=0.5),
                 Material("lamp", diffuse=0.0, ambient=0.0, emission=radiance, emission_texture=texture)]
    up = Camera([0.0, 0.0, 0.5], [0.0, 0.0, 1.5], [0.0, 1.0, 0.0], 60.0)
    seen = render(Scene.from_parts([part("floor", floor_quad(20.0), 0), lamp], materials, [], up),
                  width=16, height=16).image[..., 0]
    # the camera looks up with +y up the image: +x is to the left in the image
    assert seen[8, 12] == 0.0
    assert seen[8, 3] == pytest.approx(radiance * 2.0, rel=1e-6)

    camera = Camera([0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 60.0)  # the floor under the lamp
    n = 64
    result = render(Scene.from_parts([part("floor", floor_quad(20.0), 0), lamp], materials, [], camera),
                    width=24, height=16, light_samples=n)
    origins, directions = pixel_centre_rays(camera, 24, 16)
    down = directions[:, 2] < -0.02
    t = -origins[:, 2] / np.where(down, directions[:, 2], -1.0)
    x0, y0 = (origins[:, :2] + t[:, None] * directions[:, :2])[down].T
    value = result.image[..., 0].reshape(-1)[down]
    grid = 200
    xs = -0.5 + (np.arange(grid) + 0.5) / grid
    lx, ly = np.meshgrid(xs, xs, indexing="ij")
    texel = texture.sample(np.column_stack([lx.ravel() + 0.5, ly.ravel() + 0.5]))[:, 0].reshape(grid, grid)
    expected, sigma = [], []
    for x, y in zip(x0, y0):
        d2 = (lx - x) ** 2 + (ly - y) ** 2 + 1.5 ** 2
        g = 1.5 * 1.5 / (d2 * d2)  # cos_s cos_l / d^2 for parallel planes 1.5 apart
        sample = radiance * texel * g  # one sample's value / area (area 1, uniform by area)
        mean = sample.mean()
        expected.append(0.5 * mean)
        sigma.append(0.5 * math.sqrt(((sample ** 2).mean() - mean ** 2) / n))
    expected, sigma = np.array(expected), np.array(sigma)
    assert (np.abs(value - expected) < 5 * sigma + 1e-6).all()
    bright = x0 > 0.0  # the floor under the bright half
    for rows in (bright, ~bright):
        assert abs((value - expected)[rows].sum()) < 5 * math.sqrt((sigma[rows] ** 2).sum())
    # these sums see the texture: a uniform emitter of the same mean (what ignoring the
    # texture would give) is far outside their tolerance
    flat = []
    for x, y in zip(x0, y0):
        d2 = (lx - x) ** 2 + (ly - y) ** 2 + 1.5 ** 2
        flat.append(0.5 * radiance * (1.5 * 1.5 / (d2 * d2)).mean())
    assert abs((np.array(flat) - expected)[bright].sum()) > 10 * math.sqrt((sigma[bright] ** 2).sum())


def test_mesh_light_samples_take_the_texel_at_their_point():
    lamp, texture = _textured_lamp([[0.0, 1.0], [3.0, 0.5]])
    v = lamp.vertices
    tri = np.array([np.concatenate([v[0], v[1] - v[0], v[2] - v[0]]),
                    np.concatenate([v[0], v[2] - v[0], v[3] - v[0]])])

    def tint(prim, u, w):
        points = tri[prim, :3] + u[:, None] * tri[prim, 3:6] + w[:, None] * tri[prim, 6:9]
        return texture.sample(points[:, :2] + 0.5)[:, [0, 0, 0]]

    mean = texture.pixels.mean()
    light = emissive_mesh_light(tri, np.tile(DOWN, (2, 1)), np.full((2, 3), 2.0), tint, np.full((2, 3), mean))
    points, normals, emitted, inverse_pdf = light.sample(np.random.default_rng(4).random((500, 2)))
    np.testing.assert_allclose(emitted[:, 1], 2.0 * texture.sample(points[:, :2] + 0.5)[:, 0], rtol=1e-12)
    # uniform by area (both faces have the same mean tint): 1 / pdf = area x mean emission / mean emission
    np.testing.assert_allclose(inverse_pdf, 1.0, rtol=1e-12)
    # a map that is black everywhere makes no light at all
    assert emissive_mesh_light(tri, np.tile(DOWN, (2, 1)), np.ones((2, 3)), tint, np.zeros((2, 3))) is None


def test_an_emitter_close_to_the_lit_point_gives_no_fireflies():
    # a point 1e-3 below a 1 x 1 emissive square: sampled by area, one sample in a few
    # thousand would land near it and weigh ~1e6; uniform in solid angle every sample's
    # geometric weight cos_l / (d^2 pdf) is the triangle's solid angle over its chance,
    # at most 2 pi / 0.5; the mean still matches the closed form
    v = np.array([[-0.5, -0.5, 1.5], [-0.5, 0.5, 1.5], [0.5, 0.5, 1.5], [0.5, -0.5, 1.5]])
    tri = np.array([np.concatenate([v[0], v[1] - v[0], v[2] - v[0]]),
                    np.concatenate([v[0], v[2] - v[0], v[3] - v[0]])])
    light = emissive_mesh_light(tri, np.tile(DOWN, (2, 1)), np.ones((2, 3)))
    n = 4096
    p = np.tile([0.1, 0.05, 1.5 - 1e-3], (n, 1))
    u = decorrelated_points("jittered", 0, np.zeros(n, np.int64), np.arange(n), n, Dim.LIGHT)
    y, normals, radiance, inverse_pdf = light.sample(u, p)
    to_light = y - p
    d2 = (to_light ** 2).sum(axis=1)
    cos_l = np.abs(to_light[:, 2]) / np.sqrt(d2)
    cos_s = to_light[:, 2] / np.sqrt(d2)
    weight = cos_l * inverse_pdf / d2
    assert weight.max() < 4 * np.pi + 1e-9
    estimate = (cos_s * weight).mean()
    exact = rectangle_integral(-0.6, 0.4, -0.55, 0.45, 1e-3)
    assert estimate == pytest.approx(exact, rel=1e-3)
    # the points lie on the square (where shadow rays aim)
    np.testing.assert_allclose(y[:, 2], 1.5, atol=1e-12)
    assert (np.abs(y[:, :2]) <= 0.5 + 1e-12).all()
    # far away the faces keep area sampling: the same points as without p
    far = np.tile([0.0, 0.0, -100.0], (n, 1))
    np.testing.assert_array_equal(light.sample(u, far)[0], light.sample(u)[0])


def test_a_point_on_an_emissive_triangle_does_not_sample_its_own_plane_by_zero_over_zero():
    """A camera ray hitting an emissive triangle lights that point by the emissive triangles,
    its own among them: every direction drawn in its solid angle (2 pi, the point is in its
    plane) lies in the plane, cos = 0, and the sample must be dropped without 0 / 0."""
    import warnings

    from rtmesh.scene.model import MeshPart
    parts = [MeshPart("tri", np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]]),
                      np.array([[0, 1, 2]]), 0, None)]
    scene = Scene.from_parts(parts, [Material("lamp", emission=1.0)], [],
                             Camera([0.0, 0.0, 3.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 45.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = render(scene, width=8, height=8)
    assert result.image.max() == pytest.approx(1.0)


@pytest.mark.parametrize("one_normal, two_sided", [(True, False), (False, True), (False, False)])
def test_shadow_segments_kernel_equals_the_numpy_formulation(one_normal, two_sided):
    # the kernel forms in one pass what the estimator formed with NumPy: every number must
    # be the same (dot products summed (x + y) + z, quotients divided, both ends offset as
    # offset_ray_origins offsets them)
    from rtmesh.core.compiled import by_component
    from rtmesh.core.vecmath import dot
    from rtmesh.geometry.accel import offset_ray_origins
    from rtmesh.lights.area_lighting import shadow_segments

    rng = np.random.default_rng(7)
    n = 4000
    p = np.asfortranarray(rng.uniform(-5, 5, (n, 3)))
    ng = np.asfortranarray(rng.normal(size=(n, 3)))
    ng /= np.sqrt(dot(ng, ng))[:, None]
    y = np.asfortranarray(rng.uniform(-5, 5, (n, 3)))
    y[:5] = p[:5]  # samples at the hit: zero distance
    n_light = rng.normal(size=3) if one_normal else np.asfortranarray(rng.normal(size=(n, 3)))
    n_light = n_light / np.linalg.norm(n_light, axis=-1, keepdims=True)
    scale = np.float32(7.5)
    normals_t = n_light.reshape(3, 1).copy() if one_normal else by_component(n_light)
    wi_t, distance2, cos_light, rows, start_t, direction_t, length = shadow_segments(
        by_component(p), by_component(ng), by_component(y), normals_t, two_sided, scale)

    to_light = y - p
    d2 = dot(to_light, to_light)
    distance = np.sqrt(d2)
    wi = to_light / np.where(distance > 0.0, distance, np.inf)[:, None]
    n_rows_all = np.broadcast_to(n_light, (n, 3))
    facing = -dot(wi, np.asfortranarray(n_rows_all))
    cos = np.abs(facing) if two_sided else facing
    expected_rows = np.flatnonzero((cos > 0.0) & (dot(wi, ng) > 0.0))
    start = offset_ray_origins(p[expected_rows], ng[expected_rows], scale=scale, directions=wi[expected_rows])
    toward = np.where(facing > 0.0, 1.0, -1.0)[expected_rows, None]
    target = offset_ray_origins(y[expected_rows], n_rows_all[expected_rows] * toward, scale=scale,
                                directions=-wi[expected_rows])
    segment = target - start
    seg_length = np.sqrt(dot(segment, segment))
    direction = segment / np.where(seg_length > 0.0, seg_length, np.inf)[:, None]

    assert 0 < len(rows) < n
    np.testing.assert_array_equal(wi_t.T, wi)
    np.testing.assert_array_equal(distance2, d2)
    np.testing.assert_array_equal(cos_light, cos)
    np.testing.assert_array_equal(rows, expected_rows)
    np.testing.assert_array_equal(start_t.T, start)
    np.testing.assert_array_equal(direction_t.T, direction)
    np.testing.assert_array_equal(length, seg_length)


@pytest.mark.parametrize("powers", ["uniform", "zeros", "skewed", "tiny_tail", "one"])
def test_area_sample_kernel_chooses_the_faces_numpy_searchsorted_chooses(powers):
    # the guided, galloping search must give np.searchsorted's face for every value, and
    # the point on it the NumPy formulation's, for any spread of powers
    from rtmesh.geometry.accel import barycentric_interpolate
    from rtmesh.lights.mesh_lights import choose_area_samples

    rng = np.random.default_rng(3)
    faces = 1 if powers == "one" else 500
    power = rng.uniform(0.5, 1.5, faces)
    if powers == "zeros":
        power[rng.random(faces) < 0.3] = 0.0
        power[-5:] = 0.0
    elif powers == "skewed":
        power[17] = 1e6
    elif powers == "tiny_tail":
        power[:-1] = 1e-9  # almost every face crowds into the first cell
    cdf = np.cumsum(power)
    total = float(cdf[-1])
    guide = np.searchsorted(cdf, total * (np.arange(faces) / faces), side="right")
    triangles = rng.normal(size=(faces, 9))
    u = rng.random((20000, 2))
    u[:4, 0] = [0.0, np.nextafter(1.0, 0.0), 0.5, cdf[0] / total]  # ends and a CDF step
    face, square_t, b_t, points_t = choose_area_samples(u[:, 0].copy(), u[:, 1].copy(), total, cdf, power, guide,
                                                        np.ascontiguousarray(triangles.T))

    x = u[:, 0] * total
    expected = np.minimum(np.searchsorted(cdf, x, side="right"), faces - 1)
    np.testing.assert_array_equal(face, expected)
    with np.errstate(invalid="ignore", divide="ignore"):
        remapped = np.clip((x - (cdf[expected] - power[expected])) / power[expected], 0.0, np.nextafter(1.0, 0.0))
    np.testing.assert_array_equal(square_t[0], remapped)
    b = square_to_uniform_triangle(np.stack([remapped, u[:, 1]], axis=1))
    np.testing.assert_array_equal(b_t.T, b)
    np.testing.assert_array_equal(points_t.T, barycentric_interpolate(triangles[expected], b[:, 0], b[:, 1]))
