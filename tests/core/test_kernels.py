"""The compiled kernels (surfaces, lights, Blinn-Phong, direct light, camera rays, film sums)
against small scalar references written from the formulas, row by row in plain Python."""

import math

import numpy as np
import pytest

from rtmesh.core.compiled import by_component, kernel
from rtmesh.core.row_vectors import floor_quotient
from rtmesh.geometry.accel import offset_ray_origins
from rtmesh.lights.point_light_rows import illuminate_row, point_row
from rtmesh.lights.point_lights import DirectionalLight, PointLight, SpotLight
from rtmesh.rendering import film_sums
from rtmesh.sampling.pixel_samples import stratum_of
from rtmesh.scene import camera_rays
from rtmesh.shading import direct_light, surfaces
from rtmesh.shading.surfaces import face_viewer


def unit_rows(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1)[:, None]


def light_sample_inputs(illuminated, *records):
    """The first seven arguments of light_samples: a light's ``illuminate()`` result and the
    surface records (points, normals, directions), vectors by component."""
    wi, distance, incident = illuminated
    return (by_component(wi), distance, by_component(incident), *(by_component(r) for r in records))


def scalar_light(light, p):
    """Direction, distance and incident term of a light at one point, from the formulas."""
    if isinstance(light, DirectionalLight):
        return -light.direction, math.inf, light.irradiance
    to = light.position - p
    d = math.sqrt(float(to @ to))
    wi = to / d
    e = light.intensity / (d * d)
    if isinstance(light, SpotLight):
        cos_angle = -float(wi @ light.direction)
        lo, hi = math.cos(math.radians(light.outer_angle)), math.cos(math.radians(light.inner_angle))
        x = min(max((cos_angle - lo) / (hi - lo), 0.0), 1.0)
        e = light.intensity * (x * x * (3 - 2 * x) / (d * d))
    return wi, d, e


def scalar_blinn_phong(ns, wo, wi, kd, ks, shininess):
    cos_i = float(ns @ wi)
    value = kd * max(cos_i, 0.0)
    if shininess >= 0 and cos_i > 0:
        h = wo + wi
        value = value + ks * max(float(ns @ h) / math.sqrt(float(h @ h)), 0.0) ** shininess
    return value


@pytest.mark.parametrize("light", [
    PointLight([0.3, -0.2, 2.0], [40.0, 20.0, 10.0]),
    DirectionalLight([0.2, 0.1, -1.0], [2.0, 1.0, 0.5]),
    SpotLight([0.0, 0.0, 3.0], [0.1, 0.0, -1.0], [30.0, 30.0, 30.0], 15.0, 40.0),
])
def test_light_samples_match_the_scalar_formulas(light):
    rng = np.random.default_rng(7)
    n = 400
    p = np.asfortranarray(rng.uniform(-1, 1, size=(n, 3)))
    ng = np.asfortranarray(unit_rows(rng, n))
    # shading normals near the geometric ones; view directions from the normals' side
    ns = unit_rows(rng, n) * 0.3 + ng
    ns = np.asfortranarray(ns / np.linalg.norm(ns, axis=1)[:, None])
    d = np.asfortranarray(-unit_rows(rng, n) * 0.2 - ng)
    d /= np.linalg.norm(d, axis=1)[:, None]
    mat = rng.integers(0, 3, n).astype(np.intp)
    diffuse = np.array([[0.7, 0.5, 0.3], [0.2, 0.8, 0.4], [0.9, 0.9, 0.9]])
    specular = np.array([[0.3, 0.3, 0.3], [0.0, 0.0, 0.0], [0.5, 0.2, 0.1]])
    exponent = np.array([50.0, -1.0, 7.5])  # the middle material has no highlight
    tint = rng.uniform(0.2, 1.0, size=(n, 3))
    (lit, origins, directions, t_max, cos_i, incident, highlight_rows, highlight,
     power_exponent) = direct_light.light_samples(*light_sample_inputs(light.illuminate(p), p, ng, ns, d), mat, exponent,
                                                  direct_light.highlight_thresholds(exponent), np.float32(2.0),
                                                  1.0 - 1e-5)
    # the Blinn-Phong term goes to the rows whose shadow rays are clear
    occluded = np.zeros(len(lit), dtype=bool)
    occluded[::5] = True
    total = np.zeros((n, 3))
    direct_light.add_light(by_component(total), lit, lit, occluded, cos_i, incident, highlight_rows,
                           np.power(highlight, power_exponent), mat, diffuse, tint, specular, np.zeros((0, 3)))
    expected_lit = []
    expected_total = np.zeros((n, 3))
    for i in range(n):
        wi, dist, e = scalar_light(light, p[i])
        if not (wi @ ng[i] > 0 and (e > 0).any()):
            continue
        expected_lit.append(i)
        j = len(expected_lit) - 1
        if j % 5:
            expected_total[i] = e * scalar_blinn_phong(ns[i], -d[i], wi, diffuse[mat[i]] * tint[i],
                                                       specular[mat[i]], exponent[mat[i]])
        np.testing.assert_allclose(directions[j], wi.astype(np.float32), rtol=1e-7)
        assert t_max[j] == np.float32(min(dist * (1.0 - 1e-5), np.finfo(np.float32).max))
    np.testing.assert_array_equal(lit, expected_lit)
    np.testing.assert_allclose(total, expected_total, rtol=1e-12, atol=1e-300)
    assert 0 < len(lit) < n  # both branches exercised
    assert 0 < len(highlight_rows) < len(lit)
    # the shadow-ray origins are the offset every spawned ray gets
    np.testing.assert_array_equal(
        origins, offset_ray_origins(p[lit], ng[lit], np.float32, 2.0, directions.astype(np.float64)))


