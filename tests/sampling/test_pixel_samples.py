"""The compiled pixel sample positions equal NumPy's, bit for bit."""

import numpy as np
import pytest

from rtmesh.sampling.patterns import pixel_offsets
from rtmesh.sampling.pixel_samples import PixelSampler, pixel_positions


@pytest.mark.parametrize("sampler", ["regular", "jittered", "random", "sobol", "zsobol"])
@pytest.mark.parametrize("spp", [1, 2, 3, 4, 6, 16])
@pytest.mark.parametrize("seed", [0, 7, -3, 2 ** 63 + 5])
def test_compiled_pixel_positions_equal_numpy(sampler, spp, seed):
    if sampler == "zsobol":
        spp = 1 << (spp - 1).bit_length()  # zsobol takes powers of two (settings round up)
    rng = np.random.default_rng(spp)
    resolution = (4000, 2500)
    pixel = rng.integers(0, 10 ** 7, 500)
    sample = rng.integers(0, 4 * spp, 500)  # adaptive rounds continue past the first spp
    expected = pixel_offsets(sampler, seed, pixel, sample, spp, resolution)
    s = PixelSampler(sampler, seed, spp, resolution)
    got = pixel_positions(s.code, s.keys, s.corners, s.size, s.spp, pixel, sample)
    np.testing.assert_array_equal(got, expected)


def test_every_sampler_has_a_compiled_twin():
    from rtmesh.rendering.settings import RenderSettings
    from rtmesh.sampling.patterns import SAMPLERS
    for name in SAMPLERS:
        assert PixelSampler.for_settings(RenderSettings(sampler=name, spp=4)).spp == 4