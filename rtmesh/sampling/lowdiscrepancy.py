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

from rtmesh.sampling.hashing import GOLDEN, mix64

_BITS = 32

# generator matrices as 32 column vectors (most significant bit first):
# dimension 0 is van der Corput (bit reversal), dimension 1 is Sobol's second dimension,
# whose direction numbers follow from the primitive polynomial x + 1: v_k = v_{k-1} ^ (v_{k-1} >> 1)
_VDC = np.array([1 << (31 - k) for k in range(_BITS)], dtype=np.uint32)
_SOBOL1 = np.zeros(_BITS, dtype=np.uint32)
_SOBOL1[0] = 1 << 31
for _k in range(1, _BITS):
    _SOBOL1[_k] = _SOBOL1[_k - 1] ^ (_SOBOL1[_k - 1] >> 1)

def reverse_bits(x):
    """Reverse the 32 bits of each value, (n,) uint32 -> (n,) uint32.

    Swaps neighbouring bits, pairs and nibbles (reversing each byte), then the byte order of
    each value: eight whole-array operations and a byteswap, several times faster than a
    byte look-up table (which needs a strided copy to reorder the bytes).
    """
    x = np.asarray(x, dtype=np.uint32)
    for shift, mask in ((1, 0x55555555), (2, 0x33333333), (4, 0x0F0F0F0F)):
        shift, mask = np.uint32(shift), np.uint32(mask)
        x = ((x >> shift) & mask) | ((x & mask) << shift)
    return x.byteswap()  # the value's byte order, whatever the machine's


def _laine_karras_permutation(x, seed):
    """Burley's improved Laine-Karras hash: a permutation that only lets each bit depend on
    the bits below it, which is exactly nested uniform scrambling once bits are reversed."""
    with np.errstate(over="ignore"):
        x = x ^ (x * np.uint32(0x3D20ADEA))
        x = x + seed
        x = x * ((seed >> np.uint32(16)) | np.uint32(1))
        x = x ^ (x * np.uint32(0x05526C56))
        x = x ^ (x * np.uint32(0x53A22864))
    return x


def nested_uniform_scramble(x, seed):
    """Owen-scramble 32-bit fixed-point values with a per-element seed.

    Parameters
    ----------
    x : (n,) uint32
        Values in 0.32 fixed point.
    seed : (n,) uint32

    Returns
    -------
    (n,) uint32
    """
    return reverse_bits(_laine_karras_permutation(reverse_bits(x), np.asarray(seed, dtype=np.uint32)))


def _byte_tables(matrix):
    """The products of a generator matrix with every byte, one table per byte position.

    Multiplication over GF(2) is linear in the bits of the index, so ``index * matrix`` is
    the XOR of the products of its four bytes: four table look-ups instead of a 32-step
    loop over bits (a scrambled index has all 32 bits in use).

    Returns
    -------
    (4, 256) uint32
        ``tables[b, v]``: the XOR of the columns ``matrix[8 b + k]`` for the bits ``k`` set
        in ``v``.
    """
    bits = (np.arange(256)[:, None] >> np.arange(8)) & 1  # (256, 8): bit k of each byte
    return np.stack([np.bitwise_xor.reduce(bits * matrix[8 * b:8 * b + 8].astype(np.int64), axis=1)
                     for b in range(4)]).astype(np.uint32)


_VDC_TABLES = _byte_tables(_VDC)
_SOBOL1_TABLES = _byte_tables(_SOBOL1)


def _sobol_bits(index, tables):
    """Multiply the bits of ``index`` ((n,) uint32) by a generator matrix over GF(2), given
    as its :func:`_byte_tables`; (n,) uint32."""
    out = tables[0].take(index & np.uint32(0xFF))
    for b in range(1, 4):
        out ^= tables[b].take((index >> np.uint32(8 * b)) & np.uint32(0xFF))
    return out


def _hash_seeds(keys, count):
    """``count`` independent 32-bit seeds per key, (n,) uint64 -> (count, n) uint32."""
    with np.errstate(over="ignore"):
        seeds = [mix64(keys + GOLDEN * np.uint64(i + 1)) for i in range(count)]
    return [(s >> np.uint64(32)).astype(np.uint32) for s in seeds]


def sobol_02(sample, keys):
    """Owen-scrambled (0,2)-sequence points, one independent scramble per key.

    Parameters
    ----------
    sample : (n,) int
        Index of the point in its sequence (the sample index within the pixel).
    keys : (n,) uint64
        One key per sequence (e.g. a hash of seed, pixel and dimension): points with the same
        key belong to the same scrambled sequence.

    Returns
    -------
    (n, 2) float64
        Points in [0, 1)^2.
    """
    sample = np.asarray(sample, dtype=np.uint32)
    keys = np.asarray(keys, dtype=np.uint64)
    shuffle_seed, seed_x, seed_y = _hash_seeds(keys, 3)
    # scrambling the index permutes points only inside aligned power-of-two blocks, so every
    # power-of-two prefix is still a whole (0,m,2)-net; it decorrelates pixels from each other
    index = nested_uniform_scramble(sample, shuffle_seed)
    x = nested_uniform_scramble(_sobol_bits(index, _VDC_TABLES), seed_x)
    y = nested_uniform_scramble(_sobol_bits(index, _SOBOL1_TABLES), seed_y)
    return np.stack([x, y], axis=1).astype(np.float64) * (1.0 / 4294967296.0)
