"""Owen-scrambled Sobol (0,2)-sequence: net properties, scrambling, decorrelation."""

import numpy as np
import pytest

from rtmesh.sampling.lowdiscrepancy import nested_uniform_scramble, reverse_bits, sobol_02


def test_reverse_bits_matches_scalar_reference():
    values = np.array([0, 1, 2, 0x80000000, 0x12345678, 0xFFFFFFFF, 0xDEADBEEF], dtype=np.uint32)
    values = np.concatenate([values, np.random.default_rng(2).integers(0, 2 ** 32, 500, dtype=np.uint64)
                             .astype(np.uint32)])
    expected = [int(f"{int(v):032b}"[::-1], 2) for v in values]
    assert reverse_bits(values).tolist() == expected


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
    x = (np.arange(256, dtype=np.uint32) << np.uint32(24))
    y = nested_uniform_scramble(x, np.full(256, 0xABCDEF, dtype=np.uint32))
    assert sorted((y >> np.uint32(24)).tolist()) == list(range(256))


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


def test_generator_matrix_products_match_a_bit_by_bit_reference():
    # the byte tables must give exactly the GF(2) product of the index bits with the
    # matrix columns, for indices using all 32 bits (scrambled indices do)
    from rtmesh.sampling.lowdiscrepancy import _SOBOL1, _SOBOL1_TABLES, _VDC, _VDC_TABLES, _sobol_bits

    index = np.random.default_rng(5).integers(0, 2 ** 32, 2000, dtype=np.uint64).astype(np.uint32)
    index[:3] = [0, 1, 2 ** 32 - 1]
    for matrix, tables in ((_VDC, _VDC_TABLES), (_SOBOL1, _SOBOL1_TABLES)):
        expected = []
        for i in index.tolist():
            acc = 0
            for k in range(32):
                if i >> k & 1:
                    acc ^= int(matrix[k])
            expected.append(acc)
        assert np.array_equal(_sobol_bits(index, tables), np.array(expected, dtype=np.uint32))