def test_a_batch_of_one_row_calls_the_kernels_a_batch_of_many_compiled():
    """Component-major vectors go to kernels by component, (3, n) C order for every n: a
    one-row batch, which NumPy marks both C- and F-contiguous, must not compile them again
    (it did, 0.2-1.3 s each, in the one-ray tails of scenes with reflections)."""
    from rtmesh.lights import point_light_rows

    rng = np.random.default_rng(6)
    light = PointLight([0.0, 0.0, 3.0], [1.0, 1.0, 1.0])
    exponent = np.array([10.0])
    kernels = (point_light_rows.illuminate, direct_light.light_samples)

    def shade(n):
        p, ng, d = (np.asfortranarray(a) for a in (rng.normal(size=(n, 3)), unit_rows(rng, n), unit_rows(rng, n)))
        direct_light.light_samples(*light_sample_inputs(light.illuminate(p), p, ng, ng, d), np.zeros(n, np.intp),
                                   exponent, direct_light.highlight_thresholds(exponent), np.float32(1.0), 1.0)

    shade(5)
    compiled = [set(k.signatures) for k in kernels]
    shade(1)
    assert [set(k.signatures) for k in kernels] == compiled


def test_light_kernel_and_illuminate_agree():
    """lights' illuminate() (the public form) runs the same row arithmetic."""
    rng = np.random.default_rng(1)
    light = SpotLight([0.0, 0.0, 3.0], [0.0, 0.2, -1.0], [5.0, 6.0, 7.0], 10.0, 35.0)
    points = rng.uniform(-2, 2, size=(200, 3))
    wi, distance, incident = light.illuminate(points)
    for i in range(len(points)):
        w, dist, e = scalar_light(light, points[i])
        np.testing.assert_allclose(wi[i], w, rtol=1e-12)
        assert distance[i] == pytest.approx(dist, rel=1e-12)
        np.testing.assert_allclose(incident[i], e, rtol=1e-12, atol=1e-300)


