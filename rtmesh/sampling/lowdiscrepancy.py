"""Owen-scrambled Sobol (0,2)-sequence points, decorrelated per pixel by hashing.

The first two Sobol dimensions form a (0,2)-sequence: every prefix of ``2^m`` points puts
exactly one point in each elementary interval of area ``2^-m`` (all ``2^a x 2^b`` grids with
``a + b = m``), so any power-of-two prefix is stratified in every such way at once — what
adaptive sampling needs when it adds samples in rounds.  Nested uniform (Owen) scrambling
keeps that property while making each pixel's points independent random draws; it is done
with the hash-based permutation of Burley, "Practical Hash-based Owen Scrambling" (JCGT
2020), so it needs no tables and no state.
"""

import numpy as np

from rtmesh.core.compiled import kernel, row
from rtmesh.sampling.hashing import GOLDEN, mix64, pixel_sequence

_BITS = 32

# generator matrices as 32 column vectors (most significant bit first): dimension 0 is
# van der Corput (bit reversal, column k is 1 << (31 - k)), dimension 1 is Sobol's second
# dimension, whose direction numbers follow from the primitive polynomial x + 1:
# v_k = v_{k-1} ^ (v_{k-1} >> 1)
_SOBOL1 = np.zeros(_BITS, dtype=np.uint32)
_SOBOL1[0] = 1 << 31
for _k in range(1, _BITS):
    _SOBOL1[_k] = _SOBOL1[_k - 1] ^ (_SOBOL1[_k - 1] >> 1)

# uint32 arithmetic in uint64 words: numba widens 32-bit integers to 64 bits, so every
# product and sum is cut back to its low 32 bits, which is what wrapping uint32 gives
_LOW32 = np.uint64(0xFFFFFFFF)
_TO_UNIT = 1.0 / 4294967296.0  # 2 ** -32: a 0.32 fixed-point value as a double in [0, 1)


@row
def reverse_bits(x):
    """Reverse the 32 bits of ``x`` (a uint64 holding a uint32).

    Swaps neighbouring bits, pairs and nibbles (reversing each byte), then the bytes:
    branch-free, so loops over points vectorise.
    """
    one, two, four = np.uint64(1), np.uint64(2), np.uint64(4)
    x = ((x >> one) & np.uint64(0x55555555)) | ((x & np.uint64(0x55555555)) << one)
    x = ((x >> two) & np.uint64(0x33333333)) | ((x & np.uint64(0x33333333)) << two)
    x = ((x >> four) & np.uint64(0x0F0F0F0F)) | ((x & np.uint64(0x0F0F0F0F)) << four)
    return (((x >> np.uint64(24)) & np.uint64(0xFF)) | ((x >> np.uint64(8)) & np.uint64(0xFF00))
            | ((x << np.uint64(8)) & np.uint64(0xFF0000)) | ((x << np.uint64(24)) & np.uint64(0xFF000000)))


@row
def laine_karras_permutation(x, seed):
    """Burley's improved Laine-Karras hash of ``x`` with ``seed`` (uint32 values in uint64
    words): a permutation that only lets each bit depend on the bits below it, which is
    exactly nested uniform scrambling once bits are reversed."""
    x = x ^ ((x * np.uint64(0x3D20ADEA)) & _LOW32)
    x = (x + seed) & _LOW32
    x = (x * ((seed >> np.uint64(16)) | np.uint64(1))) & _LOW32
    x = x ^ ((x * np.uint64(0x05526C56)) & _LOW32)
    return x ^ ((x * np.uint64(0x53A22864)) & _LOW32)


@row
def nested_uniform_scramble(x, seed):
    """Owen-scramble a 32-bit fixed-point value (uint64 word) with ``seed``."""
    return reverse_bits(laine_karras_permutation(reverse_bits(x), seed))


def _byte_tables(matrix):
    """The products of a generator matrix with every byte, one table per byte position.

    Multiplication over GF(2) is linear in the bits of the index, so ``index * matrix`` is
    the XOR of the products of its four bytes: four table look-ups instead of a 32-step
    loop over bits (a scrambled index has all 32 bits in use).

    Returns
    -------
    (4, 256) uint64
        ``tables[b, v]``: the XOR of the columns ``matrix[8 b + k]`` for the bits ``k`` set
        in ``v``.
    """
    bits = (np.arange(256)[:, None] >> np.arange(8)) & 1  # (256, 8): bit k of each byte
    return np.stack([np.bitwise_xor.reduce(bits * matrix[8 * b:8 * b + 8].astype(np.int64), axis=1)
                     for b in range(4)]).astype(np.uint64)


