"""Texture lookup against hand-computed texel values."""

import numpy as np
import pytest

from rtmesh.io.texture_images import Texture

# a 2 x 3 (rows x columns) single-channel image, row 0 at the top
PIXELS = np.array([[0.0, 1.0, 2.0],
                   [3.0, 4.0, 5.0]])


def uv_of_texel(column, row, width=3, height=2):
    """UV of a texel centre (v measured upward from the bottom row)."""
    return [(column + 0.5) / width, 1.0 - (row + 0.5) / height]


@pytest.mark.parametrize("wrap", ["repeat", "clamp", "mirror"])
def test_texel_centres_read_their_texel_exactly(wrap):
    texture = Texture(PIXELS, wrap=wrap)
    uv = np.array([uv_of_texel(c, r) for r in range(2) for c in range(3)])
    np.testing.assert_array_equal(texture.sample(uv)[:, 0], PIXELS.ravel())


def test_bilinear_between_four_texels_by_hand():
    texture = Texture(PIXELS, wrap="clamp")
    # a quarter of the way from texel (0, 0) to (1, 0) and halfway down to row 1
    u = (0.5 + 0.25) / 3
    v = 1.0 - (0.5 + 0.5) / 2
    top = 0.75 * 0.0 + 0.25 * 1.0
    bottom = 0.75 * 3.0 + 0.25 * 4.0
    assert texture.sample(np.array([[u, v]]))[0, 0] == pytest.approx(0.5 * top + 0.5 * bottom)


def test_wrap_modes_outside_the_unit_square():
    left_of_image = np.array([[-0.5 / 3, 1.0 - 0.5 / 2]])  # centre of column -1, row 0
    repeat = Texture(PIXELS, wrap="repeat").sample(left_of_image)[0, 0]
    clamp = Texture(PIXELS, wrap="clamp").sample(left_of_image)[0, 0]
    mirror = Texture(PIXELS, wrap="mirror").sample(left_of_image)[0, 0]
    assert repeat == 2.0  # column -1 is column 2 of the next tile
    assert clamp == 0.0  # the edge texel
    assert mirror == 0.0  # column -1 mirrors onto column 0
    far = np.array([[1.0 + 1.5 / 3, 1.0 - 0.5 / 2]])  # centre of column 4
    assert Texture(PIXELS, wrap="repeat").sample(far)[0, 0] == 1.0
    assert Texture(PIXELS, wrap="mirror").sample(far)[0, 0] == 1.0  # 3,4,5 -> 2,1,0
    assert Texture(PIXELS, wrap="clamp").sample(far)[0, 0] == 2.0


def test_srgb_texels_are_decoded_to_linear_and_alpha_is_not():
    texels = np.array([[[0, 128, 255, 128]]], dtype=np.uint8)
    texture = Texture.from_8bit(texels, srgb=True)
    value = texture.sample(np.array([[0.5, 0.5]]))[0]
    srgb = 128 / 255
    assert value[0] == 0.0 and value[2] == pytest.approx(1.0)
    assert value[1] == pytest.approx(((srgb + 0.055) / 1.055) ** 2.4)
    assert value[3] == pytest.approx(srgb)  # alpha stays linear
    data = Texture.from_8bit(texels, srgb=False).sample(np.array([[0.5, 0.5]]))[0]
    assert data[1] == pytest.approx(srgb)


def test_wrap_modes_apply_per_axis():
    # u repeats, v clamps: one texel past the right edge reads column 0, one texel above
    # the top row reads row 0 again (clamped), not row 1 (repeated)
    texture = Texture(PIXELS, wrap=("repeat", "clamp"))
    right_of_image = np.array([uv_of_texel(3, 0)])
    above_image = np.array([uv_of_texel(1, -1)])
    assert texture.sample(right_of_image)[0, 0] == PIXELS[0, 0]
    assert texture.sample(above_image)[0, 0] == PIXELS[0, 1]
    assert Texture(PIXELS, wrap=("clamp", "repeat")).sample(above_image)[0, 0] == PIXELS[1, 1]


def test_unknown_wrap_mode_is_an_error():
    with pytest.raises(ValueError, match="wrap mode"):
        Texture(PIXELS, wrap=("repeat", "tile"))


def test_an_8bit_texture_keeps_its_bytes_and_decodes_them_when_read():
    # float64 texels would take eight times the bytes' memory for the life of the scene:
    # an 8-bit texture keeps the bytes, and each read of its pixels decodes them anew
    texels = np.random.default_rng(5).integers(0, 256, (6, 9, 4), dtype=np.uint8)
    texture = Texture.from_8bit(texels, srgb=True, wrap="clamp")
    assert texture.shape == (6, 9, 4) and texture.channels == 4
    np.testing.assert_array_equal(texture.bytes, texels)
    first, second = texture.pixels, texture.pixels
    assert first is not second
    values = texels / 255.0
    expected = np.where(values <= 0.04045, values / 12.92, ((values + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(first[..., :3], expected[..., :3], rtol=1e-12)
    np.testing.assert_array_equal(first[..., 3], values[..., 3])
    np.testing.assert_array_equal(first, second)
    # a float texture keeps its texels
    floats = Texture(first)
    assert floats.bytes is None and floats.pixels is floats.pixels