def test_surface_records_match_the_formulas():
    rng = np.random.default_rng(3)
    n_faces, n = 50, 500
    v0, e1, e2 = rng.normal(size=(3, n_faces, 3))
    normal = np.cross(e1, e2)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    faces = np.ascontiguousarray(np.concatenate([v0, e1, e2, normal], axis=1))
    n0 = normal + 0.2 * rng.normal(size=(n_faces, 3))
    dn1, dn2 = 0.2 * rng.normal(size=(2, n_faces, 3))
    vertex_normals = np.ascontiguousarray(np.concatenate([n0, dn1, dn2], axis=1))
    smooth = rng.uniform(size=n_faces) < 0.7
    material_id = rng.integers(0, 4, n_faces).astype(np.intp)
    prim = rng.integers(-1, n_faces, 2 * n).astype(np.int32)
    u, v = rng.uniform(0, 0.5, size=(2, 2 * n))
    directions = np.asfortranarray(unit_rows(rng, 2 * n))
    rows = np.flatnonzero(prim >= 0)
    for fix in (False, True):
        p, ng, ns, front, mat = surfaces.surface_records(prim, u, v, rows, by_component(directions), np.zeros((0, 3)), faces,
                                                        vertex_normals, smooth, material_id, fix)
        f, a, b, dr = prim[rows], u[rows], v[rows], directions[rows]
        np.testing.assert_allclose(p, v0[f] + a[:, None] * e1[f] + b[:, None] * e2[f], rtol=1e-12, atol=1e-12)
        sign = np.where((dr * normal[f]).sum(axis=1) < 0, 1.0, -1.0)
        np.testing.assert_array_equal(front, sign > 0)
        np.testing.assert_array_equal(ng, normal[f] * sign[:, None])
        np.testing.assert_array_equal(mat, material_id[f])
        interpolated = n0[f] + a[:, None] * dn1[f] + b[:, None] * dn2[f]
        interpolated /= np.linalg.norm(interpolated, axis=1)[:, None]
        expected = np.where(smooth[f][:, None], interpolated * sign[:, None], ng)
        if fix:
            expected = face_viewer(expected, ng, dr)
        np.testing.assert_allclose(ns, expected, rtol=1e-12, atol=1e-15)


def test_face_viewer_is_a_no_op_on_normals_that_face_the_viewer():
    ng = np.tile([0.0, 0.0, 1.0], (3, 1))
    d = np.array([[0.0, 0.6, -0.8], [0.0, 0.0, -1.0], [0.6, 0.0, -0.8]])
    ns = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, 0.6, 0.8]])
    np.testing.assert_array_equal(face_viewer(ns, ng, d), ns)


def test_pinhole_and_thin_lens_camera_rays():
    rng = np.random.default_rng(5)
    n = 300
    film = rng.uniform(0, 64, size=(n, 2))
    forward, right, up = np.eye(3)[[2, 0, 1]]
    position = np.array([1.0, 2.0, 3.0])
    plane = np.array([0.02, -0.64, -0.02, 0.64])
    whole_film = np.zeros(0, np.int64)
    origins, d = camera_rays.camera_rays(film, whole_film, 64, np.zeros((0, 2)), position, forward, right, up,
                                     plane, 5.0)
    assert origins.shape == (0, 3)
    sx, sy = film[:, 0] * plane[0] + plane[1], film[:, 1] * plane[2] + plane[3]
    expected = forward + sx[:, None] * right + sy[:, None] * up
    np.testing.assert_allclose(d, expected / np.linalg.norm(expected, axis=1)[:, None], rtol=1e-14)
    # the same rays from pixel indices and positions inside the pixels
    pixels = np.floor(film[:, 1]).astype(np.int64) * 64 + np.floor(film[:, 0]).astype(np.int64)
    _, d_pixels = camera_rays.camera_rays(film - np.floor(film), pixels, 64, np.zeros((0, 2)), position, forward,
                                      right, up, plane, 5.0)
    np.testing.assert_allclose(d_pixels, d, rtol=1e-13)
    # thin lens: every ray through a film point meets the pinhole ray on the plane of focus
    disk = rng.uniform(-0.1, 0.1, size=(n, 2))
    origins, d_lens = camera_rays.camera_rays(film, whole_film, 64, disk, position, forward, right, up, plane, 5.0)
    np.testing.assert_allclose(origins, position + disk[:, :1] * right + disk[:, 1:] * up, rtol=1e-14)
    t = 5.0 / (d_lens @ forward)
    np.testing.assert_allclose(origins + t[:, None] * d_lens, position + 5.0 * expected, rtol=1e-12)


