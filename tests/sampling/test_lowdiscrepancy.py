"""Owen-scrambled Sobol (0,2)-sequence: net properties, scrambling, decorrelation, and the
compiled kernel against a scalar reference in Python integers."""

import numba
import numpy as np
import pytest

from rtmesh.sampling.lowdiscrepancy import (SOBOL1_TABLES, _SOBOL1, nested_uniform_scramble, reverse_bits,
                                            sobol_bits, sobol_points)
from rtmesh.sampling.patterns import dimension_key

MASK32, MASK64 = (1 << 32) - 1, (1 << 64) - 1
GOLDEN = 0x9E3779B97F4A7C15


def sobol_02(index, keys):
    """Points of the sequences keyed ``keys`` (the tests' keys stand for a key per pixel:
    ``keys`` are used as pixels under one dimension key), (n, 2)."""
    return sobol_points(np.asarray(index, dtype=np.int64), np.uint64(0), np.asarray(keys).astype(np.int64), 2).T


@numba.njit
def _each(f, x, seed):
    out = np.empty(len(x), np.uint64)
    for i in range(len(x)):
        out[i] = f(np.uint64(x[i]), np.uint64(seed[i]))
    return out


@numba.njit
def _reverse(x, seed):
    return reverse_bits(x)


@numba.njit
def _scramble(x, seed):
    return nested_uniform_scramble(x, seed)


@numba.njit
def _sobol1(x, seed):
    return sobol_bits(x, SOBOL1_TABLES)


def test_reverse_bits_matches_scalar_reference():
    values = np.array([0, 1, 2, 0x80000000, 0x12345678, 0xFFFFFFFF, 0xDEADBEEF], dtype=np.uint64)
    values = np.concatenate([values, np.random.default_rng(2).integers(0, 2 ** 32, 500, dtype=np.uint64)])
    expected = [int(f"{int(v):032b}"[::-1], 2) for v in values]
    assert _each(_reverse, values, values).tolist() == expected


def _mix64(x):
    x ^= x >> 30
    x = (x * 0xBF58476D1CE4E5B9) & MASK64
    x ^= x >> 27
    x = (x * 0x94D049BB133111EB) & MASK64
    return x ^ (x >> 31)


def _reverse32(x):
    return int(f"{x:032b}"[::-1], 2)


def _owen(x, seed):
    """Burley's nested uniform scramble of a 0.32 fixed-point value, in Python integers."""
    x = _reverse32(x)
    x ^= (x * 0x3D20ADEA) & MASK32
    x = (x + seed) & MASK32
    x = (x * ((seed >> 16) | 1)) & MASK32
    x ^= (x * 0x05526C56) & MASK32
    x ^= (x * 0x53A22864) & MASK32
    return _reverse32(x)


def _reference_point(index, dim_key, pixel):
    """One point, as Burley's paper builds it: seeds hashed from the pixel's sequence key,
    the index Owen-scrambled, then the two generator matrices applied bit by bit."""
    key = _mix64(dim_key ^ ((pixel * GOLDEN) & MASK64))
    shuffle, seed_x, seed_y = (_mix64((key + GOLDEN * k) & MASK64) >> 32 for k in (1, 2, 3))
    i = _owen(index & MASK32, shuffle)
    x = _reverse32(i)  # van der Corput: column k is 1 << (31 - k)
    y = 0
    for k in range(32):
        if i >> k & 1:
            y ^= int(_SOBOL1[k])
    return _owen(x, seed_x) / 2 ** 32, _owen(y, seed_y) / 2 ** 32


def test_kernel_matches_a_scalar_reference_in_python_integers():
    rng = np.random.default_rng(9)
    index = rng.integers(0, 2 ** 32, 200).astype(np.int64)
    index[:3] = [0, 1, 2 ** 32 - 1]
    pixel = rng.integers(0, 10 ** 7, 200).astype(np.int64)
    for seed, dimension in ((0, 0), (2 ** 64 - 1, 1 << 24), (12345, (1 << 28) + 6)):
        key = dimension_key(seed, dimension)
        points = sobol_points(index, key, pixel, 2)
        first = sobol_points(index, key, pixel, 1)
        expected = np.array([_reference_point(int(i), int(key), int(p)) for i, p in zip(index, pixel)])
        np.testing.assert_array_equal(points.T, expected)
        np.testing.assert_array_equal(first[0], expected[:, 0])


