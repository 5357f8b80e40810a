"""The light tree (rtmesh.lights.light_tree): the probability a walk picks a light is the
probability light_pmf() retraces, every light that can light a point can be picked there,
the importance is pbrt-v4's formula, and merged cones hold their children's."""

import math

import numpy as np
import pytest

from rtmesh.lights import light_table as lt
from rtmesh.lights import light_tree
from rtmesh.lights import point_light_rows as plr


def _rows(seed=0, triangles=40):
    """A point, a spot, a one-sided quad, a two-sided disk, emissive triangles of random
    orientation and, optionally, the environment."""
    rng = np.random.default_rng(seed)
    rows = []

    def row(kind, a, b, c, d, e, two_sided=0.0):
        r = np.zeros(lt.WIDTH)
        r[0], r[1:4], r[4:7], r[7:10], r[10:13], r[13:16] = kind, a, b, c, d, e
        r[lt.TWO_SIDED] = two_sided
        return r

    point = np.zeros(lt.WIDTH)
    point[:12] = plr.pack_row(plr.POINT, position=(0.0, 3.0, 0.0), power=(5.0, 5.0, 5.0))
    spot = np.zeros(lt.WIDTH)
    spot[:12] = plr.pack_row(plr.SPOT, position=(2.0, 2.0, 0.0), direction=(0.0, -1.0, 0.0), power=(9.0, 9.0, 9.0),
                             cos_inner=math.cos(0.3), cos_outer=math.cos(0.5))
    rows += [point, spot,
             row(lt.QUAD, (-1.0, 2.5, -1.0), (0.0, -1.0, 0.0), (4.0, 4.0, 4.0), (2.0, 0.0, 0.0), (0.0, 0.0, 2.0)),
             row(lt.DISK, (-3.0, 1.0, 1.0), (1.0, 0.0, 0.0), (2.0, 2.0, 2.0), (0.0, 0.5, 0.0), (0.0, 0.0, 0.5), 1.0)]
    for _ in range(triangles):
        v0 = rng.uniform(-4, 4, 3)
        e1, e2 = rng.normal(size=3) * 0.3, rng.normal(size=3) * 0.3
        n = np.cross(e1, e2)
        rows.append(row(lt.TRIANGLE, v0, n / np.linalg.norm(n), rng.uniform(0.5, 3.0, 3), e1, e2))
    rows.append(row(lt.ENVIRONMENT, 0, 0, 0, 0, 0, 1.0))
    rows = np.array(rows)
    power = rng.uniform(0.5, 5.0, len(rows))
    return rows, power


@pytest.fixture(scope="module")
def tree():
    rows, power = _rows()
    return light_tree.LightTree(rows, power), rows


def _points(n, seed=1):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-5, 5, (n, 3))
    normals = rng.normal(size=(n, 3))
    return points, normals / np.linalg.norm(normals, axis=1, keepdims=True)


def test_the_walk_picks_each_light_with_the_probability_its_trail_gives(tree):
    """For fixed points, stratified numbers u: each light's share of the u interval is its
    light_pmf() (to the grid's resolution), and choose_light() returns that same pmf."""
    t, rows = tree
    points, normals = _points(6)
    m = 100000
    u = (np.arange(m) + 0.5) / m
    for p, n in zip(points, normals):
        lights, pmfs = light_tree.choose_lights(t.record, np.tile(p, (m, 1)), np.tile(n, (m, 1)), u)
        every = np.arange(len(rows))
        expected = light_tree.light_pmfs(t.record, every, np.tile(p, (len(rows), 1)), np.tile(n, (len(rows), 1)))
        picked = lights >= 0
        np.testing.assert_allclose(pmfs[picked], expected[lights[picked]], rtol=1e-12)
        frequency = np.bincount(lights[picked], minlength=len(rows)) / m
        np.testing.assert_allclose(frequency, expected, atol=3e-4)
        # what is not picked is the share no light can reach
        assert abs((1.0 - picked.mean()) - (1.0 - expected.sum())) < 3e-4
        assert expected.sum() <= 1.0 + 1e-12


