"""Sample generation: counter-based random numbers and pixel patterns (warps: :mod:`rtmesh.sampling.warps`).

Every random number in rtmesh is a pure function of ``(seed, pixel, sample, dimension)``,
computed by hashing those integers.  No generator state is carried between calls, so a
sample's value does not depend on which thread renders it, on the chunk it falls in, or on
how many other samples were drawn before it: renders are bit-identical for any thread count
and chunk size.

Dimensions used by the integrator are named in :class:`Dim`.  Every stratified quantity
(pixel position, lens, time, glossy direction, ambient-occlusion and area-light points) comes
from one machinery, :func:`pixel_offsets`, :func:`decorrelated_points` and
:func:`stratified_values` over a private ``_stratified``.  A pixel's sample index is global
across adaptive rounds: samples ``k spp .. (k + 1) spp - 1`` form the k-th stratified set
(jittered, zsobol), and any power-of-two prefix of the samples is stratified (Sobol).

``zsobol`` (:mod:`rtmesh.sampling.zsobol`) orders one image-wide sequence along a Morton
curve, so its points depend on where the pixel is: it needs the image's ``resolution``.
"""

import functools
import math
from enum import IntEnum

import numpy as np

from rtmesh.core.rays import component_major, take_rows
from rtmesh.sampling.hashing import GOLDEN, M1, mix64, pixel_sequence
from rtmesh.sampling.lowdiscrepancy import sobol_points
from rtmesh.sampling.zsobol import block_bits, check_layout, zorder_levels, zsobol_points

SAMPLERS = ("regular", "random", "jittered", "sobol", "zsobol")


class Dim(IntEnum):
    """Sample dimensions (pairs of uniform numbers) and what they drive."""

    PIXEL = 0  # (x, y) position inside the pixel
    LENS = 2  # (u, v) on the thin-lens aperture
    TIME = 4  # time in the shutter interval (one number; dimension 5 is unused)
    AO = 16  # first of the ambient-occlusion dimensions; AO rays at depth d use AO + 2*d
    LIGHT = 1 << 24  # first of the area-light dimensions (see rtmesh.sampling.sampler.light_dimension)
    GLOSSY = 1 << 25  # glossy-reflection directions; the rays spawned at depth d use GLOSSY + 2*d
    ALPHA = 1 << 26  # stochastic transparency of cut-outs, keyed by the ray (see rtmesh.geometry.cutouts)
    ENVIRONMENT = 1 << 27  # environment-light directions; the hits at depth d use ENVIRONMENT + 2*d
    BSDF = 1 << 28  # sampled BSDF directions (pair BSDF + 4*d) and lobe choices (BSDF + 4*d + 2) at depth d
    PATH_LIGHT = 1 << 29  # the path integrator's light point at its first vertex (a Sobol pair)
    PATH_BSDF = (1 << 29) + 2  # and its BSDF direction there
    PHOTON_POINT = (1 << 29) + 4  # a photon pass's emission points (Sobol pairs over the photon index)
    PHOTON_DIRECTION = (1 << 29) + 6  # and its emission directions
    DITHER = (1 << 29) + 8  # the blue-noise thresholds of 8-bit output (one number; see rtmesh.io.images)
    PATH_CHOICE = (1 << 29) + 10  # the path integrator's light choice at its first vertex (one number)


def dimension_key(seed, dimension):
    """64-bit key of one dimension of a render's samples (uint64): the part of
    :func:`sequence_key` that is the same for every pixel."""
    with np.errstate(over="ignore"):  # the multiplication is meant to wrap modulo 2**64
        return mix64(np.uint64(seed & 0xFFFFFFFFFFFFFFFF) * GOLDEN + np.uint64(dimension))


def sequence_key(seed, pixel, dimension):
    """64-bit key of the sample sequence of one pixel and dimension, (n,) -> (n,) uint64.

    Every sample of a pixel in a given dimension shares it; :func:`uniform` hashes the
    sample index into it, the Sobol sampler (:func:`rtmesh.sampling.lowdiscrepancy.sobol_points`,
    which forms it itself) derives its scrambling seeds from it.
    """
    with np.errstate(over="ignore"):  # the multiplication is meant to wrap modulo 2**64
        return pixel_sequence(dimension_key(seed, dimension), np.asarray(pixel, dtype=np.uint64))


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
        Component-major (see :mod:`rtmesh.core.rays`).
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