def test_film_sums_and_means():
    rng = np.random.default_rng(2)
    total, total_sq = np.zeros((10, 3), order="F"), np.zeros((10, 3), order="F")
    radiance = rng.uniform(size=(4, 3, 3))
    pixels = np.array([7, 2, 5, 0])
    count = np.zeros(10, np.int64)
    count[pixels[:2]] = 1  # these two had a sample of 0 already, the others none (sums start at 0)
    film_sums.accumulate_samples(total.T, total_sq.T, count, pixels, radiance, np.zeros((0, 3), np.float32))
    np.testing.assert_allclose(total[pixels], radiance.sum(axis=1), rtol=1e-15)
    np.testing.assert_allclose(total_sq[pixels], (radiance ** 2).sum(axis=1), rtol=1e-15)
    count[pixels] += 3
    means = np.full((10, 3), np.nan, dtype=np.float32)
    film_sums.mean_image(total, count, means)
    assert means.dtype == np.float32
    np.testing.assert_allclose(means[pixels], radiance.sum(axis=1) / [[4], [4], [3], [3]], rtol=1e-7)
    assert not means[[1, 3, 4, 6, 8, 9]].any()  # no samples: 0
    # the means written with the sums are mean_image's, bit for bit; other pixels untouched
    count[pixels] -= 3
    again = np.full((10, 3), -1.0, dtype=np.float32)
    film_sums.accumulate_samples(np.zeros((3, 10)), np.zeros((3, 10)), count, pixels, radiance, again)
    np.testing.assert_array_equal(again[pixels], means[pixels])
    assert (np.delete(again, pixels, axis=0) == -1).all()


