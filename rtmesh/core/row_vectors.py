"""One-row arithmetic for compiled kernels: vectors (dot products, normalising), in the
summation order of :mod:`rtmesh.core.vecmath`, so compiled and NumPy results agree bit for
bit, and integer quotients without an integer division.
"""

import math

import numpy as np

from rtmesh.core.compiled import row


# ------------------------------------------------------------------ vectors
@row
def dot3(ax, ay, az, bx, by, bz):
    # (x + y) + z, the order rtmesh.core.vecmath.dot sums in
    return (ax * bx + ay * by) + az * bz


@row
def normalized3(x, y, z, scale):
    """``(x, y, z) * scale / length``; zero stays zero."""
    length = math.sqrt(dot3(x, y, z, x, y, z))
    inv = (1.0 / length if length > 0.0 else 0.0) * scale
    return x * inv, y * inv, z * inv


@row
def tangent_frame(nx, ny, nz):
    """Unit tangents ``t, b`` with ``t x b = n`` of a unit normal, as six numbers: the
    branchless construction of Duff et al. (2017), as :func:`rtmesh.core.vecmath.orthonormal_basis`
    (``sign * nx * nx`` is ``sign * nx ** 2`` exactly: ``sign`` is +-1)."""
    sign = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (sign + nz)
    c = nx * ny * a
    return 1.0 + sign * nx * nx * a, sign * c, -sign * nx, c, sign + ny * ny * a, -ny


# Smallest cosine between a bent shading normal and the direction to the viewer: enough to
# keep the Blinn-Phong half vector and the mirror direction well defined.


# ------------------------------------------------------------------ integers
@row
def floor_quotient(value, divisor, inverse_divisor):
    """``value // divisor`` for ``0 <= value < 2**52`` and ``divisor >= 1``, by a float
    product and a one-step correction (``inverse_divisor`` is ``1.0 / divisor``): an integer
    division takes tens of cycles and has no vector form, so it would keep the loops that
    call it from vectorising."""
    quotient = np.int64(value * inverse_divisor)
    quotient += (quotient + 1) * divisor <= value
    quotient -= quotient * divisor > value
    return quotient
