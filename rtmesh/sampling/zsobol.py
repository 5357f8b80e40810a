"""Blue-noise Sobol points: sample indices along a Morton curve with per-level digit permutations.

The ``zsobol`` sampler (Ahmed & Wonka, "Screen-space blue-noise diffusion of Monte Carlo
sampling error via hierarchical ordering of pixels", SIGGRAPH Asia 2020; pbrt-v4's
``ZSobolSampler``) draws every dimension from *one* Owen-scrambled (0,2)-sequence shared by
the whole image, instead of one sequence per pixel.  Pixel ``p``'s samples are the block of
``2^k`` consecutive points that starts at its Morton code times ``2^k``, so the four pixels
of every 2x2 quad hold one aligned block of ``4 * 2^k`` points (a finer net), every 4x4
group one of ``16 * 2^k``, and so on: neighbouring pixels get complementary points, and the
image's error becomes high-frequency (blue) noise.  The base-4 digits of the index (one per
level of the quadtree) are permuted at random, each by a permutation chosen from the digits
above it and the dimension, so the quadrants of every node come in a random order
(pbrt-v4's ``GetSampleIndex``) and dimensions are decorrelated.

Differences from pbrt-v4:

- the bits of the pixel's own block (its samples) are scrambled bit by bit, each flipped by
  a hash of the bits above it, where pbrt permutes them as base-4 digits too: a nested
  binary scramble keeps every aligned power-of-two subset of a pixel's points an aligned
  block of the sequence, so the rays of one hit and the first ``2^k`` samples of a pixel
  stay nets (a base-4 permutation scatters the two halves of a digit);
- the points are Owen-scrambled bit by bit (:func:`owen_scramble`, pbrt's ``OwenScrambler``)
  rather than by pbrt's default Laine-Karras hash (measured in :func:`owen_scramble`);

- ``rays`` points per pixel sample (shadow or ambient-occlusion rays of one hit) take
  in-pixel indices ``sample * rays + ray``; a pixel's block holds ``spp * rays`` points
  rounded up to a power of two;
- adaptive rounds continue a pixel's index past ``spp``: the set ``sample // spp`` (the
  round) sits above the Morton digits, and the digits below it are permuted from it too, so
  each round is a complete blue-noise pattern of its own (round 0 is pbrt's);
- indices are 32-bit: bits above 32 (only images with more than ``2^32 / spp`` pixels, or
  late rounds of large ones) are dropped after the permutation, which has already mixed
  them into the digits below.
"""

import itertools

import numpy as np

from rtmesh.core.compiled import kernel, row
from rtmesh.sampling.hashing import GOLDEN, mix64, permutation_element, pixel_sequence, uniform
from rtmesh.sampling.lowdiscrepancy import (SOBOL1_TABLES, reverse_bits, scramble_seed, seeded_sobol_pair, sobol_bits,
                                            sobol_pair, sobol_seeds)

# the 24 permutations of a base-4 digit, one row each
PERMUTATIONS = np.array(list(itertools.permutations(range(4))), dtype=np.uint64)
# the largest index width (Morton digits and a pixel's block) the 64-bit layout holds with
# the round above it
MAX_INDEX_BITS = 62
# a kernel's sequence_keys record: the layout after the dimension keys
ZORDER, WIDTH, LEVELS, LOG2_SPP = 0, 1, 2, 3
_LOW32 = np.uint64(0xFFFFFFFF)
_TO_UNIT = 1.0 / 4294967296.0  # 2 ** -32: a 0.32 fixed-point value as a double in [0, 1)
_ONE, _TWO, _THREE = np.uint64(1), np.uint64(2), np.uint64(3)


def zorder_levels(width, height):
    """Levels of the quadtree over the image: ``log2`` of its larger side rounded up to a
    power of two (0 for one pixel)."""
    return (max(int(width), int(height)) - 1).bit_length()


