"""A light's choice by its importance at the shading point: a bounding volume hierarchy over
the lights (pbrt-v4's ``BVHLightSampler``, after Conty Estevez & Kulla 2018).

The power alias table (:class:`rtmesh.lights.light_table.LightTable`) picks a light by its
power alone: of an emissive mesh's faces the one behind the mesh, or a lamp across the
building, as often as the one facing the point.  The tree picks by an estimate of each
light's contribution at the point instead: every node bounds its lights' positions (a box),
their emission directions (a cone of axis ``w`` and spread ``theta_o``, widened by the
emission falloff ``theta_e``) and their summed power ``phi``; a walk from the root picks a
child in proportion to :func:`importance` (power over squared distance, times the best
cosines the bounds allow at the emitter and at the receiving surface) until it reaches a
light.  The probability of a light is the product of the child choices on its path, which
:func:`light_pmf` retraces from the light's bit trail (for the weights of multiple
importance sampling when a path meets the light by BSDF sampling).

Lights at infinity (directional lights, the environment) are not in the tree: they are
chosen with probability ``k / (k + 1)`` among ``k`` of them, uniformly (pbrt's rule), the
tree with the rest.

The tree is balanced: the lights are sorted along a Morton curve of their bounds' centres
and every node splits its range in the middle, so that node ``i`` over ``[lo, hi)`` has its
children at ``i + 1`` and ``i + 2 (mid - lo)`` and no pointer table is needed (pbrt splits by
a surface-area-orientation cost; the Morton order keeps a build of millions of placed
emitter faces linear after the sort).

Records
-------
``tree = (nodes, links, trails, infinite)``:

* ``nodes`` (N, NODE_WIDTH) float64: box min (0-2) and max (3-5), ``phi`` (6), cone axis
  ``w`` (7-9), ``cos theta_o`` (10), ``cos theta_e`` (11), and what the walk derives from
  them: the box's centre (12-14), half its diagonal (15), ``sin theta_o`` (16);
* ``links`` (N, 2) int64: a leaf's light row or an interior node's second child (0), flags
  (1: :data:`LEAF`, :data:`TWO_SIDED`);
* ``trails`` (L,) uint64: each light's path from the root, a bit a level (0 first child),
  from the lowest bit; lights outside the tree have :data:`NOT_IN_TREE`;
* ``infinite`` (k,) int64: the light rows at infinity.
"""

import math

import numpy as np

from rtmesh.core.compiled import kernel, row
from rtmesh.lights import light_table as lt
from rtmesh.lights import point_light_rows as plr

NODE_WIDTH = 17
BOX, PHI, AXIS, COS_O, COS_E = 0, 6, 7, 10, 11
# derived for the walk: the box's centre, half its diagonal, sin theta_o
CENTRE, HALF_DIAGONAL, SIN_O = 12, 15, 16
LEAF, TWO_SIDED = 1, 2
NOT_IN_TREE = np.uint64(0xFFFFFFFFFFFFFFFF)
# the largest number below 1, for the remapped sample number (pbrt's OneMinusEpsilon)
_BELOW_ONE = 1.0 - 2.0 ** -53
# the record of no tree (lights chosen by power): no trails
NO_TREE = (np.zeros((0, NODE_WIDTH)), np.zeros((0, 2), np.int64), np.zeros(0, np.uint64), np.zeros(0, np.int64))


