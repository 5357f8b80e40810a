"""Compiled helpers of the float32 boundary: ulps of float32 values, secondary-ray origin
offsets, and Embree's float32 closest-hit results as float64 (see :mod:`rtmesh.geometry.accel`).
"""

import functools

import numba
import numpy as np
from numba import types
from numba.extending import intrinsic

from rtmesh.core.compiled import cached, kernel, row

# ------------------------------------------------------------------ float32 offsets
# See rtmesh.geometry.accel for the reasoning behind the origin offset and its constants.
ULPS = np.float32(4.0)
EXTENT_EPSILONS = np.float32(16.0 * np.finfo(np.float32).eps)
DIRECTION_SHARE = np.float32(0.25)
_F32_ZERO, _F32_ONE = np.float32(0.0), np.float32(1.0)
F32_MAX = float(np.finfo(np.float32).max)


@intrinsic
def _float32_bits(typingctx, x):
    """The bits of a float32 as an int32 (a free reinterpretation, like ``ndarray.view``)."""
    if x != types.float32:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int32))

    return types.int32(types.float32), codegen


@intrinsic
def _float32_from_bits(typingctx, bits):
    """The float32 whose bits are the low 32 bits of the integer ``bits``."""
    if not isinstance(bits, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        low = builder.trunc(args[0], context.get_value_type(types.int32)) if bits.bitwidth > 32 else args[0]
        return builder.bitcast(low, context.get_value_type(types.float32))

    return types.float32(bits), codegen


_EXPONENT_MASK = np.int32(0x7F800000)
_ULP_SCALE = np.float32(2.0 ** -23)


@row
def _ulp32(x):
    """Spacing of float32 numbers at float32 ``x``, read from the exponent bits
    (``2**(e - 23)``); 0 for zeros and subnormals."""
    return _float32_from_bits(_float32_bits(x) & _EXPONENT_MASK) * _ULP_SCALE


def ulp32(x):
    """Spacing of float32 numbers at each element (any shape and layout).

    ``np.spacing(abs(x))`` for normal floats; 0 for zeros and subnormals.

    Parameters
    ----------
    x : float32 array
    """
    return _ulp32_ufunc()(x)


@functools.cache
def _ulp32_ufunc():
    """The compiled ufunc behind :func:`ulp32`, made on first use rather than at import:
    loading it starts numba's code generator (about 0.4 s), which a process that only
    parses its arguments or reports a bad file never needs."""
    return cached(lambda cache: numba.vectorize(["float32(float32)"], nopython=True, cache=cache))(_ulp32_element)


def _ulp32_element(x):
    return _ulp32(x)


@row
def _sign32(x):
    if x > 0:
        return _F32_ONE
    if x < 0:
        return -_F32_ONE
    return _F32_ZERO


@row
def offset_origin(px, py, pz, nx, ny, nz, dx, dy, dz, scale):
    """One point moved off its surface (see :func:`offset_origins`); float32 ``(x, y, z)``.

    ``d`` is the float32 ray direction, or zeros for a normal-only offset.
    """
    px, py, pz = np.float32(px), np.float32(py), np.float32(pz)
    nx, ny, nz = np.float32(nx), np.float32(ny), np.float32(nz)
    ux, uy, uz = _ulp32(px), _ulp32(py), _ulp32(pz)
    distance = ULPS * ((abs(nx) * ux + abs(ny) * uy) + abs(nz) * uz) + EXTENT_EPSILONS * scale
    mx = nx + DIRECTION_SHARE * np.float32(dx)
    my = ny + DIRECTION_SHARE * np.float32(dy)
    mz = nz + DIRECTION_SHARE * np.float32(dz)
    # plus one ulp in every coordinate that moves: rounding cannot give the old value back
    return (px + (mx * distance + _sign32(mx) * ux),
            py + (my * distance + _sign32(my) * uy),
            pz + (mz * distance + _sign32(mz) * uz))


@kernel
def offset_origins(points_t, normals_t, directions_t, scale):
    """Ray origins moved off a surface; see :func:`rtmesh.geometry.accel.offset_ray_origins`.

    The vectors come by component (:func:`rtmesh.core.compiled.by_component`).

    Parameters
    ----------
    points_t, normals_t : (3, n) float
    directions_t : (3, n) float or (3, 0)
        Directions of the rays, or an empty array for a normal-only offset.
    scale : float32
        Scene size.

    Returns
    -------
    (n, 3) float32
        Component-major.
    """
    points, normals, directions = points_t.T, normals_t.T, directions_t.T
    n = len(points)
    out = np.empty((3, n), np.float32)
    along = len(directions) > 0
    for i in range(n):
        dx = directions[i, 0] if along else 0.0
        dy = directions[i, 1] if along else 0.0
        dz = directions[i, 2] if along else 0.0
        out[0, i], out[1, i], out[2, i] = offset_origin(points[i, 0], points[i, 1], points[i, 2],
                                                  normals[i, 0], normals[i, 1], normals[i, 2],
                                                  dx, dy, dz, scale)
    return out.T



# ------------------------------------------------------------------ Embree results
@kernel
def closest_hits(t_far, prim, u, v):
    """Embree's float32 closest-hit results as float64, with ``inf`` for the misses.

    Parameters
    ----------
    t_far, u, v : (n,) float32
    prim : (n,) int32
        Triangle hit, -1 for a miss.

    Returns
    -------
    t, u, v : (n,) float64
    """
    n = len(prim)
    t64, u64, v64 = np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):
        t64[i] = np.float64(t_far[i]) if prim[i] >= 0 else np.inf
        u64[i], v64[i] = np.float64(u[i]), np.float64(v[i])
    return t64, u64, v64