def test_every_light_that_reaches_a_point_can_be_picked_there(tree):
    """Conservative bounds: a light facing the point (or two-sided, or a point light) has a
    positive probability; the one-sided quad seen from behind has none."""
    t, rows = tree
    quad = 2
    front = np.array([[0.0, 0.0, 0.0]])      # below the quad, which faces down
    behind = np.array([[0.0, 4.0, 0.0]])     # above it
    up = np.array([[0.0, 1.0, 0.0]])
    assert light_tree.light_pmfs(t.record, np.array([quad]), front, up)[0] > 0.0
    assert light_tree.light_pmfs(t.record, np.array([quad]), behind, -up)[0] == 0.0
    points, normals = _points(200, seed=3)
    for light in (0, 1):  # the point light everywhere; the spot inside its cone
        p = light_tree.light_pmfs(t.record, np.full(len(points), light), points, normals)
        if light == 0:
            assert (p > 0.0).all()
    below_spot = np.array([[2.0, -1.0, 0.0]])
    assert light_tree.light_pmfs(t.record, np.array([1]), below_spot, up)[0] > 0.0
    # triangles: facing the point from in front -> positive
    for k in range(4, len(rows) - 1):
        centre = rows[k, 1:4] + (rows[k, 10:13] + rows[k, 13:16]) / 3.0
        p = centre + 0.5 * rows[k, 4:7]
        assert light_tree.light_pmfs(t.record, np.array([k]), p[None], rows[k, 4:7][None])[0] > 0.0


def test_lights_at_infinity_share_k_over_k_plus_one():
    rows, power = _rows(triangles=3)
    t = light_tree.LightTree(rows, power)
    environment = len(rows) - 1
    p = light_tree.light_pmfs(t.record, np.array([environment]), np.zeros((1, 3)), np.array([[0.0, 1.0, 0.0]]))
    assert p[0] == pytest.approx(0.5)
    only_far = light_tree.LightTree(rows[environment:], power[environment:])
    assert light_tree.light_pmfs(only_far.record, np.array([0]), np.zeros((1, 3)), np.zeros((1, 3)))[0] == 1.0


def _importance_reference(low, high, phi, w, cos_o, cos_e, two_sided, p, n):
    """pbrt-v4's LightBounds::Importance, written out in Python."""
    pc = (low + high) / 2
    d2 = float(np.dot(p - pc, p - pc))
    d2c = max(d2, np.linalg.norm(high - low) / 2)
    wi = (p - pc) / math.sqrt(d2)
    cos_w = float(np.dot(w, wi))
    if two_sided:
        cos_w = abs(cos_w)
    theta_w = math.acos(min(max(cos_w, -1), 1))
    r2 = np.dot(high - low, high - low) / 4
    theta_b = math.pi if d2 < r2 else math.asin(math.sqrt(r2 / d2))
    theta_o = math.acos(cos_o)
    theta_p = max(max(theta_w - theta_o, 0.0) - theta_b, 0.0)
    if math.cos(theta_p) <= cos_e:
        return 0.0
    value = phi * math.cos(theta_p) / d2c
    theta_i = math.acos(min(abs(float(np.dot(wi, n))), 1.0))
    return value * math.cos(max(theta_i - theta_b, 0.0))


def test_importance_is_pbrts_formula(tree):
    t, _ = tree
    nodes, links = t.record[0], t.record[1]
    points, normals = _points(30, seed=7)
    for i in range(0, len(nodes), 7):
        node = nodes[i]
        values = light_tree.importances(t.record, i, points, normals)
        for p, n, value in zip(points, normals, values):
            reference = _importance_reference(node[0:3], node[3:6], node[6], node[7:10], node[10], node[11],
                                              bool(links[i, 1] & light_tree.TWO_SIDED), p, n)
            assert value == pytest.approx(reference, rel=1e-9, abs=1e-12)


def test_a_parents_cone_holds_its_childrens(tree):
    t, _ = tree
    nodes, links = t.record[0], t.record[1]
    for i in range(len(nodes)):
        if links[i, 1] & light_tree.LEAF:
            continue
        parent = math.acos(min(max(nodes[i, 10], -1.0), 1.0))
        for child in (i + 1, links[i, 0]):
            spread = math.acos(min(max(nodes[child, 10], -1.0), 1.0))
            between = math.acos(min(max(float(np.dot(nodes[i, 7:10], nodes[child, 7:10])), -1.0), 1.0))
            assert parent >= min(between + spread, math.pi) - 1e-7  # (acos of a cosine near 1)
            assert (nodes[i, 0:3] <= nodes[child, 0:3]).all() and (nodes[i, 3:6] >= nodes[child, 3:6]).all()
        assert nodes[i, 6] == pytest.approx(nodes[i + 1, 6] + nodes[links[i, 0], 6])