def light_bounds(rows, power):
    """Each bounded light's box, cone and power, and which lights are at infinity.

    Parameters
    ----------
    rows : (L, WIDTH) float64
        :attr:`rtmesh.lights.light_table.LightTable.rows`.
    power : (L,) float64
        Each light's power (what the power alias table weighs it by).

    Returns
    -------
    bounded : (B,) int64
        The rows of the lights with a position.
    nodes : (B, NODE_WIDTH) float64
        Their bounds, as leaves.
    two_sided : (B,) bool
    infinite : (k,) int64
        The rows of directional lights and the environment.
    """
    kinds = rows[:, 0].astype(np.int64) if len(rows) else np.zeros(0, np.int64)
    far = (kinds == plr.DIRECTIONAL) | (kinds == lt.ENVIRONMENT)
    bounded = np.flatnonzero(~far)
    r, k = rows[bounded], kinds[bounded]
    nodes = np.zeros((len(bounded), NODE_WIDTH))
    nodes[:, PHI] = np.maximum(power[bounded], 0.0)
    # points, spots and projectors: a point; every direction, or a spot's cone
    point = (k == plr.POINT) | (k == plr.SPOT) | (k == lt.PROJECTOR)
    nodes[point, BOX:BOX + 3] = r[point, plr.POSITION:plr.POSITION + 3]
    nodes[point, BOX + 3:BOX + 6] = r[point, plr.POSITION:plr.POSITION + 3]
    nodes[point, AXIS + 2] = 1.0
    nodes[point, COS_O], nodes[point, COS_E] = -1.0, 0.0
    spot = k == plr.SPOT
    if spot.any():
        axis = r[spot, plr.DIRECTION:plr.DIRECTION + 3]
        nodes[spot, AXIS:AXIS + 3] = axis / np.linalg.norm(axis, axis=1, keepdims=True)
        inner = np.clip(r[spot, plr.COS_INNER], -1.0, 1.0)
        outer = np.clip(r[spot, plr.COS_OUTER], -1.0, 1.0)
        # the full-power cone, then the falloff to the outer edge (pbrt's SpotLight::Bounds)
        nodes[spot, COS_O] = inner
        nodes[spot, COS_E] = np.cos(np.arccos(outer) - np.arccos(inner))
    # quads, disks, triangles: their box; emission about the normal, falling off to 90 degrees
    area = ~point
    corner, normal = r[area, 1:4], r[area, 4:7]
    a, b = r[area, 10:13], r[area, 13:16]
    kind_area = k[area]
    disk = (kind_area == lt.DISK)[:, None]
    triangle = (kind_area == lt.TRIANGLE)[:, None]
    # corners: quad v, v+a, v+b, v+a+b; triangle v, v+a, v+b; disk centre +- (|a| + |b|)
    candidates = np.stack([corner, corner + a, corner + b, np.where(triangle, corner, corner + a + b)])
    low, high = candidates.min(axis=0), candidates.max(axis=0)
    reach = np.abs(a) + np.abs(b)
    low = np.where(disk, corner - reach, low)
    high = np.where(disk, corner + reach, high)
    nodes[area, BOX:BOX + 3], nodes[area, BOX + 3:BOX + 6] = low, high
    nodes[area, AXIS:AXIS + 3] = normal
    nodes[area, COS_O], nodes[area, COS_E] = 1.0, 0.0
    two_sided = np.zeros(len(bounded), bool)
    two_sided[area] = r[area, lt.TWO_SIDED] > 0.0
    return bounded.astype(np.int64), nodes, two_sided, np.flatnonzero(far).astype(np.int64)


