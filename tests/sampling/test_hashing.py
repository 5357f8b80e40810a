"""The 64-bit hash: the compiled pass over many samples against the NumPy form; the
hashed permutation of an index against its scalar reference and a random permutation's
pairs."""

import numba
import numpy as np
import pytest
from scipy import stats

from rtmesh.sampling.hashing import FEISTEL_ROUNDS, mix64, path_key, path_keys, permutation_element


def test_path_keys_are_path_key_of_each_sample():
    rng = np.random.default_rng(4)
    pixel = rng.integers(0, 1 << 40, 1000)
    sample = rng.integers(0, 1 << 33, 1000)
    with np.errstate(over="ignore"):
        key = mix64(np.uint64(12345))
        expected = path_key(key, pixel.astype(np.uint64), sample.astype(np.uint64))
    got = path_keys(key, pixel, sample)
    assert got.dtype == np.uint64 and np.array_equal(got, expected)
    # distinct samples, distinct keys (a bijection of the sample index for one pixel)
    assert len(np.unique(path_keys(key, np.zeros(4096, np.int64), np.arange(4096)))) == 4096



def _feistel(i, length, seed):
    """permutation_element in Python integers (a scalar reference of the compiled row)."""
    m64 = (1 << 64) - 1

    def mix(x):
        x ^= x >> 30; x = (x * 0xBF58476D1CE4E5B9) & m64
        x ^= x >> 27; x = (x * 0x94D049BB133111EB) & m64
        return x ^ (x >> 31)

    bits = max(1, (length - 1).bit_length())
    half = (bits + 1) // 2
    mask = (1 << half) - 1
    while True:
        left, right = i >> half, i & mask
        for r in range(FEISTEL_ROUNDS):
            f = mix(seed ^ ((right * 0x9E3779B97F4A7C15) & m64) ^ (((r + 1) * 0xD1B54A32D192ED03) & m64)) & mask
            left, right = right, left ^ f
        i = (left << half) | right
        if i < length:
            return i


@numba.njit
def _permutation(length, seed):
    out = np.empty(length, np.int64)
    for i in range(length):
        out[i] = permutation_element(i, length, seed)
    return out


@pytest.mark.parametrize("length", [1, 2, 5, 16, 100, 1024])
def test_permutation_element_permutes_and_is_its_scalar_reference(length):
    for seed in (0, 1, 0xDEADBEEF, 0x123456789ABCDEF):
        got = _permutation(length, np.uint64(seed))
        np.testing.assert_array_equal(np.sort(got), np.arange(length))
        np.testing.assert_array_equal(got, [_feistel(i, length, seed) for i in range(length)])


@pytest.mark.parametrize("length", [2, 3, 8, 16])
def test_permutation_element_puts_each_pair_anywhere_alike(length):
    # over seeds, the ordered pair (element 0, element 1) is uniform over its
    # length x (length - 1) values (chi-square), as a random permutation's is
    counts = np.zeros((length, length))
    with np.errstate(over="ignore"):  # mix64's products wrap by design
        seeds = [mix64(np.uint64(seed)) for seed in range(60 * length * (length - 1))]
    for seed in seeds:
        p = _permutation(length, seed)
        counts[p[0], p[1]] += 1
    assert np.trace(counts) == 0
    assert stats.chisquare(counts[~np.eye(length, dtype=bool)]).pvalue > 1e-4
