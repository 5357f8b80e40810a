"""Sample generation: counter-based random numbers, pixel patterns and warps.

Every random number in rtmesh is a pure function of ``(seed, pixel, sample, dimension)``,
computed by hashing those integers.  No generator state is carried between calls, so a
sample's value does not depend on which thread renders it, on the chunk it falls in, or on
how many other samples were drawn before it: renders are bit-identical for any thread count
and chunk size.

Dimensions used by the integrator are named in :class:`Dim`.
"""

import math
from enum import IntEnum

import numpy as np

from .batches import component_major, take_rows
from .hashing import GOLDEN, M1, mix64
from .lowdiscrepancy import sobol_02

SAMPLERS = ("regular", "random", "jittered", "sobol")


class Dim(IntEnum):
    """Sample dimensions (pairs of uniform numbers) and what they drive."""

    PIXEL = 0  # (x, y) position inside the pixel
    LENS = 2  # (u, v) on the thin-lens aperture
    TIME = 4  # time in the shutter interval (one number; dimension 5 is unused)
    AO = 16  # first of the ambient-occlusion dimensions; AO rays at depth d use AO + 2*d
    LIGHT = 1 << 24  # first of the area-light dimensions (see rtmesh.area_lights.light_dimension)
    GLOSSY = 1 << 25  # glossy-reflection directions; the rays spawned at depth d use GLOSSY + 2*d
    ALPHA = 1 << 26  # stochastic transparency of cut-outs, keyed by the ray (see rtmesh.cutouts)


def sequence_key(seed, pixel, dimension):
    """64-bit key of the sample sequence of one pixel and dimension, (n,) -> (n,) uint64.

    Every sample of a pixel in a given dimension shares it; :func:`uniform` hashes the
    sample index into it, the Sobol sampler uses it as the scrambling seed.
    """
    pixel = np.asarray(pixel, dtype=np.uint64)
    with np.errstate(over="ignore"):  # the multiplications are meant to wrap modulo 2**64
        key = mix64(np.uint64(seed & 0xFFFFFFFFFFFFFFFF) * GOLDEN + np.uint64(dimension))
        return mix64(key ^ (pixel * GOLDEN))


def uniform(seed, pixel, sample, dimension):
    """Uniform random numbers in [0, 1) as a pure function of their integer keys.

    Parameters
    ----------
    seed : int
        Render seed.
    pixel : (n,) int
        Linear pixel index (``row * width + column``).
    sample : (n,) int or int
        Sample index within the pixel.
    dimension : int
        Which dimension of the sample (see :class:`Dim`).

    Returns
    -------
    (n,) float64
        Values in [0, 1), 53 random bits each.
    """
    sample = np.asarray(sample, dtype=np.uint64)
    with np.errstate(over="ignore"):  # the multiplication is meant to wrap modulo 2**64
        x = mix64(sequence_key(seed, pixel, dimension) ^ (sample * M1 + np.uint64(1)))
    # top 53 bits -> exactly representable doubles in [0, 1)
    return (x >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)


def uniform2(seed, pixel, sample, dimension):
    """Two independent uniform arrays for dimensions ``dimension`` and ``dimension + 1``.

    Returns
    -------
    (n, 2) float64
        Component-major (see :mod:`rtmesh.batches`).
    """
    return component_major(np.stack(
        [uniform(seed, pixel, sample, dimension), uniform(seed, pixel, sample, dimension + 1)]))


def strata_shape(spp):
    """Grid of ``nx * ny == spp`` strata, as square as ``spp`` allows.

    Parameters
    ----------
    spp : int
        Samples per pixel, >= 1.

    Returns
    -------
    nx, ny : int
        Columns and rows of strata, ``nx >= ny``.
    """
    ny = int(math.isqrt(spp))
    while spp % ny:
        ny -= 1
    return spp // ny, ny


def pixel_offsets(sampler, seed, pixel, sample, spp):
    """Sample positions inside the pixel.

    Parameters
    ----------
    sampler : {"regular", "random", "jittered", "sobol"}
        See :func:`stratified_points`.
    seed : int
    pixel : (n,) int
        Linear pixel index of each sample.
    sample : (n,) int
        Sample index within its pixel, in ``[0, spp)``.
    spp : int
        Samples per pixel.

    Returns
    -------
    (n, 2) float64
        Offsets in [0, 1)^2 from the pixel's top-left corner (x right, y down),
        component-major (see :mod:`rtmesh.batches`).
    """
    return stratified_points(sampler, seed, pixel, sample, spp, Dim.PIXEL)


