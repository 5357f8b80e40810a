"""The Lambertian (ideal diffuse) reflection model: ``f = albedo / pi``, sampled by a
cosine-weighted hemisphere.

Parameters (row of :data:`rtmesh.materials.lobes.PARAMETER_WIDTH`): ``albedo`` r, g, b.
"""

import math

from rtmesh.core.compiled import row
from rtmesh.materials import lobes
from rtmesh.materials.metallic_roughness import square_to_cosine_hemisphere_row

NAME = "lambert"
# parameters that textures scale (rtmesh.materials.models.SLOTS)
SLOTS = {"colour": 0}


def parameters(material):
    """The model's row from a :class:`~rtmesh.materials.table.Material`: its diffuse colour
    as the albedo."""
    return [float(c) for c in material.diffuse]


@row
def evaluate(params, m, table, ox, oy, oz, wx, wy, wz):
    """``f |wi.z|`` (r, g, b) and the density of :func:`sample` (see :mod:`~rtmesh.materials.lobes`)."""
    if not ((oz > 0.0) & (wz > 0.0)):
        return 0.0, 0.0, 0.0, 0.0
    c = wz / math.pi
    return params[m, 0] * c, params[m, 1] * c, params[m, 2] * c, c


@row
def sample(params, m, table, ox, oy, oz, u0, u1, u2):
    """A cosine-distributed ``wi``: its weight is the albedo."""
    if not oz > 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, lobes.FAILED
    wx, wy, wz = square_to_cosine_hemisphere_row(u1, u2)
    if not wz > 0.0:
        return wx, wy, wz, 0.0, 0.0, 0.0, 0.0, lobes.FAILED
    return wx, wy, wz, params[m, 0], params[m, 1], params[m, 2], wz / math.pi, lobes.DIFFUSE


@row
def parts(params, m, table, ox, oy, oz, wx, wy, wz):
    """The diffuse and transmitted parts (r, g, b each) of :func:`evaluate`'s ``f |cos|``
    (the light-path passes; the glossy part is the rest): all diffuse."""
    fr, fg, fb, _ = evaluate(params, m, table, ox, oy, oz, wx, wy, wz)
    return fr, fg, fb, 0.0, 0.0, 0.0


@row
def albedo(params, m):
    """Directional albedo (r, g, b), for the denoiser's guide."""
    return params[m, 0], params[m, 1], params[m, 2]