def block_bits(spp, rays=1):
    """``log2`` of a pixel's block: ``spp * rays`` rounded up to a power of two."""
    return (int(spp) * int(rays) - 1).bit_length()


def index_bits(width, height, spp, rays=1):
    """Bits of the index below the round: two per quadtree level and a pixel's block."""
    return 2 * zorder_levels(width, height) + block_bits(spp, rays)


def rounded_spp(spp):
    """``spp`` rounded up to a power of two, as the sampler needs it."""
    return 1 << (int(spp) - 1).bit_length()


@row
def spread_bits(v):
    """The low 32 bits of ``v`` (uint64) moved to the even bit positions."""
    v = v & np.uint64(0xFFFFFFFF)
    v = (v | (v << np.uint64(16))) & np.uint64(0x0000FFFF0000FFFF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x00FF00FF00FF00FF)
    v = (v | (v << np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    v = (v | (v << np.uint64(2))) & np.uint64(0x3333333333333333)
    return (v | (v << _ONE)) & np.uint64(0x5555555555555555)


@row
def morton_code(pixel, width):
    """Morton code of the linear pixel index ``pixel`` (row-major, ``width`` columns; uint64
    both): the column's bits at even positions, the row's at odd ones (pbrt's
    ``EncodeMorton2(x, y)``)."""
    line = pixel // width
    column = pixel - line * width
    return spread_bits(column) | (spread_bits(line) << _ONE)


@row
def zsobol_index(permutation_key, morton, sample, ray, log2_spp, rays, levels, log2_block):
    """The global sequence index of one point: pbrt-v4's ``GetSampleIndex``, with the round
    above the Morton digits and the pixel's own bits scrambled one by one (module notes).

    Parameters
    ----------
    permutation_key : uint64
        The dimension's key of the digit permutations.
    morton : uint64
        The pixel's :func:`morton_code`.
    sample : uint64
        The sample's index in its pixel, global across rounds.
    ray : uint64
        Which of the sample's ``rays`` points.
    log2_spp, rays, levels, log2_block : uint64
        ``log2`` of the (power-of-two) samples per round, points per sample,
        :func:`zorder_levels` and :func:`block_bits`.

    Returns
    -------
    uint64
        The permuted index (below ``2^64``; the caller keeps 32 bits).
    """
    set_index = sample >> log2_spp
    in_pixel = (sample & ((_ONE << log2_spp) - _ONE)) * rays + ray
    high = block_high(morton, set_index, levels, log2_block)
    return block_index(permutation_key, high, levels, log2_block) | pixel_bits(permutation_key, high, in_pixel,
                                                                               log2_block)


@row
def block_high(morton, set_index, levels, log2_block):
    """The unpermuted index of a pixel's block in one round: the round above the Morton code,
    the pixel's own ``log2_block`` bits zero (uint64)."""
    return (set_index << (levels + levels + log2_block)) | (morton << log2_block)


@row
def block_index(permutation_key, high, levels, log2_block):
    """The permuted index of the block :func:`block_high` gives: the round as it is, the
    quadtree's base-4 digits from the top, each permuted by the digits above it (the same
    for all of a pixel's points in a round, so kernels form it once)."""
    index = (high >> (levels + levels + log2_block)) << (levels + levels + log2_block)
    for level in range(np.int64(levels) - 1, -1, -1):
        shift = log2_block + np.uint64(2 * level)
        digit = (high >> shift) & _THREE
        chosen = (mix64((high >> (shift + _TWO)) ^ permutation_key) >> np.uint64(24)) % np.uint64(24)
        index |= PERMUTATIONS[chosen, digit] << shift
    return index


@row
def pixel_bits(permutation_key, high, in_pixel, log2_block):
    """The pixel's own ``log2_block`` bits of the index (``in_pixel``), each flipped by a
    hash of the bits above it (those of ``high`` too)."""
    z = high | in_pixel
    bits = np.uint64(0)
    for bit in range(np.int64(log2_block) - 1, -1, -1):
        shift = np.uint64(bit)
        flip = mix64((z >> (shift + _ONE)) ^ permutation_key) & _ONE
        bits |= (((z >> shift) & _ONE) ^ flip) << shift
    return bits


@row
def owen_scramble(v, seed):
    """Nested uniform (Owen) scrambling of a 0.32 fixed-point value ``v`` (uint64 word) with
    ``seed``: every bit is flipped by a random bit of the node of the binary tree its
    higher bits lead to.

    One hash serves four bits: the hash of the bits above a group of four (with a marker
    bit for their length) gives the 15 flips of the group's subtree (1 + 2 + 4 + 8 nodes).
    Exact like pbrt-v4's ``OwenScrambler`` (one hash a bit), at an eighth of its hashes.
    The Laine-Karras hash of :func:`rtmesh.sampling.lowdiscrepancy.nested_uniform_scramble`,
    which the per-pixel sequences of ``sobol`` use, is cheaper still but leaves a low bit's
    flip nearly independent of the bits far above it: harmless with a seed per pixel, but
    under zsobol's one image-wide scramble the points of a pixel (which differ in their top
    bits only) got nearly the same offsets inside their strata (correlation 0.82 of the
    offsets, against 0.10 with this scrambling; docs/SAMPLERS.md).
    """
    out = v
    for group in range(8):
        above = np.uint64(4 * group)
        prefix = (v >> (np.uint64(32) - above)) if group > 0 else np.uint64(0)
        h = mix64(((_ONE << above) | prefix) ^ seed)
        for t in range(4):
            position = np.uint64(31 - 4 * group - t)
            node = ((v >> (position + _ONE)) & ((_ONE << np.uint64(t)) - _ONE)) + (_ONE << np.uint64(t)) - _ONE
            out ^= ((h >> node) & _ONE) << position
    return out


@row
def permutation_key(key):
    """The key of a dimension's digit permutations, from its key (uint64)."""
    return mix64(key + GOLDEN * np.uint64(4))


@row
def zsobol_point(key, index, dims):
    """Point ``index`` (uint64; its low 32 bits are used) of the (0,2)-sequence of the
    dimension keyed ``key``, Owen-scrambled: ``(x, y)`` in [0, 1)^2 (``y`` 0 when ``dims``
    is 1)."""
    index = index & _LOW32
    x = np.float64(owen_scramble(reverse_bits(index), scramble_seed(key, 2))) * _TO_UNIT
    if dims == 1:
        return x, 0.0
    return x, np.float64(owen_scramble(sobol_bits(index, SOBOL1_TABLES), scramble_seed(key, 3))) * _TO_UNIT


@row
def zsobol_pair(key, morton, sample, ray, log2_spp, rays, levels, log2_block):
    """Point ``(x, y)`` in [0, 1)^2 of one pixel sample in the dimension keyed ``key``
    (:func:`rtmesh.sampling.patterns.dimension_key`: the same for every pixel): the
    :func:`zsobol_index` point of the (0,2)-sequence, Owen-scrambled per dimension.  The
    other arguments are :func:`zsobol_index`'s."""
    index = zsobol_index(permutation_key(key), morton, sample, ray, log2_spp, rays, levels, log2_block)
    return zsobol_point(key, index, 2)


@kernel
def zsobol_points(sample, ray, dimension_key, pixel, width, log2_spp, rays, levels, log2_block, dims):
    """:func:`zsobol_pair` points of many samples; a run of points of one pixel and round
    (the rays of a hit, a pixel's samples) permutes the Morton digits once.

    Parameters
    ----------
    sample : (n,) int64
        Each point's sample index in its pixel (global across rounds).
    ray : (n,) int64
        Which of its sample's ``rays`` points.
    dimension_key : uint64
    pixel : (n,) int64
        Each point's pixel (linear index).
    width : int
        Image columns.
    log2_spp, rays, levels, log2_block : int
        See :func:`zsobol_index`.
    dims : int
        1: the first coordinate only; 2: both.

    Returns
    -------
    (dims, n) float64
        Points in [0, 1)^2, component-major.
    """
    n = len(sample)
    points = np.empty((dims, n))
    w, s, r = np.uint64(width), np.uint64(log2_spp), np.uint64(rays)
    lv, lb = np.uint64(levels), np.uint64(log2_block)
    key = permutation_key(dimension_key)
    mask = (_ONE << s) - _ONE
    last_pixel, last_set = np.int64(-1), np.uint64(0)
    high = start = np.uint64(0)
    for i in range(n):
        set_index = np.uint64(sample[i]) >> s
        if pixel[i] != last_pixel or set_index != last_set:
            last_pixel, last_set = pixel[i], set_index
            high = block_high(morton_code(np.uint64(pixel[i]), w), set_index, lv, lb)
            start = block_index(key, high, lv, lb)
        in_pixel = (np.uint64(sample[i]) & mask) * r + np.uint64(ray[i])
        x, y = zsobol_point(dimension_key, start | pixel_bits(key, high, in_pixel, lb), dims)
        points[0, i] = x
        if dims == 2:
            points[1, i] = y
    return points


def check_layout(width, height, spp, rays=1):
    """Raise ValueError unless ``spp`` is a power of two and the image and its points per
    pixel fit the 64-bit layout (:data:`MAX_INDEX_BITS`)."""
    if spp & (spp - 1):
        raise ValueError(f"the zsobol sampler needs a power-of-two spp (got {spp})")
    bits = index_bits(width, height, spp, rays)
    if bits > MAX_INDEX_BITS:
        raise ValueError(f"the zsobol sampler's index needs {bits} bits for a {width}x{height} image with "
                         f"{spp * rays} points a pixel (at most {MAX_INDEX_BITS})")


def sequence_keys(sampler, seed, dimensions, spp, resolution):
    """The record :func:`sequence_pair` reads: the layout, then one key per dimension.

    Parameters
    ----------
    sampler : {"sobol", "zsobol"}
    seed : int
    dimensions : sequence of int
        The (first) dimension of each pair (:class:`rtmesh.sampling.patterns.Dim`).
    spp : int
        Samples per stratified set.
    resolution : (int, int)
        Image width and height.

    Returns
    -------
    (4 + len(dimensions),) uint64
        ``[zorder, width, levels, log2(spp)]`` (``zorder`` 1 under zsobol; all 0 under
        sobol), then the keys (:func:`rtmesh.sampling.patterns.dimension_key`).
    """
    from rtmesh.sampling.patterns import dimension_key  # patterns imports this module

    layout = [0, 0, 0, 0]
    if sampler == "zsobol":
        check_layout(*resolution, spp)
        layout = [1, resolution[0], zorder_levels(*resolution), block_bits(spp)]
    return np.array(layout + [dimension_key(seed, d) for d in dimensions], dtype=np.uint64)


@row
def sequence_pair(keys, which, pixel, sample):
    """Point ``(x, y)`` of one pixel sample (int64 ``pixel`` and ``sample``, one ray) in
    the dimension ``which`` of a :func:`sequence_keys` record: the pixel's own Owen-scrambled
    sequence (sobol, :func:`rtmesh.sampling.lowdiscrepancy.sobol_pair`) or its block of the
    image's Morton-ordered one (zsobol, :func:`zsobol_pair`)."""
    key = keys[4 + which]
    if keys[ZORDER] == _ONE:
        log2_spp = keys[LOG2_SPP]
        return zsobol_pair(key, morton_code(np.uint64(pixel), keys[WIDTH]), np.uint64(sample), np.uint64(0),
                           log2_spp, _ONE, keys[LEVELS], log2_spp)
    return sobol_pair(pixel_sequence(key, np.uint64(pixel)), sample)


@row
def sequence_number(keys, which, pixel, sample, ray, rays, log2_block):
    """One number in [0, 1) of ray ``ray`` of the ``rays`` a pixel sample sends (int64 all)
    in the dimension ``which`` of a :func:`sequence_keys` record, for a one-dimensional choice
    (the light a light sample takes): a pixel's ``spp * rays`` numbers fall in distinct
    strata of ``2^log2_block``, and which sample gets which stratum does not follow the
    sample index.

    Under zsobol, the first coordinate of :func:`sequence_ray_pair`'s point (blue noise
    across pixels; zsobol's per-dimension digit permutations decorrelate it from the other
    dimensions, as in pbrt-v4).  Under sobol, a jittered point in stratum
    :func:`rtmesh.sampling.hashing.permutation_element` of the sample's index within its
    block, as pbrt-v4's padded samplers draw one-dimensional samples: a random permutation
    of the index, where the nested index scramble of :func:`sequence_ray_pair` keeps aligned
    blocks of indices together.  (The first coordinate of the dimension's own Sobol
    sequence, as under zsobol, was not measured against it.)
    """
    key = keys[4 + which]
    if keys[ZORDER] == _ONE:
        return zsobol_pair(key, morton_code(np.uint64(pixel), keys[WIDTH]), np.uint64(sample), np.uint64(ray),
                           keys[LOG2_SPP], np.uint64(rays), keys[LEVELS], np.uint64(log2_block))[0]
    j = sample * rays + ray
    block = np.int64(1) << log2_block
    # one permutation per pixel and block of indices (adaptive rounds continue the index)
    stream = mix64(pixel_sequence(key, np.uint64(pixel)) ^ (np.uint64(j >> log2_block) * GOLDEN))
    within = j & (block - 1)
    stratum = permutation_element(within, block, stream)
    return (stratum + uniform(stream, within)) / block


@row
def sequence_ray_pair(keys, which, pixel, sample, ray, rays, log2_block):
    """Point ``(x, y)`` of ray ``ray`` of the ``rays`` a pixel sample sends (int64 all) in
    the dimension ``which`` of a :func:`sequence_keys` record: index ``sample * rays + ray``
    of the pixel's own sequence (sobol), or in-pixel index ``sample * rays + ray`` of its
    block of ``2^log2_block`` points (:func:`block_bits` of ``spp`` and ``rays``) of the
    image's Morton-ordered one (zsobol), so the ``spp * rays`` points of a pixel form one
    stratified set and the rays of one sample an aligned block of it.  One ray
    (``ray`` 0, ``rays`` 1, ``log2_block`` the record's ``log2(spp)``) is
    :func:`sequence_pair`'s point."""
    return seeded_ray_pair(keys, which, sequence_seeds(keys, which, pixel), pixel, sample, ray, rays, log2_block)


@row
def sequence_seeds(keys, which, pixel):
    """What :func:`sequence_ray_pair` forms once per pixel and dimension (int64 ``pixel``):
    the scrambling seeds of the pixel's own sequence under sobol
    (:func:`rtmesh.sampling.lowdiscrepancy.sobol_seeds`); zeros under zsobol, whose points
    take none.  For a caller drawing many points of one pixel's dimension
    (:func:`seeded_ray_pair`)."""
    if keys[ZORDER] == _ONE:
        return np.uint64(0), np.uint64(0), np.uint64(0)
    return sobol_seeds(pixel_sequence(keys[4 + which], np.uint64(pixel)))


@row
def seeded_ray_pair(keys, which, seeds, pixel, sample, ray, rays, log2_block):
    """:func:`sequence_ray_pair` with the pixel's :func:`sequence_seeds` of dimension
    ``which`` given."""
    if keys[ZORDER] == _ONE:
        return zsobol_pair(keys[4 + which], morton_code(np.uint64(pixel), keys[WIDTH]), np.uint64(sample),
                           np.uint64(ray), keys[LOG2_SPP], np.uint64(rays), keys[LEVELS], np.uint64(log2_block))
    return seeded_sobol_pair(seeds, sample * rays + ray)