def pixel_offsets(sampler, seed, pixel, sample, spp, resolution=None):
    """Sample positions inside the pixel.

    Parameters
    ----------
    sampler : {"regular", "random", "jittered", "sobol", "zsobol"}
        See :func:`decorrelated_points`; ``regular`` puts the samples at the stratum centres,
        an ordered supersampling grid.
    seed : int
    pixel : (n,) int
        Linear pixel index of each sample.
    sample : (n,) int
        Sample index within its pixel, global across adaptive rounds: the jittered strata
        are ``sample % spp``.
    spp : int
        Samples per stratified set (the render's samples per pixel; a power of two for
        ``zsobol``).
    resolution : (int, int), optional
        Image width and height, which ``zsobol`` needs (the pixel's place on the Morton
        curve); the other samplers ignore it.

    Returns
    -------
    (n, 2) float64
        Offsets in [0, 1)^2 from the pixel's top-left corner (x right, y down),
        component-major (see :mod:`rtmesh.core.rays`).
    """
    return _stratified(sampler, seed, pixel, sample, spp, Dim.PIXEL, 0, 1, 2, resolution)


def decorrelated_points(sampler, seed, pixel, sample, spp, dimension, ray=0, rays=1, resolution=None):
    """Points in [0, 1)^2 for a dimension other than the pixel's: lens, glossy, AO, lights.

    The one sample machinery of the renderer for two-dimensional quantities.  Pixel
    sample ``sample`` gets ``rays`` points (``ray`` in ``[0, rays)``: the ambient-occlusion
    or shadow rays of its hit), and the ``spp * rays`` points of a pixel's set of ``spp``
    samples are stratified *together*:

    - ``jittered`` (and ``regular``, which jitters outside the pixel dimension: the same
      points in every pixel would turn the integration error into bands repeated across
      the image, a penumbra made of ``rays`` hard shadows) splits the square into
      ``rays`` cells (:func:`strata_shape`), each cut into ``spp`` strata.  Ray ``ray`` of
      every sample falls in cell ``ray``, so the rays of one hit are stratified among
      themselves, and in the stratum of that cell given by a per-pixel permutation of the
      samples (:func:`shuffled_strata`), so the ``spp`` samples fill every stratum once
      and the strata are not paired with the pixel strata;
    - ``sobol`` takes point ``sample * rays + ray`` of an Owen-scrambled (0,2)-sequence
      scrambled per pixel and dimension: every power-of-two prefix of a pixel's points is
      stratified in all elementary intervals, as is, for power-of-two ``rays``, the set of
      one hit;
    - ``zsobol`` takes point ``sample * rays + ray`` of the pixel's block of one image-wide
      Owen-scrambled (0,2)-sequence ordered along a Morton curve (:mod:`rtmesh.sampling.zsobol`):
      each pixel's points are stratified as ``sobol``'s (for power-of-two ``spp * rays``),
      and neighbouring pixels' points complement each other (blue-noise error);
    - ``random`` places the points uniformly and independently.

    Each point is a pure function of ``(seed, pixel, sample, ray, dimension)``; sample
    indices past ``spp`` (later adaptive rounds) form further stratified sets.

    Parameters
    ----------
    sampler : {"regular", "random", "jittered", "sobol", "zsobol"}
    seed : int
    pixel, sample : (n,) int
        Linear pixel index and sample index within the pixel.
    spp : int
        Samples per stratified set.
    dimension : int
        First of the two dimensions the point uses (see :class:`Dim`).
    ray : int or (n,) int, optional
        Which of the sample's points, in ``[0, rays)``.
    rays : int, optional
        Points per pixel sample, >= 1.
    resolution : (int, int), optional
        Image width and height (``zsobol`` only; see :func:`pixel_offsets`).

    Returns
    -------
    (n, 2) float64
        Component-major (see :mod:`rtmesh.core.rays`).
    """
    return _stratified(sampler, seed, pixel, sample, spp, dimension, ray, rays, 2, resolution)


