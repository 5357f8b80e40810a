"""The 64-bit hash: the compiled pass over many samples against the NumPy form."""

import numpy as np

from rtmesh.sampling.hashing import mix64, path_key, path_keys


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
