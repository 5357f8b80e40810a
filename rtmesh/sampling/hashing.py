"""The 64-bit integer hash behind every random number in rtmesh."""

import numpy as np
from numba.extending import register_jitable

from rtmesh.core.compiled import kernel

M1 = np.uint64(0xBF58476D1CE4E5B9)
M2 = np.uint64(0x94D049BB133111EB)
GOLDEN = np.uint64(0x9E3779B97F4A7C15)


@register_jitable
def mix64(x):
    """SplitMix64 finaliser: a bijective 64-bit mix with full avalanche.

    Plain NumPy when called from Python; compiled code (:mod:`rtmesh.sampling.pixel_samples`) calls
    the same function, compiled for one uint64.

    Parameters
    ----------
    x : (n,) uint64 or uint64

    Returns
    -------
    (n,) uint64
        Products wrap modulo 2**64, as the mix intends (callers silence NumPy's overflow
        warning for scalars).
    """
    x = x ^ (x >> np.uint64(30))
    x = x * M1
    x = x ^ (x >> np.uint64(27))
    x = x * M2
    return x ^ (x >> np.uint64(31))


@register_jitable
def pixel_sequence(key, pixel):
    """The key of one pixel's sample sequence in one dimension: the dimension's ``key``
    (:func:`rtmesh.sampling.patterns.dimension_key`) mixed with the pixel index, the part of
    a sample's hash that is the same for all of a pixel's samples.

    Plain NumPy for (n,) uint64 pixels (the product wraps modulo 2**64; callers silence
    NumPy's overflow warning for scalars); compiled code calls the same function for one
    pixel, so kernels can form it once per pixel.
    """
    return mix64(key ^ (np.uint64(pixel) * GOLDEN))


@register_jitable
def path_key(key, pixel, sample):
    """The key of one pixel sample's random numbers in the path integrator: the seed's
    ``key`` mixed with the pixel and the sample index (a pure function of the three, so
    images do not depend on chunks or threads)."""
    return mix64(pixel_sequence(key, pixel) ^ (np.uint64(sample) * M2))


@kernel
def path_keys(key, pixel, sample):
    """:func:`path_key` of many samples, compiled (one pass, no temporaries).

    Parameters
    ----------
    key : uint64
    pixel, sample : (n,) int64
        Each sample's pixel and index in it.

    Returns
    -------
    (n,) uint64
    """
    out = np.empty(len(pixel), np.uint64)
    for i in range(len(pixel)):
        out[i] = path_key(key, pixel[i], sample[i])
    return out


@register_jitable
def uniform(key, dimension):
    """A uniform number in [0, 1) (53 bits) of one sample's ``dimension``."""
    return np.float64(mix64(key ^ (np.uint64(dimension) * GOLDEN)) >> np.uint64(11)) * (1.0 / 9007199254740992.0)



# the Feistel network's rounds: 8 give uniformly distributed pairs (p(i), p(j)) down to a
# permutation of 2 elements (chi-square over seeds); 4 do not for 8 to 64 elements
FEISTEL_ROUNDS = 8
_ROUND = np.uint64(0xD1B54A32D192ED03)


@register_jitable
def permutation_element(i, length, seed):
    """Element ``i`` of a pseudo-random permutation of ``[0, length)`` chosen by ``seed``:
    a balanced Feistel network (round function :func:`mix64`) on the bits of the smallest
    even power of two at least ``length``, walked until it lands inside the range (Black &
    Rogaway 2002, "Ciphers with arbitrary finite domains").

    Unlike a nested (bit-by-bit) scramble of an index, which keeps every aligned block of
    indices together, it leaves no trace of the index's binary structure.  Kensler's hashed
    permutation (2013; pbrt-v4's ``PermutationElement``) is cheaper and places each element
    uniformly, but not pairs: over seeds, ``(p(0), p(1))`` of a permutation of 8 takes some of
    its 56 values at a third and others at twice the uniform rate.

    Parameters
    ----------
    i, length : int
        ``0 <= i < length <= 2**62``.
    seed : uint64
        Chooses the permutation.

    Returns
    -------
    int64
    """
    bits = 1
    while (np.int64(1) << bits) < length:
        bits += 1
    half = np.uint64((bits + 1) // 2)
    mask = (np.uint64(1) << half) - np.uint64(1)
    x = np.uint64(i)
    while True:
        left, right = x >> half, x & mask
        for r in range(FEISTEL_ROUNDS):
            left, right = right, left ^ (mix64(seed ^ (right * GOLDEN) ^ (np.uint64(r + 1) * _ROUND)) & mask)
        x = (left << half) | right
        # a permutation of the whole 2^(2 half) words: walking its cycle from i reaches
        # [0, length) again
        if x < np.uint64(length):
            return np.int64(x)
