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