@pytest.mark.parametrize("width", [1, 3, 640, 3840, 65535])
def test_camera_rays_find_the_row_and_column_of_every_pixel_index(width):
    """The kernel splits pixel indices into rows and columns without integer division:
    check the rows' first and last pixels and random ones."""
    rng = np.random.default_rng(width)
    rows = np.arange(1, 60)
    pixels = np.unique(np.concatenate([rows * width, rows * width - 1, rng.integers(0, width * 70000, 2000)]))
    # image plane (1, 0, 1, 0): sx is the film x, sy the film y, direction ~ (sx, sy, 1)
    _, d = camera_rays.camera_rays(np.zeros((len(pixels), 2)), pixels, width, np.zeros((0, 2)), np.zeros(3),
                               np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]),
                               np.array([1.0, 0.0, 1.0, 0.0]), 1.0)
    np.testing.assert_allclose(d[:, 0] / d[:, 2], pixels % width, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(d[:, 1] / d[:, 2], pixels // width, rtol=1e-12, atol=1e-9)


@kernel
def _point_light_both_ways(light, points):
    out = np.empty((2, len(points), 7))
    for i in range(len(points)):
        out[0, i] = illuminate_row(light, points[i, 0], points[i, 1], points[i, 2])
        out[1, i] = point_row(light, points[i, 0], points[i, 1], points[i, 2])
    return out


def test_the_point_light_row_is_the_general_row_of_a_point_light_to_the_bit():
    """The fused stage's point-light loop (point_row) forms what illuminate_row forms for
    a point light, the point at the light itself included (direction and term 0)."""
    light = PointLight([0.5, -1.0, 3.0], [5.0, 6.0, 7.0])
    points = np.random.default_rng(3).uniform(-4, 4, size=(500, 3))
    points[7] = light.position
    general, point = _point_light_both_ways(light.kernel_row(), points)
    np.testing.assert_array_equal(point, general)
    assert (point[7, [0, 1, 2, 4, 5, 6]] == 0).all()


@kernel
def _quotients(values, divisor):
    out = np.empty((2, len(values)), np.int64)
    inverse = 1.0 / divisor
    for i in range(len(values)):
        out[0, i] = floor_quotient(values[i], divisor, inverse)
        out[1, i] = stratum_of(np.uint64(values[i]), divisor, inverse)
    return out


@pytest.mark.parametrize("divisor", [1, 3, 16, 17, 1000, 65535, 2 ** 20])
def test_quotients_without_integer_division_are_exact(divisor):
    """floor_quotient (a pixel's row) and stratum_of (a sample's stratum) are ``//`` and ``%``
    by a float product and a one-step correction: exact up to the largest indices rtmesh
    allows (sides up to 2^20, so pixels and samples below 2^40)."""
    rng = np.random.default_rng(divisor)
    multiples = np.arange(0, 2 ** 40 // divisor, max(1, 2 ** 40 // divisor // 5000), dtype=np.int64) * divisor
    values = np.unique(np.concatenate([multiples, multiples + divisor - 1, rng.integers(0, 2 ** 40, 5000)]))
    values = values[values >= 0]
    row, stratum = _quotients(values, divisor)
    np.testing.assert_array_equal(row, values // divisor)
    np.testing.assert_array_equal(stratum, values % divisor)


def test_highlight_powers_below_float64_range_are_dropped_and_shininess_zero_is_one():
    exponent = np.array([5000.0, 0.0, -1.0])
    threshold = direct_light.highlight_thresholds(exponent)
    assert threshold[0] ** 5000.0 == pytest.approx(2.0 ** -1000, rel=1e-9)
    assert threshold[1] == 0.0 and threshold[2] == np.inf
    # one point, light straight above, viewer at grazing angles: highlight cosines from ~1 to ~0
    n = 64
    angles = np.linspace(0.0, 1.55, n)
    d = np.asfortranarray(np.column_stack([np.sin(angles), np.zeros(n), -np.cos(angles)]))
    p = np.zeros((n, 3), order="F")
    up = np.asfortranarray(np.tile([0.0, 0.0, 1.0], (n, 1)))
    light = PointLight([0.0, 0.0, 1.0], [1.0, 1.0, 1.0]).illuminate(p)
    for m in range(3):
        mat = np.full(n, m, dtype=np.intp)
        lit, *_, cos_i, incident, rows, highlight, power_exponent = direct_light.light_samples(
            *light_sample_inputs(light, p, up, up, d), mat, exponent, threshold, np.float32(1.0), 1.0)
        assert len(lit) == n
        if m == 0:
            assert (highlight ** 5000.0 >= 2.0 ** -1000).all() and 0 < len(rows) < n
        elif m == 1:
            np.testing.assert_array_equal(rows, np.arange(n))  # every lit row: power 1
            np.testing.assert_array_equal(highlight ** power_exponent, 1.0)
        else:
            assert not len(rows)



def test_kernels_compile_without_a_writable_cache_directory():
    """A function numba cannot cache (here: its source file does not exist, as for a
    read-only install with a read-only home, where numba finds no cache locator) is
    compiled uncached instead of failing at import."""
    namespace = {}
    exec("def twice(x):\n    return 2.0 * x\n", namespace)  # source file "<string>"
    import numba
    with pytest.raises(RuntimeError, match="cannot cache"):
        numba.njit(cache=True)(namespace["twice"])
    twice = kernel(namespace["twice"])
    assert twice(1.5) == 3.0


def test_add_rows_adds_into_the_given_rows_only():
    rng = np.random.default_rng(5)
    target = np.asfortranarray(rng.uniform(size=(9, 3)))
    rows, values = np.array([8, 0, 4]), rng.uniform(size=(3, 3))
    expected = target.copy()
    expected[rows] += values
    film_sums.add_rows(by_component(target), rows, by_component(np.asfortranarray(values)))
    np.testing.assert_array_equal(target, expected)


@pytest.mark.parametrize("display", [False, True])
def test_pixel_errors_equal_the_numpy_expressions(display):
    """The compiled per-pixel error equals the film's former NumPy expressions bit for bit,
    over pixels with 0, 1 and more samples, zero sums and NaN-free noise."""
    rng = np.random.default_rng(1)
    n = 5000
    count = rng.integers(0, 6, n)
    total = rng.exponential(1.0, (n, 3)) * count[:, None]
    total_sq = total ** 2 / np.maximum(count, 1)[:, None] * rng.uniform(0.5, 2.0, (n, 3))
    total[::7] = total_sq[::7] = 0.0
    floor = 0.01
    nf = count[:, None].astype(np.float64)
    mean = total / np.maximum(nf, 1)
    var = (total_sq - nf * mean * mean) / np.maximum(nf - 1, 1)
    std_err = np.sqrt(np.where(nf > 1, np.maximum(var, 0.0), 0.0) / np.maximum(nf, 1))
    scale = np.abs(mean) + floor
    expected = np.where(count >= 2, np.mean(std_err / (np.sqrt(scale) if display else scale), axis=1), np.nan)
    got = film_sums.pixel_errors(np.asfortranarray(total), np.asfortranarray(total_sq), count, 0, n, floor, display)
    np.testing.assert_array_equal(got, expected)
