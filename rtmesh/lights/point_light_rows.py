"""Point, directional and spot lights in compiled code: one light's direction, distance and
incident term at a point, from its row of named fields.

A light's row is one record of :data:`ROW` (kind, position, direction, power, cone
cosines), handed to kernels as its 12 float64 words; kernels read the fields by the word
indices derived from the record layout (:data:`POSITION`, ...), so the layout is written
once, here.  Lights without a row (their own ``illuminate``) are as welcome: the general
path asks every light for ``illuminate(points)``; only the fused direct-lighting stage
needs a row.
"""

import math

import numpy as np

from rtmesh.core.compiled import by_component, kernel, row
from rtmesh.core.row_vectors import dot3

POINT, DIRECTIONAL, SPOT = 0, 1, 2
# the fields of a light's row, in order; ``power`` is the intensity (W/sr, point and spot)
# or the irradiance (W/m^2, directional), ``direction`` the way the light travels
ROW = np.dtype([("kind", np.float64), ("position", np.float64, 3), ("direction", np.float64, 3),
                ("power", np.float64, 3), ("cos_inner", np.float64), ("cos_outer", np.float64)])
# word index of each field in a row (kernels read ``light[POSITION + 1]`` for position y)
KIND, POSITION, DIRECTION, POWER, COS_INNER, COS_OUTER = (ROW.fields[name][1] // 8 for name in ROW.names)


def pack_row(kind, position=(0.0, 0.0, 0.0), direction=(0.0, 0.0, 0.0), power=(0.0, 0.0, 0.0),
             cos_inner=1.0, cos_outer=1.0):
    """A light's row for the kernels.

    Parameters
    ----------
    kind : {POINT, DIRECTIONAL, SPOT}
    position, direction, power : (3,) float
    cos_inner, cos_outer : float
        Cosines of the spot cone's inner and outer half-angles.

    Returns
    -------
    (12,) float64
        The words of one :data:`ROW` record.
    """
    record = np.zeros(1, ROW)
    record["kind"], record["position"], record["direction"] = kind, position, direction
    record["power"], record["cos_inner"], record["cos_outer"] = power, cos_inner, cos_outer
    return record.view(np.float64).copy()


@row
def _toward(light, px, py, pz):
    """Unit direction from a point toward the light's position, the distance, and the
    squared distance the incident term divides by."""
    tx, ty, tz = light[POSITION] - px, light[POSITION + 1] - py, light[POSITION + 2] - pz
    distance = math.sqrt(dot3(tx, ty, tz, tx, ty, tz))
    # a light sitting exactly on a point lights it from nowhere: direction 0, term 0
    safe = distance if distance > 0.0 else np.inf
    return tx / safe, ty / safe, tz / safe, distance, safe * safe


@row
def point_row(light, px, py, pz):
    """:func:`illuminate_row` of a point light (kind :data:`POINT`): the same numbers
    without the other kinds' arithmetic (a division and a smoothstep per point), for loops
    that know their light is a point light."""
    wx, wy, wz, distance, square = _toward(light, px, py, pz)
    return wx, wy, wz, distance, light[POWER] / square, light[POWER + 1] / square, light[POWER + 2] / square


@row
def illuminate_row(light, px, py, pz):
    """Direction, distance and incident term of one light at one point.

    ``light`` is a light's row (:func:`pack_row`).  Returns ``(wx, wy, wz, distance,
    er, eg, eb)``.  Every kind is formed and the light's own picked by selects, not
    branches, so that the loops calling this vectorise.
    """
    kind = light[KIND]
    directional, spot = kind == DIRECTIONAL, kind == SPOT
    wx, wy, wz, distance, square = _toward(light, px, py, pz)
    # the spot's cone: a smoothstep in cos(angle) between the outer and the inner angle
    # (a step when they are equal)
    cos_angle = -dot3(wx, wy, wz, light[DIRECTION], light[DIRECTION + 1], light[DIRECTION + 2])
    cos_inner, cos_outer = light[COS_INNER], light[COS_OUTER]
    x = min(max((cos_angle - cos_outer) / (cos_inner - cos_outer), 0.0), 1.0)
    step = 1.0 if cos_angle >= cos_outer else 0.0
    cone = x * x * (3.0 - 2.0 * x) if cos_inner - cos_outer > 0.0 else step
    falloff = cone / square
    # point: intensity / distance^2; spot: intensity * (cone / distance^2); directional:
    # the irradiance, from -direction, infinitely far
    pr, pg, pb = light[POWER], light[POWER + 1], light[POWER + 2]
    er = pr if directional else (pr * falloff if spot else pr / square)
    eg = pg if directional else (pg * falloff if spot else pg / square)
    eb = pb if directional else (pb * falloff if spot else pb / square)
    return (-light[DIRECTION] if directional else wx, -light[DIRECTION + 1] if directional else wy,
            -light[DIRECTION + 2] if directional else wz, np.inf if directional else distance, er, eg, eb)


def illuminate_points(light, points):
    """:func:`illuminate` at points of any layout and float dtype: what the point-like
    lights' ``illuminate(points)`` returns.

    Parameters
    ----------
    light : (12,) float64
    points : (k, 3) float
    """
    return illuminate(light, by_component(np.asarray(points, dtype=np.float64)))


@kernel
def illuminate(light, points_t):
    """Direction toward a light, distance and incident term at each point.

    Parameters
    ----------
    light : (12,) float64
        The light's row (:func:`pack_row`).
    points_t : (3, k) float
        The points by component (:func:`rtmesh.core.compiled.by_component`).

    Returns
    -------
    wi : (k, 3) float64
    distance : (k,) float64
    incident : (k, 3) float64
    """
    points = points_t.T
    k = len(points)
    wi, distance, incident = np.empty((3, k)), np.empty(k), np.empty((3, k))
    for i in range(k):
        (wi[0, i], wi[1, i], wi[2, i], distance[i],
         incident[0, i], incident[1, i], incident[2, i]) = illuminate_row(light, points[i, 0],
                                                                       points[i, 1], points[i, 2])
    return wi.T, distance, incident.T