def stratified_values(sampler, seed, pixel, sample, spp, dimension, resolution=None):
    """One number in [0, 1) per pixel sample, the ``spp`` numbers of a set stratified.

    For one-dimensional quantities such as the time in the shutter: the one-dimensional
    case of :func:`decorrelated_points`.  ``jittered`` and ``regular`` put exactly one value
    of each set of ``spp`` samples in each interval ``[k / spp, (k + 1) / spp)``, assigned
    to the samples by :func:`shuffled_strata`; ``sobol`` uses the first coordinate of the
    scrambled (0,2)-sequence, a (0,1)-sequence: every power-of-two prefix is stratified the
    same way, as does ``zsobol``'s; ``random`` is uniform.

    Parameters
    ----------
    sampler : {"regular", "random", "jittered", "sobol", "zsobol"}
    seed : int
    pixel, sample : (n,) int
    spp : int
    dimension : int
    resolution : (int, int), optional
        Image width and height (``zsobol`` only; see :func:`pixel_offsets`).

    Returns
    -------
    (n,) float64
    """
    return _stratified(sampler, seed, pixel, sample, spp, dimension, 0, 1, 1, resolution)


def shuffled_strata(seed, pixel, sample, spp, dimension, ray=0, rays=1):
    """A per-pixel permutation of the strata ``[0, spp)``, applied to sample indices.

    Jittered points of every dimension would put sample ``i`` in stratum ``i``, so without
    a shuffle the sample in the top-left pixel stratum would always get, say, the first lens
    or time stratum: the dimensions would be correlated and a moving edge would sweep across
    the pixel in step with the time.  Each set of ``spp`` samples of a pixel gets, in each
    dimension and for each ray of :func:`decorrelated_points`, the permutation
    ``i -> (a i + b) mod spp`` with hashed ``a`` (a unit modulo ``spp``) and ``b``: computed
    point by point, so it works on any subset of a pixel's samples (rays that survive to
    depth d), and independent between pixels, dimensions, rays and sets.

    Parameters
    ----------
    seed : int
    pixel : (n,) int
    sample : (n,) int
        Sample index within the pixel.  Indices past ``spp`` (samples added in later rounds)
        belong to the set ``sample // spp``, which gets its own permutation.
    spp : int
        Samples per stratified set.
    dimension : int
    ray : int or (n,) int, optional
    rays : int, optional
        See :func:`decorrelated_points`.

    Returns
    -------
    (n,) int64
        The permuted index, in the same set of ``spp`` as ``sample``.
    """
    sample = np.asarray(sample, dtype=np.int64)
    stratum = sample % spp
    return (sample - stratum) + _permuted_strata(seed, pixel, sample, spp, dimension, ray, rays)


