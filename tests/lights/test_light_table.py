"""The path kernel's light table (rtmesh.lights.light_table): a triangle light's sample toward
a point close to it is uniform in the solid angle it subtends, with the density area_pdf
reports; the Whitted integrator's light groups."""

import math

import numba
import numpy as np
import pytest

from rtmesh.lights import light_table as lt
from rtmesh.lights.area_lights import QuadLight
from rtmesh.lights.point_lights import PointLight


def _table(triangles, emission, lights=(), two_sided=False):
    v0, v1, v2 = (np.asarray(t, dtype=float) for t in triangles)
    rows = np.concatenate([v0, v1 - v0, v2 - v0])[None]
    normal = np.cross(v1 - v0, v2 - v0)
    normal /= np.linalg.norm(normal)
    return lt.LightTable(list(lights), rows, normal[None], np.asarray(emission, dtype=float)[None], None, 10.0,
                         two_sided)


@numba.njit
def _samples(light, p, u):
    """lt.sample_area's samples of a triangle light (the path kernel's sample_li):
    direction, distance, pdf, barycentrics, and area_pdf of the sampled direction."""
    out = np.zeros((len(u), 8))
    for i in range(len(u)):
        wx, wy, wz, d, pdf, b1, b2 = lt.sample_area(light, p[0], p[1], p[2], u[i, 0], u[i, 1])
        out[i, 0], out[i, 1], out[i, 2], out[i, 3], out[i, 4], out[i, 5], out[i, 6], out[i, 7] = (
            wx, wy, wz, d, pdf, b1, b2, lt.area_pdf(light, p[0], p[1], p[2], wx, wy, wz, d))
    return out


@numba.njit
def _solid_angle(light, p):
    return lt.triangle_solid_angle(light, p[0], p[1], p[2])


@pytest.mark.parametrize("height", [0.02, 0.3, 100.0])
def test_a_triangle_lights_a_point_with_its_analytic_irradiance(height):
    """Irradiance at a point under a triangle light (facing it, normal straight up) by the
    samples' estimate ``L cos / pdf`` against the closed form (Lambert's polygon formula);
    near the triangle the samples are uniform in solid angle (pdf 1 / omega, what area_pdf
    says), far away uniform by area, and the estimate is unbiased either way."""
    corners = [[-1.0, -1.0, 0.0], [2.0, -0.5, 0.0], [0.0, 1.5, 0.0]]
    table = _table(corners[::-1], [3.0, 3.0, 3.0])  # wound to face down (-z), toward the point
    p = np.array([0.1, 0.05, -height])
    u = np.random.default_rng(5).random((200_000, 2))
    s = _samples(table.rows[0], p, u)
    ok = s[:, 4] > 0
    assert ok.mean() > 0.99
    np.testing.assert_allclose(s[ok, 4], s[ok, 7], rtol=1e-12)  # the sample's pdf is area_pdf's
    omega = _solid_angle(table.rows[0], p)
    if lt.SOLID_ANGLE_FROM < omega < lt.SOLID_ANGLE_TO:
        np.testing.assert_allclose(s[ok, 4], 1.0 / omega, rtol=1e-12)
    estimate = np.where(ok, 3.0 * np.maximum(s[:, 2], 0.0) / np.where(ok, s[:, 4], 1.0), 0.0)
    # Lambert: E = L / 2 sum over edges of (angle subtended) x (cos of the edge plane's normal with n)
    v = [np.asarray(c) - p for c in corners]
    exact = 0.0
    for i in range(3):
        a, b = v[i], v[(i + 1) % 3]
        gamma = math.acos(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b))
        n_edge = np.cross(a, b)
        exact += gamma * n_edge[2] / np.linalg.norm(n_edge)
    exact = abs(3.0 * exact / 2.0)
    mean, error = estimate.mean(), estimate.std() / math.sqrt(len(estimate))
    assert abs(mean - exact) < 4 * error + 1e-9 * exact


def test_solid_angle_samples_carry_their_barycentrics():
    """The barycentric weights of a solid-angle sample are the point's (textured emitters)."""
    corners = np.array([[-1.0, -1.0, 0.0], [2.0, -0.5, 0.0], [0.0, 1.5, 0.0]])
    table = _table(corners[::-1], [1.0, 1.0, 1.0])
    p = np.array([0.2, 0.1, -0.05])
    s = _samples(table.rows[0], p, np.random.default_rng(6).random((500, 2)))
    row = table.rows[0]
    points = p + s[:, :3] * s[:, 3:4]
    rebuilt = row[1:4] + s[:, 5:6] * row[10:13] + s[:, 6:7] * row[13:16]
    np.testing.assert_allclose(rebuilt, points, atol=1e-9)


def test_one_sided_triangles_are_dark_from_behind_unless_two_sided():
    corners = [[-1.0, -1.0, 0.0], [2.0, -0.5, 0.0], [0.0, 1.5, 0.0]]
    p = np.array([0.1, 0.05, 0.05])  # above: behind a triangle facing down
    u = np.random.default_rng(7).random((100, 2))
    one = _table(corners[::-1], [1.0, 1.0, 1.0])
    two = _table(corners[::-1], [1.0, 1.0, 1.0], two_sided=True)
    assert (_samples(one.rows[0], p, u)[:, 4] == 0).all()
    assert (_samples(two.rows[0], p, u)[:, 4] > 0).all()


def test_light_groups_take_delta_lights_once_and_emitters_as_one_light():
    corners = [[-1.0, -1.0, 0.0], [2.0, -0.5, 0.0], [0.0, 1.5, 0.0]]
    quad = QuadLight(np.array([0.0, 2.0, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([2.0, 2.0, 2.0]))
    point = PointLight(np.array([0.0, 3.0, 0.0]), np.array([5.0, 5.0, 5.0]))
    table = _table(corners, [1.0, 1.0, 1.0], lights=(quad, point))
    delta_rows, start, order, probability, alias, pmf = table.light_groups()
    kinds = table.rows[:, 0]
    assert len(delta_rows) == 1 and kinds[delta_rows[0]] < lt.QUAD
    assert len(start) == 3  # the quad, the triangles
    assert sorted(order.tolist()) == sorted(set(range(len(table.rows))) - set(delta_rows.tolist()))
    for g in range(len(start) - 1):
        rows = order[start[g]:start[g + 1]]
        assert pmf[rows].sum() == pytest.approx(1.0)
    assert pmf[delta_rows].sum() == 0.0