def elementary_interval_counts(points, a, b):
    """Points per cell of the 2^a x 2^b grid."""
    ix = np.floor(points[:, 0] * 2 ** a).astype(int)
    iy = np.floor(points[:, 1] * 2 ** b).astype(int)
    return np.bincount(ix * 2 ** b + iy, minlength=2 ** (a + b))


@pytest.mark.parametrize("m", [0, 1, 2, 4, 6, 8])
@pytest.mark.parametrize("key", [0, 1, 12345, 2 ** 63 + 7])
def test_every_power_of_two_prefix_is_a_0m2_net(m, key):
    n = 2 ** m
    points = sobol_02(np.arange(n), np.full(n, key, dtype=np.uint64))
    assert ((points >= 0) & (points < 1)).all()
    for a in range(m + 1):
        counts = elementary_interval_counts(points, a, m - a)
        assert (counts == 1).all(), f"2^{a} x 2^{m - a} grid not stratified"


def test_prefix_property_holds_for_consecutive_blocks():
    # points 16..31 are also a (0,4,2)-net (the sequence is built of nets)
    points = sobol_02(np.arange(16, 32), np.full(16, 99, dtype=np.uint64))
    for a in range(5):
        assert (elementary_interval_counts(points, a, 4 - a) == 1).all()


def test_different_keys_give_decorrelated_points():
    n, pixels = 4, 4096
    sample = np.tile(np.arange(n), pixels)
    keys = np.repeat(np.arange(pixels, dtype=np.uint64), n)
    points = sobol_02(sample, keys).reshape(pixels, n, 2)
    first = points[:, 0, :]
    # the first point of each pixel is uniform over the square (chi-square on 8x8 cells)
    counts = elementary_interval_counts(first, 3, 3)
    expected = pixels / 64
    chi2 = ((counts - expected) ** 2 / expected).sum()
    assert chi2 < 110  # 63 degrees of freedom: p ~ 2e-4 to exceed
    # and pixels do not share points
    assert len(np.unique(first[:, 0])) > 0.99 * pixels


def test_scramble_is_a_permutation_of_the_high_bits():
    # nested uniform scrambling maps the 256 values k << 24 onto themselves (a permutation
    # of the top 8 bits, with lower bits filled in)
    x = (np.arange(256, dtype=np.uint64) << np.uint64(24))
    y = _each(_scramble, x, np.full(256, 0xABCDEF, dtype=np.uint64))
    assert sorted((y >> np.uint64(24)).tolist()) == list(range(256))


def test_pure_function_of_index_and_key():
    a = sobol_02(np.array([5, 9, 5]), np.array([3, 3, 3], dtype=np.uint64))
    assert np.array_equal(a[0], a[2]) and not np.array_equal(a[0], a[1])


def test_a_point_does_not_depend_on_the_other_indices_in_the_call():
    # each point alone, and in calls with few indices (where some bit is set in no
    # scrambled index), equals the point computed among many: rounds and chunks of any
    # size take the same samples
    rng = np.random.default_rng(5)
    index = rng.integers(0, 1 << 12, 300)
    keys = rng.integers(0, 1 << 63, 300).astype(np.uint64)
    together = sobol_02(index, keys)
    alone = np.concatenate([sobol_02(index[i:i + 1], keys[i:i + 1]) for i in range(300)])
    np.testing.assert_array_equal(alone, together)
    # a hand-computed case: one key, index 16 alone against indices 0..31
    key = np.array([11], dtype=np.uint64)
    np.testing.assert_array_equal(sobol_02(np.array([16]), key),
                                  sobol_02(np.arange(32), np.repeat(key, 32))[16:17])


def test_generator_matrix_product_matches_a_bit_by_bit_reference():
    # the byte tables must give exactly the GF(2) product of the index bits with the
    # matrix columns, for indices using all 32 bits (scrambled indices do)
    index = np.random.default_rng(5).integers(0, 2 ** 32, 2000, dtype=np.uint64)
    index[:3] = [0, 1, 2 ** 32 - 1]
    expected = []
    for i in index.tolist():
        acc = 0
        for k in range(32):
            if i >> k & 1:
                acc ^= int(_SOBOL1[k])
        expected.append(acc)
    assert _each(_sobol1, index, index).tolist() == expected