def _permuted_strata(seed, pixel, sample, spp, dimension, ray, rays):
    """The stratum ``shuffled_strata`` gives each sample, in ``[0, spp)``, (n,) int64."""
    stratum = np.asarray(sample, dtype=np.int64) % spp
    if spp == 1:
        return stratum
    key = sequence_key(seed, pixel, dimension)
    # one permutation per (set, ray): the set and ray index hashed into the pixel's key
    stream = (np.asarray(sample, dtype=np.int64) // spp) * rays + ray
    with np.errstate(over="ignore"):  # the multiplication is meant to wrap modulo 2**64
        key = mix64(key + stream.astype(np.uint64) * GOLDEN)
    a = _units(spp)[(key >> np.uint64(32)) % np.uint64(len(_units(spp)))]
    b = ((key & np.uint64(0xFFFFFFFF)) % np.uint64(spp)).astype(np.int64)
    return (a * stratum + b) % spp


@functools.lru_cache(maxsize=64)
def _units(spp):
    """The units modulo ``spp`` (the multipliers of an affine permutation), (k,) int64."""
    return np.flatnonzero(np.gcd(np.arange(spp), spp) == 1).astype(np.int64)


@functools.lru_cache(maxsize=64)
def _cell_grids(rays, spp, dims):
    """Cell and stratum grids of one stratified set of ``rays`` points per sample.

    Returns
    -------
    cells : (int, int)
        ``(cx, cy)``: the ``rays`` cells (one per ray) tiling the square, or the unit
        interval (``cy == 1``) when ``dims == 1``.
    strata : (int, int)
        ``(sx, sy)``: each cell cut into ``spp`` strata, chosen so that the joint grid of
        ``cx * sx`` by ``cy * sy`` strata is as square as the factors allow (with a single
        ray it is :func:`strata_shape` of ``spp``).
    table : (spp, 2) float64
        Column and row of each stratum inside its cell, component-major: a gather from a
        tiny table is much cheaper than dividing every index by ``sx``.
    """
    if dims == 1:
        cells, strata = (rays, 1), (spp, 1)
    else:
        cells = strata_shape(rays)
        pairs = [(spp // ny, ny) for ny in range(1, spp + 1) if spp % ny == 0]
        # squarest joint grid; among equals the wider one, as strata_shape
        strata = min(pairs, key=lambda p: (abs(math.log(cells[0] * p[0] / (cells[1] * p[1]))),
                                           -cells[0] * p[0]))
    k = np.arange(spp)
    table = component_major(np.stack([k % strata[0], k // strata[0]]).astype(np.float64))
    return cells, strata, table


def _stratified(sampler, seed, pixel, sample, spp, dimension, ray, rays, dims, resolution=None):
    """Every sampler's points: see :func:`decorrelated_points`.

    ``dims`` is 2 for points in [0, 1)^2, returned as (n, 2) component-major, or 1 for
    values in [0, 1), returned as (n,).  The pixel dimension (:attr:`Dim.PIXEL`) keeps
    sample ``i`` in stratum ``i % spp`` (the reference the other dimensions are shuffled
    against) and ``regular`` puts it at the stratum's centre.
    """
    if sampler not in SAMPLERS:
        raise ValueError(f"unknown sampler {sampler!r}; expected one of {', '.join(SAMPLERS)}")
    sample = np.asarray(sample, dtype=np.int64)
    index = sample * rays + ray if rays > 1 else sample
    if sampler == "random":
        if dims == 1:
            return uniform(seed, pixel, index, dimension)
        return uniform2(seed, pixel, index, dimension)
    if sampler == "sobol":
        points = sobol_points(np.ascontiguousarray(index, dtype=np.int64), dimension_key(seed, dimension),
                              np.ascontiguousarray(pixel, dtype=np.int64), dims)
        return points[0] if dims == 1 else points.T
    if sampler == "zsobol":
        if resolution is None:
            raise ValueError("the zsobol sampler needs the image resolution")
        width, height = resolution
        check_layout(width, height, spp, rays)
        ray = np.ascontiguousarray(np.broadcast_to(np.asarray(ray, dtype=np.int64), sample.shape))
        points = zsobol_points(np.ascontiguousarray(sample), ray, dimension_key(seed, dimension),
                               np.ascontiguousarray(pixel, dtype=np.int64), width, (spp - 1).bit_length(), rays,
                               zorder_levels(width, height), block_bits(spp, rays), dims)
        return points[0] if dims == 1 else points.T
    (cx, cy), (sx, sy), table = _cell_grids(rays, spp, dims)
    if dimension == Dim.PIXEL:
        stratum = sample % spp if spp > 1 else np.zeros_like(sample)
    else:
        stratum = _permuted_strata(seed, pixel, sample, spp, dimension, ray, rays)
    if dims == 1:
        jitter = uniform(seed, pixel, index, dimension)
        return ((ray * spp + stratum) + jitter) * (1.0 / (rays * spp))
    size = np.array([cx * sx, cy * sy], dtype=np.float64)
    if sampler == "regular" and dimension == Dim.PIXEL and rays == 1:
        # the stratum centres: the same spp points in every pixel, formed once per call
        # and gathered (the same arithmetic as below, on spp rows instead of n)
        return take_rows(component_major(((table + 0.5) / size).T), stratum)
    jitter = uniform2(seed, pixel, index, dimension)
    corner = take_rows(table, stratum)
    if rays > 1:
        ray = np.asarray(ray, dtype=np.int64)
        cell = np.stack([ray % cx * sx, ray // cx * sy]).astype(np.float64)
        corner = corner + (component_major(cell) if ray.ndim else cell)
    return (corner + jitter) / size
