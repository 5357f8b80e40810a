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
    AO = 16  # first of the ambient-occlusion dimensions; AO ray k at depth d uses AO + 2*(k + d*1024)


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
        ``regular`` puts the samples at the centres of an ``nx x ny`` grid of strata,
        ``random`` places them uniformly, ``jittered`` puts one uniform sample in each stratum,
        ``sobol`` takes them from an Owen-scrambled (0,2)-sequence scrambled per pixel, so
        every power-of-two prefix of a pixel's samples is stratified.
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
    if sampler == "random":
        return uniform2(seed, pixel, sample, Dim.PIXEL)
    if sampler == "sobol":
        points = sobol_02(sample, sequence_key(seed, pixel, Dim.PIXEL))
        return component_major(points.T)
    if sampler not in SAMPLERS:
        raise ValueError(f"unknown sampler {sampler!r}; expected one of {', '.join(SAMPLERS)}")
    nx, ny = strata_shape(spp)
    size = np.array([nx, ny], dtype=np.float64)
    # the spp strata are worked out once and looked up per sample: a gather from a tiny
    # table is much cheaper than integer division of every sample index
    strata = np.arange(spp)
    cells = component_major(np.stack([strata % nx, strata // nx]).astype(np.float64))
    if sampler == "regular":
        return take_rows((cells + 0.5) / size, sample)
    return (take_rows(cells, sample) + uniform2(seed, pixel, sample, Dim.PIXEL)) / size


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