def _morton_order(nodes):
    """The leaves in the order of a 3D Morton curve of their boxes' centres (21 bits an axis)."""
    centre = 0.5 * (nodes[:, BOX:BOX + 3] + nodes[:, BOX + 3:BOX + 6])
    low, high = centre.min(axis=0), centre.max(axis=0)
    span = np.where(high > low, high - low, 1.0)
    cells = np.minimum(((centre - low) / span * (2 ** 21)).astype(np.uint64), np.uint64(2 ** 21 - 1))
    code = np.zeros(len(nodes), np.uint64)
    for bit in range(21):
        for axis in range(3):
            code |= ((cells[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return np.argsort(code, kind="stable")


class LightTree:
    """The light tree of a :class:`rtmesh.lights.light_table.LightTable`'s rows.

    Parameters
    ----------
    rows : (L, WIDTH) float64
    power : (L,) float64

    Attributes
    ----------
    record : tuple
        ``(nodes, links, trails, infinite)`` (the module's records), for the kernels.
    """

    def __init__(self, rows, power):
        bounded, leaves, two_sided, infinite = light_bounds(np.asarray(rows, np.float64),
                                                             np.asarray(power, np.float64))
        order = _morton_order(leaves) if len(leaves) else np.zeros(0, np.int64)
        count = len(order)
        nodes = np.zeros((max(2 * count - 1, 0), NODE_WIDTH))
        links = np.zeros((len(nodes), 2), np.int64)
        trails = np.full(len(rows), NOT_IN_TREE, dtype=np.uint64)
        if count:
            _build(leaves[order], two_sided[order], bounded[order], nodes, links, trails)
        self.record = (nodes, links, trails, infinite)


@row
def _cone_union(ax, ay, az, cos_a, bx, by, bz, cos_b):
    """The smallest cone holding cones ``a`` and ``b`` (pbrt-v4's ``Union``): axis and
    ``cos theta``."""
    if cos_a <= -1.0 or cos_b <= -1.0:
        return 0.0, 0.0, 1.0, -1.0
    theta_a, theta_b = math.acos(min(max(cos_a, -1.0), 1.0)), math.acos(min(max(cos_b, -1.0), 1.0))
    d = min(max(ax * bx + ay * by + az * bz, -1.0), 1.0)
    theta_d = math.acos(d)
    if min(theta_d + theta_b, math.pi) <= theta_a:
        return ax, ay, az, cos_a
    if min(theta_d + theta_a, math.pi) <= theta_b:
        return bx, by, bz, cos_b
    theta_o = 0.5 * (theta_a + theta_d + theta_b)
    if theta_o >= math.pi:
        return 0.0, 0.0, 1.0, -1.0
    # rotate a's axis toward b's by theta_o - theta_a, about a x b
    rx, ry, rz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    length = math.sqrt(rx * rx + ry * ry + rz * rz)
    if not length > 0.0:
        return 0.0, 0.0, 1.0, -1.0
    rx, ry, rz = rx / length, ry / length, rz / length
    angle = theta_o - theta_a
    c, s = math.cos(angle), math.sin(angle)
    # Rodrigues: a cos + (r x a) sin (r is normal to a)
    cx, cy, cz = ry * az - rz * ay, rz * ax - rx * az, rx * ay - ry * ax
    wx, wy, wz = ax * c + cx * s, ay * c + cy * s, az * c + cz * s
    norm = math.sqrt(wx * wx + wy * wy + wz * wz)
    return wx / norm, wy / norm, wz / norm, math.cos(theta_o)


@kernel
def _build(leaves, two_sided, light_rows, nodes, links, trails):
    """Fill ``nodes`` and ``links`` (2 n - 1 rows) for the ``n`` sorted ``leaves`` and each
    light's bit trail."""
    n = len(leaves)
    # node ranges, parents first (depth-first: node i over [lo, hi) has its first child at
    # i + 1 and its second at i + 2 (mid - lo))
    lo_of, hi_of = np.empty(len(nodes), np.int64), np.empty(len(nodes), np.int64)
    trail_of, depth_of = np.empty(len(nodes), np.uint64), np.empty(len(nodes), np.int64)
    lo_of[0], hi_of[0], trail_of[0], depth_of[0] = 0, n, np.uint64(0), 0
    for i in range(len(nodes)):
        lo, hi = lo_of[i], hi_of[i]
        if hi - lo == 1:
            nodes[i, :] = leaves[lo, :]
            links[i, 0], links[i, 1] = light_rows[lo], LEAF | (TWO_SIDED if two_sided[lo] else 0)
            trails[light_rows[lo]] = trail_of[i]
            continue
        mid = (lo + hi) // 2
        first, second = i + 1, i + 2 * (mid - lo)
        lo_of[first], hi_of[first] = lo, mid
        lo_of[second], hi_of[second] = mid, hi
        trail_of[first] = trail_of[i]
        trail_of[second] = trail_of[i] | (np.uint64(1) << np.uint64(depth_of[i]))
        depth_of[first] = depth_of[second] = depth_of[i] + 1
        links[i, 0], links[i, 1] = second, 0
    # bounds, children before parents
    for i in range(len(nodes) - 1, -1, -1):
        if links[i, 1] & LEAF:
            continue
        a, b = i + 1, links[i, 0]
        for c in range(3):
            nodes[i, BOX + c] = min(nodes[a, BOX + c], nodes[b, BOX + c])
            nodes[i, BOX + 3 + c] = max(nodes[a, BOX + 3 + c], nodes[b, BOX + 3 + c])
        nodes[i, PHI] = nodes[a, PHI] + nodes[b, PHI]
        wx, wy, wz, cos_o = _cone_union(nodes[a, AXIS], nodes[a, AXIS + 1], nodes[a, AXIS + 2], nodes[a, COS_O],
                                        nodes[b, AXIS], nodes[b, AXIS + 1], nodes[b, AXIS + 2], nodes[b, COS_O])
        nodes[i, AXIS], nodes[i, AXIS + 1], nodes[i, AXIS + 2], nodes[i, COS_O] = wx, wy, wz, cos_o
        nodes[i, COS_E] = min(nodes[a, COS_E], nodes[b, COS_E])
        links[i, 1] = (links[a, 1] | links[b, 1]) & TWO_SIDED
    for i in range(len(nodes)):
        ex, ey, ez = nodes[i, BOX + 3] - nodes[i, BOX], nodes[i, BOX + 4] - nodes[i, BOX + 1], \
            nodes[i, BOX + 5] - nodes[i, BOX + 2]
        for c in range(3):
            nodes[i, CENTRE + c] = 0.5 * (nodes[i, BOX + c] + nodes[i, BOX + 3 + c])
        nodes[i, HALF_DIAGONAL] = 0.5 * math.sqrt(ex * ex + ey * ey + ez * ez)
        nodes[i, SIN_O] = math.sqrt(max(1.0 - nodes[i, COS_O] * nodes[i, COS_O], 0.0))


@row
def importance(nodes, links, i, px, py, pz, nx, ny, nz):
    """An estimate of node ``i``'s lights' contribution at point ``p`` of a surface of
    normal ``n`` (``n`` zero: a point in a medium), pbrt-v4's ``LightBounds::Importance``:
    ``phi cos(theta') / d^2``, with ``theta'`` the least angle the cone and the box allow
    between an emission direction and the direction to ``p`` (0 beyond ``theta_e`` past
    the cone), times the best cosine at the surface."""
    node = nodes[i]
    if not node[PHI] > 0.0:
        return 0.0
    half = node[HALF_DIAGONAL]
    vx, vy, vz = px - node[CENTRE], py - node[CENTRE + 1], pz - node[CENTRE + 2]
    d2 = vx * vx + vy * vy + vz * vz
    # (pbrt clamps the squared distance by half the diagonal's length)
    d2c = max(d2, half)
    inverse_d = 1.0 / math.sqrt(d2) if d2 > 0.0 else 0.0
    if inverse_d > 0.0:
        wix, wiy, wiz = vx * inverse_d, vy * inverse_d, vz * inverse_d
    else:
        wix, wiy, wiz = 0.0, 0.0, 1.0
    cos_w = node[AXIS] * wix + node[AXIS + 1] * wiy + node[AXIS + 2] * wiz
    if links[i, 1] & TWO_SIDED:
        cos_w = abs(cos_w)
    sin_w = math.sqrt(max(1.0 - cos_w * cos_w, 0.0))
    # the directions the box subtends from p: its bounding sphere's cone (all, from inside)
    if d2 < half * half:
        cos_b, sin_b = -1.0, 0.0
    else:
        sin_b = half * inverse_d
        cos_b = math.sqrt(max(1.0 - sin_b * sin_b, 0.0))
    cos_o, sin_o = node[COS_O], node[SIN_O]
    # theta_x = max(theta_w - theta_o, 0), theta' = max(theta_x - theta_b, 0)
    if cos_w > cos_o:
        cos_x, sin_x = 1.0, 0.0
    else:
        cos_x, sin_x = cos_w * cos_o + sin_w * sin_o, sin_w * cos_o - cos_w * sin_o
    cos_p = 1.0 if cos_x > cos_b else cos_x * cos_b + sin_x * sin_b
    if cos_p <= node[COS_E]:
        return 0.0
    value = node[PHI] * cos_p / d2c
    if nx != 0.0 or ny != 0.0 or nz != 0.0:
        cos_i = abs(wix * nx + wiy * ny + wiz * nz)
        sin_i = math.sqrt(max(1.0 - cos_i * cos_i, 0.0))
        cos_pi = 1.0 if cos_i > cos_b else cos_i * cos_b + sin_i * sin_b
        value *= cos_pi
    return max(value, 0.0)


@row
def _children(nodes, links, i, px, py, pz, nx, ny, nz):
    """Interior node ``i``'s children and the probability of choosing the first at ``p``,
    ``n`` (-1 where neither can light it)."""
    a, b = i + 1, links[i, 0]
    ca = importance(nodes, links, a, px, py, pz, nx, ny, nz)
    cb = importance(nodes, links, b, px, py, pz, nx, ny, nz)
    return a, b, (ca / (ca + cb) if ca + cb > 0.0 else -1.0)


@row
def in_use(tree):
    """Whether ``tree`` chooses the lights (not :data:`NO_TREE`, which the path stage hands
    the kernels for ``light_sampler = "power"`` and under the Whitted configuration)."""
    return len(tree[2]) > 0


@row
def infinite_share(tree):
    """The probability of choosing among the lights at infinity."""
    nodes, infinite = tree[0], tree[3]
    k = len(infinite)
    return k / (k + (1.0 if len(nodes) else 0.0)) if k else 0.0


@row
def choose_light(tree, px, py, pz, nx, ny, nz, u):
    """A light for point ``p`` of a surface of normal ``n``, by ``u`` in [0, 1).

    Returns
    -------
    light : int
        Its row, -1 where no light can reach ``p``.
    pmf : float
        The probability of that choice (:func:`light_pmf`).
    """
    nodes, links, infinite = tree[0], tree[1], tree[3]
    share = infinite_share(tree)
    if u < share:
        k = len(infinite)
        return infinite[min(int(u / share * k), k - 1)], share / k
    if len(nodes) == 0:
        return -1, 0.0
    u = min((u - share) / (1.0 - share), _BELOW_ONE)
    pmf = 1.0 - share
    i = 0
    while not links[i, 1] & LEAF:
        a, b, pa = _children(nodes, links, i, px, py, pz, nx, ny, nz)
        if pa < 0.0:
            return -1, 0.0
        if u < pa:
            u, pmf, i = min(u / pa, _BELOW_ONE), pmf * pa, a
        else:
            u, pmf, i = min((u - pa) / (1.0 - pa), _BELOW_ONE), pmf * (1.0 - pa), b
    if i == 0 and not importance(nodes, links, 0, px, py, pz, nx, ny, nz) > 0.0:
        return -1, 0.0
    return links[i, 0], pmf


@row
def light_pmf(tree, light, px, py, pz, nx, ny, nz):
    """The probability that :func:`choose_light` picks ``light`` for ``p`` and ``n``."""
    nodes, links, trails, infinite = tree
    share = infinite_share(tree)
    trail = trails[light]
    if trail == NOT_IN_TREE:
        return share / len(infinite) if len(infinite) else 0.0
    pmf = 1.0 - share
    i = 0
    while not links[i, 1] & LEAF:
        a, b, pa = _children(nodes, links, i, px, py, pz, nx, ny, nz)
        if pa < 0.0:
            return 0.0
        if trail & np.uint64(1):
            pmf *= 1.0 - pa
            i = b
        else:
            pmf *= pa
            i = a
        trail >>= np.uint64(1)
    if i == 0 and not importance(nodes, links, 0, px, py, pz, nx, ny, nz) > 0.0:
        return 0.0
    return pmf


@kernel
def choose_lights(tree, points, normals, u):
    """:func:`choose_light` for many points (tests and tools): (n,) lights and pmfs."""
    n = len(u)
    lights, pmfs = np.empty(n, np.int64), np.empty(n)
    for j in range(n):
        lights[j], pmfs[j] = choose_light(tree, points[j, 0], points[j, 1], points[j, 2], normals[j, 0],
                                          normals[j, 1], normals[j, 2], u[j])
    return lights, pmfs


@kernel
def light_pmfs(tree, lights, points, normals):
    """:func:`light_pmf` for many (light, point) pairs: (n,) probabilities."""
    n = len(lights)
    out = np.empty(n)
    for j in range(n):
        out[j] = light_pmf(tree, lights[j], points[j, 0], points[j, 1], points[j, 2], normals[j, 0], normals[j, 1],
                           normals[j, 2])
    return out


@kernel
def importances(tree, i, points, normals):
    """:func:`importance` of node ``i`` at many points: (n,)."""
    nodes, links = tree[0], tree[1]
    out = np.empty(len(points))
    for j in range(len(points)):
        out[j] = importance(nodes, links, i, points[j, 0], points[j, 1], points[j, 2], normals[j, 0], normals[j, 1],
                            normals[j, 2])
    return out
