"""Point, directional and spot lights in compiled code: one light's direction, distance and
incident term at a point, from the row of floats :meth:`kernel_parameters` packs.
"""

import math

import numpy as np

from rtmesh.core.compiled import kernel, row
from rtmesh.core.row_vectors import dot3

# ------------------------------------------------------------------ lights
POINT, DIRECTIONAL, SPOT = 0, 1, 2


@row
def illuminate_row(light, px, py, pz):
    """Direction, distance and incident term of one light at one point.

    ``light`` is a light's :meth:`kernel_parameters` row: ``[kind, position (3),
    direction (3), power (3), cos_inner, cos_outer]``.  Returns ``(wx, wy, wz, distance,
    er, eg, eb)``.  Every kind is formed and the light's own picked by selects, not
    branches, so that the loops calling this vectorise.
    """
    kind = light[0]
    directional, spot = kind == DIRECTIONAL, kind == SPOT
    tx, ty, tz = light[1] - px, light[2] - py, light[3] - pz
    distance = math.sqrt(dot3(tx, ty, tz, tx, ty, tz))
    # a light sitting exactly on a point lights it from nowhere: direction 0, term 0
    safe = distance if distance > 0.0 else np.inf
    wx, wy, wz = tx / safe, ty / safe, tz / safe
    square = safe * safe
    # the spot's cone: a smoothstep in cos(angle) between the outer and the inner angle
    # (a step when they are equal)
    cos_angle = -dot3(wx, wy, wz, light[4], light[5], light[6])
    cos_inner, cos_outer = light[10], light[11]
    x = min(max((cos_angle - cos_outer) / (cos_inner - cos_outer), 0.0), 1.0)
    step = 1.0 if cos_angle >= cos_outer else 0.0
    cone = x * x * (3.0 - 2.0 * x) if cos_inner - cos_outer > 0.0 else step
    falloff = cone / square
    # point: intensity / distance^2; spot: intensity * (cone / distance^2); directional:
    # the irradiance, from -direction, infinitely far
    er = light[7] if directional else (light[7] * falloff if spot else light[7] / square)
    eg = light[8] if directional else (light[8] * falloff if spot else light[8] / square)
    eb = light[9] if directional else (light[9] * falloff if spot else light[9] / square)
    return (-light[4] if directional else wx, -light[5] if directional else wy,
            -light[6] if directional else wz, np.inf if directional else distance, er, eg, eb)


@kernel
def illuminate(light, points):
    """Direction toward a light, distance and incident term at each point.

    Parameters
    ----------
    light : (12,) float64
        The light's :meth:`kernel_parameters`.
    points : (k, 3) float

    Returns
    -------
    wi : (k, 3) float64
    distance : (k,) float64
    incident : (k, 3) float64
    """
    k = len(points)
    wi, distance, incident = np.empty((3, k)), np.empty(k), np.empty((3, k))
    for i in range(k):
        (wi[0, i], wi[1, i], wi[2, i], distance[i],
         incident[0, i], incident[1, i], incident[2, i]) = illuminate_row(light, points[i, 0],
                                                                       points[i, 1], points[i, 2])
    return wi.T, distance, incident.T
