"""The sampler object draws exactly the points the stages drew with explicit dimensions."""

import numpy as np
import pytest

from rtmesh.sampling.patterns import Dim, decorrelated_points, pixel_offsets, stratified_values
from rtmesh.sampling.sampler import Sampler, light_dimension


@pytest.mark.parametrize("kind", ["regular", "random", "jittered", "sobol", "zsobol"])
def test_sampler_methods_are_their_dimensions(kind):
    rng = np.random.default_rng(3)
    pixel, sample = rng.integers(0, 10 ** 6, 200), rng.integers(0, 16, 200)
    size = (1000, 1000)
    s = Sampler(kind, 5, 4, size)
    args = (kind, 5, pixel, sample, 4)
    np.testing.assert_array_equal(s.pixel(pixel, sample), pixel_offsets(*args, size))
    np.testing.assert_array_equal(s.lens(pixel, sample), decorrelated_points(*args, Dim.LENS, resolution=size))
    np.testing.assert_array_equal(s.time(pixel, sample), stratified_values(*args, Dim.TIME, size))
    np.testing.assert_array_equal(s.ambient_occlusion(pixel, sample, 2, 1, 3),
                                  decorrelated_points(*args, Dim.AO + 4, 1, 3, size))
    np.testing.assert_array_equal(s.glossy(pixel, sample, 1),
                                  decorrelated_points(*args, Dim.GLOSSY + 2, resolution=size))
    np.testing.assert_array_equal(s.area_light(pixel, sample, 1, 2, 3, 0, 4),
                                  decorrelated_points(*args, light_dimension(1, 2, 3), 0, 4, size))


def test_every_stage_has_dimensions_of_its_own():
    dims = {int(Dim.PIXEL), int(Dim.LENS), int(Dim.TIME), int(Dim.ALPHA)}
    dims |= {int(Dim.AO) + 2 * d for d in range(8)} | {int(Dim.GLOSSY) + 2 * d for d in range(8)}
    lights = {light_dimension(d, i, 5) for d in range(8) for i in range(5)}
    assert len(lights) == 40 and not lights & dims
    assert len(dims) == 4 + 16
