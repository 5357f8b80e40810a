"""The packed textures of compiled code against Texture.sample (its NumPy reference)."""

import numpy as np
import pytest

from rtmesh.core.compiled import kernel
from rtmesh.io.texture_atlas import TextureAtlas, texel
from rtmesh.io.texture_images import Texture


@kernel
def _lookups(texels, descriptors, t, uv):
    out = np.zeros((uv.shape[0], 4))
    for i in range(uv.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = texel(texels, descriptors, t, uv[i, 0], uv[i, 1])
    return out


@pytest.fixture(scope="module")
def textures():
    rng = np.random.default_rng(0)
    return [Texture(rng.random((5, 7, 4)), wrap="repeat"),
            Texture(rng.random((6, 3, 3)), wrap="mirror", transform=[[0.5, 0.2, 0.1], [-0.3, 1.1, 0.4]]),
            Texture(rng.random((4, 4, 1)), wrap=("clamp", "repeat")),
            Texture(rng.random((3, 5, 2)), wrap=("repeat", "mirror"))]


def test_lookups_equal_texture_sample(textures):
    atlas = TextureAtlas(textures)
    uv = np.random.default_rng(1).uniform(-2.0, 3.0, (2000, 2))
    for i, texture in enumerate(textures):
        reference = texture.sample(uv)
        got = _lookups(atlas.texels, atlas.descriptors, i, uv)
        c = texture.channels
        colour = reference[:, :3] if c >= 3 else np.repeat(reference[:, :1], 3, axis=1)
        # the atlas holds float32 texels
        np.testing.assert_allclose(got[:, :3], colour, atol=1e-6)
        alpha = reference[:, -1] if c in (2, 4) else np.ones(len(uv))
        np.testing.assert_allclose(got[:, 3], alpha, atol=1e-6)


def test_textures_are_named_by_identity(textures):
    atlas = TextureAtlas(textures)
    assert [atlas.index(t) for t in textures] == [0, 1, 2, 3]
    assert atlas.index(None) == -1
    with pytest.raises(KeyError):
        atlas.index(Texture(np.ones((1, 1, 3))))


def _as_float(texture):
    """The same texture without its bytes: the atlas keeps it as float32 texels."""
    return Texture(texture.pixels, wrap=(texture.wrap_u, texture.wrap_v), transform=texture.transform)


def test_8bit_textures_are_kept_as_bytes_and_read_as_their_float32_texels():
    # every byte value, in sRGB colour with linear alpha, linear data, and grey; odd sizes
    # so that regions start mid-word unless the atlas aligns them
    rng = np.random.default_rng(3)
    textures = [Texture.from_8bit(rng.integers(0, 256, (33, 17, 4), dtype=np.uint8), srgb=True),
                Texture.from_8bit(rng.integers(0, 256, (9, 31, 3), dtype=np.uint8), srgb=False, wrap="mirror"),
                Texture.from_8bit(rng.integers(0, 256, (5, 7), dtype=np.uint8), srgb=True, wrap="clamp"),
                Texture(rng.random((6, 5, 3)))]
    atlas = TextureAtlas(textures)
    floats = TextureAtlas([_as_float(t) for t in textures])
    # bytes take a quarter of the float32 words (each texture's region from a whole word)
    assert atlas.texels.size == sum(-(-n // 4) for n in (33 * 17 * 4, 9 * 31 * 3, 5 * 7)) + 6 * 5 * 3
    assert floats.texels.size == 33 * 17 * 4 + 9 * 31 * 3 + 5 * 7 + 6 * 5 * 3
    uv = rng.uniform(-1.5, 2.5, (3000, 2))
    for i in range(len(textures)):
        np.testing.assert_array_equal(_lookups(atlas.texels, atlas.descriptors, i, uv),
                                      _lookups(floats.texels, floats.descriptors, i, uv))