SOBOL1_TABLES = _byte_tables(_SOBOL1)


@row
def sobol_bits(index, tables):
    """Multiply the bits of ``index`` (a uint32 in a uint64 word) by a generator matrix over
    GF(2), given as its :func:`_byte_tables`."""
    byte = np.uint64(0xFF)
    return (tables[0, index & byte] ^ tables[1, (index >> np.uint64(8)) & byte]
            ^ tables[2, (index >> np.uint64(16)) & byte] ^ tables[3, (index >> np.uint64(24)) & byte])


@row
def scramble_seed(key, which):
    """Independent 32-bit scrambling seed number ``which`` (1, 2, 3, ...) of a sequence keyed
    ``key`` (uint64), in a uint64 word."""
    return mix64(key + GOLDEN * np.uint64(which)) >> np.uint64(32)


@row
def owen_sobol_pair(index, seed_x, seed_y):
    """Point ``index`` (a uint32 in a uint64 word) of the (0,2)-sequence, each coordinate
    Owen-scrambled with its own seed (:func:`scramble_seed`), ``(x, y)`` in [0, 1)^2: values
    in 0.32 fixed point, so exact doubles."""
    # the first dimension's generator is the bit reversal, which the scramble's own
    # reversal undoes
    x = reverse_bits(laine_karras_permutation(index, seed_x))
    y = nested_uniform_scramble(sobol_bits(index, SOBOL1_TABLES), seed_y)
    return np.float64(x) * _TO_UNIT, np.float64(y) * _TO_UNIT


@row
def sobol_pair(key, index):
    """Point ``index`` (below 2**32) of the Owen-scrambled (0,2)-sequence keyed ``key`` (a
    pixel's sequence key, :func:`rtmesh.sampling.patterns.sequence_key`), ``(x, y)`` in
    [0, 1)^2: values in 0.32 fixed point, so exact doubles."""
    return seeded_sobol_pair(sobol_seeds(key), index)


@row
def sobol_seeds(key):
    """The three 32-bit scrambling seeds of the sequence keyed ``key`` (uint64 words): of
    the index shuffle, of x and of y.  Scrambling the index permutes points only inside
    aligned power-of-two blocks, so every power-of-two prefix is still a whole
    (0,m,2)-net; it decorrelates pixels.  Formed once, for a caller drawing many points of
    one sequence (:func:`seeded_sobol_pair`)."""
    return scramble_seed(key, 1), scramble_seed(key, 2), scramble_seed(key, 3)


@row
def seeded_sobol_pair(seeds, index):
    """:func:`sobol_pair` of the sequence whose :func:`sobol_seeds` are ``seeds``."""
    shuffled = nested_uniform_scramble(np.uint64(index) & _LOW32, seeds[0])
    return owen_sobol_pair(shuffled, seeds[1], seeds[2])


@kernel
def sobol_points(index, dimension_key, pixel, dims):
    """Owen-scrambled (0,2)-sequence points, scrambled per pixel (:func:`sobol_pair`).

    Parameters
    ----------
    index : (n,) int64
        Index of each point in its sequence (below 2**32).
    dimension_key : uint64
        The dimension's key (:func:`rtmesh.sampling.patterns.dimension_key`): with the
        pixel it keys the sequence (:func:`rtmesh.sampling.patterns.sequence_key`).
    pixel : (n,) int64
        Each point's pixel.
    dims : int
        1: the first coordinate only, a (0,1)-sequence; 2: both.

    Returns
    -------
    (dims, n) float64
        Points in [0, 1)^2, component-major.
    """
    n = len(index)
    points = np.empty((dims, n))
    for i in range(n):
        x, y = sobol_pair(pixel_sequence(dimension_key, pixel[i]), index[i])
        points[0, i] = x
        if dims == 2:
            points[1, i] = y
    return points
