"""Tone mapping operators against scalar references written from their specifications."""

import math

import numpy as np
import pytest

from rtmesh.io.colour import TONEMAPS, linear_to_srgb, srgb_to_linear, tonemap


def neutral_reference(rgb):
    """Khronos PBR Neutral for one colour, as the specification writes it."""
    f90, ks, kd = 0.04, 0.8 - 0.04, 0.15
    x = min(rgb)
    f = x - x * x / (4 * f90) if x <= 2 * f90 else f90
    c = [v - f for v in rgb]
    p = max(c)
    if p <= ks:
        return c
    pn = 1 - (1 - ks) ** 2 / (p + 1 - 2 * ks)
    g = 1 / (kd * (p - pn) + 1)
    return [v * pn / p * g + pn * (1 - g) for v in c]


def agx_reference(rgb):
    """Minimal AgX for one colour: the GLSL form, matrices given column by column."""
    columns = [(0.842479062253094, 0.0423282422610123, 0.0423756549057051),
               (0.0784335999999992, 0.878468636469772, 0.0784336),
               (0.0792237451477643, 0.0791661274605434, 0.879142973793104)]
    inverse_columns = [(1.19687900512017, -0.0528968517574562, -0.0529716355144438),
                       (-0.0980208811401368, 1.15190312990417, -0.0980434501171241),
                       (-0.0990297440797205, -0.0989611768448433, 1.15107367264116)]

    def times(cols, v):
        return [sum(cols[i][j] * v[i] for i in range(3)) for j in range(3)]

    lo, hi = -12.47393, 4.026069
    encoded = []
    for v in times(columns, rgb):
        stops = math.log2(v) if v > 0 else lo
        t = (min(max(stops, lo), hi) - lo) / (hi - lo)
        encoded.append(15.5 * t ** 6 - 40.14 * t ** 5 + 31.96 * t ** 4 - 6.868 * t ** 3 + 0.4298 * t ** 2
                       + 0.1191 * t - 0.00232)
    display = times(inverse_columns, encoded)
    return [srgb_to_linear(np.float64(v)) for v in display]


@pytest.mark.parametrize("operator, reference", [("pbr-neutral", neutral_reference), ("agx", agx_reference)])
def test_operators_match_their_scalar_references(operator, reference):
    rng = np.random.default_rng(4)
    colours = np.concatenate([rng.uniform(0, 1, (200, 3)), rng.uniform(0, 0.1, (100, 3)),
                              np.exp(rng.uniform(-8, 6, (200, 3))), np.zeros((1, 3))])
    got = tonemap(colours[None], operator=operator)[0]
    expected = np.clip([reference(list(c)) for c in colours], 0.0, 1.0)
    np.testing.assert_allclose(got, expected, atol=2e-6)  # float32 output


def test_pbr_neutral_keeps_colours_below_the_compression_start_up_to_its_offset():
    colours = np.array([[0.5, 0.3, 0.2], [0.7, 0.7, 0.7], [0.75, 0.1, 0.09]], dtype=np.float32)
    np.testing.assert_allclose(tonemap(colours[None], operator="pbr-neutral")[0], colours - 0.04, rtol=1e-6)


@pytest.mark.parametrize("operator", TONEMAPS)
def test_every_operator_maps_greys_monotonically_into_the_unit_interval(operator):
    grey = np.repeat(np.geomspace(1e-4, 1e4, 400)[:, None], 3, axis=1).astype(np.float32)
    out = tonemap(grey[None], operator=operator)[0]
    assert ((out >= 0) & (out <= 1)).all()
    assert (np.diff(out[:, 1]) >= -1e-7).all()
    # greys stay grey (AgX's matrices are not exactly grey-preserving: within 1e-3)
    assert np.abs(out - out[:, 1:2]).max() < 1e-3


def test_agx_output_encodes_to_the_display_values_of_the_curve():
    """The sRGB encoding rtmesh applies afterwards gives back AgX's display values."""
    mid_grey = tonemap(np.full((1, 1, 3), 0.18, dtype=np.float32), operator="agx")
    display = linear_to_srgb(mid_grey)
    assert 0.45 < display.mean() < 0.55  # AgX puts middle grey near the middle of the display range
