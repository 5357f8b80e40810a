"""The numbers of benchmarks/bench_equal_error.py that need no renderer: the two-seed error
and the extrapolation of time to a target error."""

import math

import numpy as np
import pytest

from benchmarks.bench_equal_error import cost_line, exponents, power_law, seed_error, time_to_error


def test_seed_error_is_the_noise_of_one_render_over_the_mean():
    rng = np.random.default_rng(3)
    truth = np.full((64, 64, 3), 2.0)
    a = truth + rng.normal(0.0, 0.1, truth.shape)
    b = truth + rng.normal(0.0, 0.1, truth.shape)
    # the difference of two renders has twice the variance of one: / sqrt(2) gives one's
    assert seed_error(a, b) == pytest.approx(0.1 / 2.0, rel=0.03)
    mask = np.zeros((64, 64), bool)
    mask[:8] = True
    expected = np.sqrt(np.mean((a[mask] - b[mask]) ** 2)) / math.sqrt(2) / (0.5 * (a[mask] + b[mask])).mean()
    assert seed_error(a, b, mask) == pytest.approx(expected)
    assert seed_error(a, a) == 0.0


def test_power_law_recovers_the_exponent():
    spps = [16, 64, 256]
    for k in (0.5, 0.62):
        c, fitted = power_law(spps, [0.9 * s ** -k for s in spps])
        assert fitted == pytest.approx(k) and c == pytest.approx(0.9)
    with pytest.raises(ValueError):
        power_law([16, 16], [0.2, 0.1])


def test_cost_line_keeps_the_fixed_cost_non_negative():
    assert cost_line([16, 64], [0.5 + 0.1 * 16, 0.5 + 0.1 * 64]) == pytest.approx((0.5, 0.1))
    # a negative intercept (noise) falls back to time proportional to spp
    a, b = cost_line([16, 64], [1.0, 6.0])
    assert a == 0.0 and b == pytest.approx((16 * 1.0 + 64 * 6.0) / (16 ** 2 + 64 ** 2))


def test_time_to_error_on_a_monte_carlo_law():
    # error = 0.8 / sqrt(spp), time = 0.2 + 0.05 spp: 4 % needs 400 spp, 20.2 s
    spps = [16, 64]
    result = time_to_error(spps, [0.2 + 0.05 * s for s in spps], [0.8 / math.sqrt(s) for s in spps], 0.04)
    assert result["spp"] == pytest.approx(400.0)
    assert result["seconds"] == pytest.approx(20.2)
    assert result["exponent"] == pytest.approx(0.5)
    assert result["extrapolated"]
    inside = time_to_error(spps, [1.0, 4.0], [0.2, 0.1], 0.15)
    assert not inside["extrapolated"] and 16 < inside["spp"] < 64
    with pytest.raises(ValueError):
        time_to_error(spps, [1.0, 4.0], [0.1, 0.2], 0.05)  # error rising with spp


def test_time_to_error_uses_the_neighbouring_levels():
    # a stratifying sampler: k 0.75 from 16 to 64 spp, 0.5 beyond
    spps = [16, 64, 256]
    errors = [0.32, 0.32 * 4 ** -0.75, 0.32 * 4 ** -0.75 / 2]
    seconds = [0.1 * s for s in spps]
    assert exponents(spps, errors) == pytest.approx([0.75, 0.5])
    between = time_to_error(spps, seconds, errors, 0.32 * 2 ** -0.75)  # at 32 spp on the first pair
    assert between["spp"] == pytest.approx(32.0) and between["exponent"] == pytest.approx(0.75)
    assert not between["extrapolated"]
    beyond = time_to_error(spps, seconds, errors, errors[-1] / 2)  # past 256 spp: the last pair's k
    assert beyond["spp"] == pytest.approx(1024.0) and beyond["exponent"] == pytest.approx(0.5)
    assert beyond["seconds"] == pytest.approx(102.4) and beyond["extrapolated"]
    below = time_to_error(spps, seconds, errors, 0.64)  # under 16 spp: the first pair's k
    assert below["spp"] == pytest.approx(16 * 2 ** (-1 / 0.75)) and below["extrapolated"]