def stratified_points(sampler, seed, pixel, index, count, dimension):
    """Points in [0, 1)^2 drawn in sets of ``count`` that are stratified together.

    The one sample machinery of the renderer: pixel positions, ambient-occlusion directions
    and area-light samples all come from here, each in its own :class:`Dim` dimension.
    Point ``index`` of a pixel's sequence belongs to the set ``index // count`` and to the
    stratum ``index % count`` of that set, so a caller that needs ``count`` points per pixel
    sample passes ``index = sample * count + j`` for ``j`` in ``[0, count)``.

    Parameters
    ----------
    sampler : {"regular", "random", "jittered", "sobol"}
        ``random`` places the points uniformly, ``jittered`` puts one uniform point in each
        stratum of an ``nx x ny`` grid (:func:`strata_shape`) in every set, ``sobol`` takes
        them from an Owen-scrambled (0,2)-sequence scrambled per pixel and dimension, so
        every power-of-two prefix of a pixel's points (and, for a power-of-two ``count``,
        every set) is stratified.  ``regular`` puts pixel positions (:attr:`Dim.PIXEL`) at
        the stratum centres, an ordered supersampling grid; in every other dimension the
        same points in every pixel would turn the integration error into bands repeated
        across the image (a penumbra made of ``count`` hard shadows), so there it jitters.
    seed : int
    pixel : (n,) int
        Linear pixel index of each point.
    index : (n,) int
        Index of the point in its pixel's sequence for this dimension.
    count : int
        Points per stratified set, >= 1.
    dimension : int
        First of the two dimensions the point uses (see :class:`Dim`).

    Returns
    -------
    (n, 2) float64
        Component-major (see :mod:`rtmesh.batches`).
    """
    if sampler == "random":
        return uniform2(seed, pixel, index, dimension)
    if sampler == "sobol":
        points = sobol_02(index, sequence_key(seed, pixel, dimension))
        return component_major(points.T)
    if sampler not in SAMPLERS:
        raise ValueError(f"unknown sampler {sampler!r}; expected one of {', '.join(SAMPLERS)}")
    nx, ny = strata_shape(count)
    size = np.array([nx, ny], dtype=np.float64)
    # the strata are worked out once and looked up per point: a gather from a tiny table is
    # much cheaper than dividing every index by nx
    strata = np.arange(count)
    cells = component_major(np.stack([strata % nx, strata // nx]).astype(np.float64))
    stratum = index % count if count > 1 else np.zeros_like(index)
    if sampler == "regular" and dimension == Dim.PIXEL:
        return take_rows((cells + 0.5) / size, stratum)
    return (take_rows(cells, stratum) + uniform2(seed, pixel, index, dimension)) / size


def shuffled_strata(seed, pixel, sample, spp, dimension):
    """A per-pixel permutation of the strata ``[0, spp)``, applied to sample indices.

    Jittered points of every dimension put sample ``i`` in stratum ``i``, so without a
    shuffle the sample in the top-left pixel stratum would always get, say, the first lens
    or time stratum: the dimensions would be correlated and a moving edge would sweep across
    the pixel in step with the time.  Each pixel and dimension gets the permutation
    ``i -> (a i + b) mod spp`` with hashed ``a`` (a unit modulo ``spp``) and ``b``: computed
    point by point, so it works on any subset of a pixel's samples (rays that survive to
    depth d), and independent between pixels and dimensions.

    Parameters
    ----------
    seed : int
    pixel : (n,) int
    sample : (n,) int
        Sample index within the pixel.  Indices past ``spp`` (samples added in later rounds)
        belong to the set ``sample // spp``, which is permuted the same way.
    spp : int
        Samples per stratified set.
    dimension : int

    Returns
    -------
    (n,) int64
        The permuted index, in the same set of ``spp`` as ``sample``.
    """
    sample = np.asarray(sample, dtype=np.int64)
    if spp == 1:
        return sample
    key = sequence_key(seed, pixel, dimension)
    units = np.flatnonzero(np.gcd(np.arange(spp), spp) == 1)
    a = units[(key >> np.uint64(32)) % np.uint64(len(units))]
    b = ((key & np.uint64(0xFFFFFFFF)) % np.uint64(spp)).astype(np.int64)
    stratum = sample % spp
    return (sample - stratum) + (a * stratum + b) % spp


def decorrelated_points(sampler, seed, pixel, sample, spp, dimension):
    """One point in [0, 1)^2 per pixel sample for a dimension other than the pixel's.

    :func:`stratified_points` with each pixel's ``spp`` points stratified together, and,
    for the ``jittered`` and ``regular`` samplers, their strata paired with the pixel
    strata by :func:`shuffled_strata` (Owen-scrambled Sobol points are scrambled per
    dimension already, random points are independent).

    Parameters
    ----------
    sampler : {"regular", "random", "jittered", "sobol"}
    seed : int
    pixel, sample : (n,) int
        Linear pixel index and sample index within the pixel (in ``[0, spp)``).
    spp : int
    dimension : int
        First of the two dimensions the point uses (see :class:`Dim`).

    Returns
    -------
    (n, 2) float64
        Component-major (see :mod:`rtmesh.batches`).
    """
    if sampler in ("jittered", "regular"):
        sample = shuffled_strata(seed, pixel, sample, spp, dimension)
    return stratified_points(sampler, seed, pixel, sample, spp, dimension)


def stratified_values(sampler, seed, pixel, sample, spp, dimension):
    """One number in [0, 1) per pixel sample, the ``spp`` numbers of a pixel stratified.

    For one-dimensional quantities such as the time in the shutter.  ``jittered`` and
    ``regular`` put exactly one value in each interval ``[k / spp, (k + 1) / spp)``,
    assigned to the samples by :func:`shuffled_strata`; ``sobol`` uses the first coordinate
    of the scrambled (0,2)-sequence, a (0,1)-sequence: every power-of-two prefix is
    stratified the same way; ``random`` is uniform.

    Parameters
    ----------
    sampler : {"regular", "random", "jittered", "sobol"}
    seed : int
    pixel, sample : (n,) int
    spp : int
    dimension : int

    Returns
    -------
    (n,) float64
    """
    if sampler == "random":
        return uniform(seed, pixel, sample, dimension)
    if sampler == "sobol":
        return sobol_02(sample, sequence_key(seed, pixel, dimension))[:, 0]
    if sampler not in SAMPLERS:
        raise ValueError(f"unknown sampler {sampler!r}; expected one of {', '.join(SAMPLERS)}")
    stratum = shuffled_strata(seed, pixel, sample, spp, dimension)
    return (stratum + uniform(seed, pixel, sample, dimension)) * (1.0 / spp)


def square_to_uniform_disk_concentric(u):
    """Shirley-Chiu concentric map of the unit square onto the unit disk.

    Area-preserving and low-distortion, so stratification of ``u`` survives the warp.

    Parameters
    ----------
    u : (n, 2) float
        Points in [0, 1)^2.

    Returns
    -------
    (n, 2) float
        Points in the unit disk; density 1/pi with respect to area.
    """
    a = 2.0 * u[:, 0] - 1.0
    b = 2.0 * u[:, 1] - 1.0
    use_a = np.abs(a) > np.abs(b)
    r = np.where(use_a, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(
            use_a, (np.pi / 4.0) * (b / a), (np.pi / 2.0) - (np.pi / 4.0) * (a / b)
        )
    phi = np.nan_to_num(phi)  # a == b == 0 maps to the centre whatever phi is
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)


def square_to_cosine_hemisphere(u):
    """Cosine-weighted directions on the hemisphere around +z (Malley's method).

    Parameters
    ----------
    u : (n, 2) float
        Points in [0, 1)^2.

    Returns
    -------
    (n, 3) float
        Unit directions with z >= 0; density cos(theta)/pi with respect to solid angle.
    """
    d = square_to_uniform_disk_concentric(u)
    z = np.sqrt(np.maximum(0.0, 1.0 - (d * d).sum(axis=1)))
    return np.column_stack([d, z])


def square_to_cosine_hemisphere_pdf(w):
    """Solid-angle density of :func:`square_to_cosine_hemisphere`: ``max(0, z) / pi``."""
    return np.maximum(0.0, w[:, 2]) / np.pi


def square_to_uniform_triangle(u):
    """Uniform points on a triangle, as barycentric weights of its vertices 1 and 2.

    ``(b1, b2) = sqrt(u0) * (1 - u1, u1)``: the Jacobian of the map is the constant 1/2, so
    the density is uniform over the triangle, and the map is continuous, so stratified
    ``u`` stay stratified on the triangle.

    Parameters
    ----------
    u : (n, 2) float
        Points in [0, 1)^2.

    Returns
    -------
    (n, 2) float
        Barycentric weights ``(b1, b2)`` with ``b1, b2 >= 0`` and ``b1 + b2 <= 1``
        (see :func:`rtmesh.accel.barycentric_interpolate`); density ``1 / area`` with respect
        to area on any triangle.
    """
    s = np.sqrt(u[:, 0])
    return np.stack([s * (1.0 - u[:, 1]), s * u[:, 1]], axis=1)


def uniform_triangle_to_square(b):
    """Inverse of :func:`square_to_uniform_triangle`, (n, 2) -> (n, 2)."""
    total = b[:, 0] + b[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        u1 = np.where(total > 0.0, b[:, 1] / total, 0.0)
    return np.stack([total * total, u1], axis=1)
