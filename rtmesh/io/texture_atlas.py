"""Image textures as compiled code reads them: every texture of a scene packed into one flat
float32 array with a descriptor row each, and the bilinear lookup of
:meth:`rtmesh.io.texture_images.Texture.sample` (UV transform, wrap modes, texel centres at
half-integers) as one row.

float32 holds the 8-bit texels that most textures decode from exactly and halves the
memory of the float64 images; HDR textures keep 24 bits of mantissa.
"""

import math

import numpy as np

from rtmesh.core.compiled import row
from rtmesh.io.texture_images import WRAP_MODES

# descriptor columns
OFFSET, WIDTH, HEIGHT, CHANNELS, WRAP_U, WRAP_V, TRANSFORM = 0, 1, 2, 3, 4, 5, 6
DESCRIPTOR_WIDTH = 12
REPEAT, CLAMP, MIRROR = (WRAP_MODES.index(name) for name in ("repeat", "clamp", "mirror"))


class TextureAtlas:
    """Textures packed for kernels.

    Parameters
    ----------
    textures : sequence of Texture
        Distinct textures; their index here is what kernels name them by.

    Attributes
    ----------
    texels : (sum of h w c,) float32
    descriptors : (t, DESCRIPTOR_WIDTH) float64
        Offset, width, height, channels, wrap modes (u, v) and the 2 x 3 UV transform.
    """

    def __init__(self, textures):
        self.textures = list(textures)
        images = [np.asarray(texture.pixels) for texture in self.textures]
        rows, offset = [], 0
        for texture, pixels in zip(self.textures, images):
            h, w, c = pixels.shape
            rows.append([offset, w, h, c, WRAP_MODES.index(texture.wrap_u), WRAP_MODES.index(texture.wrap_v),
                         *np.asarray(texture.transform, dtype=np.float64).ravel()])
            offset += h * w * c
        # each image converted straight into its place: one float32 copy of the texels (a
        # float32 copy of each, concatenated, took twice the memory and time)
        self.texels = np.zeros(max(offset, 1), np.float32)
        for descriptor, pixels in zip(rows, images):
            start = descriptor[OFFSET]
            self.texels[start:start + pixels.size].reshape(pixels.shape)[...] = pixels
        self.descriptors = np.array(rows, dtype=np.float64).reshape(-1, DESCRIPTOR_WIDTH)

    def index(self, texture):
        """Index of ``texture`` (by identity), -1 for None."""
        if texture is None:
            return -1
        for i, known in enumerate(self.textures):
            if known is texture:
                return i
        raise KeyError("texture not in the atlas")


@row
def _wrap(i, size, mode):
    if mode == REPEAT:
        return i % size
    if mode == CLAMP:
        return min(max(i, 0), size - 1)
    period = i % (2 * size)
    return period if period < size else 2 * size - 1 - period


@row
def _bilinear(texels, base, w, c, xa, xb, ya, yb, fx, fy, k):
    """Channel ``k`` of the four texels around a point, blended (as ``Texture.sample``)."""
    top = (np.float64(texels[base + (ya * w + xa) * c + k]) * (1.0 - fx)
           + np.float64(texels[base + (ya * w + xb) * c + k]) * fx)
    bottom = (np.float64(texels[base + (yb * w + xa) * c + k]) * (1.0 - fx)
              + np.float64(texels[base + (yb * w + xb) * c + k]) * fx)
    return top * (1.0 - fy) + bottom * fy


@row
def texel(texels, descriptors, t, u, v):
    """Bilinearly filtered texture ``t`` at ``(u, v)`` (before its transform): ``(r, g, b, a)``
    with grey images repeated into r, g, b and ``a`` 1 without an alpha channel (1 or 3
    channels)."""
    d = descriptors[t]
    if d[TRANSFORM] != 1.0 or d[TRANSFORM + 1] != 0.0 or d[TRANSFORM + 2] != 0.0 or d[TRANSFORM + 3] != 0.0 \
            or d[TRANSFORM + 4] != 1.0 or d[TRANSFORM + 5] != 0.0:
        u, v = (d[TRANSFORM] * u + d[TRANSFORM + 1] * v + d[TRANSFORM + 2],
                d[TRANSFORM + 3] * u + d[TRANSFORM + 4] * v + d[TRANSFORM + 5])
    base = np.int64(d[OFFSET])
    w, h, c = np.int64(d[WIDTH]), np.int64(d[HEIGHT]), np.int64(d[CHANNELS])
    x = u * w - 0.5
    y = (1.0 - v) * h - 0.5
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0
    mu, mv = np.int64(d[WRAP_U]), np.int64(d[WRAP_V])
    xa, xb = _wrap(np.int64(x0), w, mu), _wrap(np.int64(x0) + 1, w, mu)
    ya, yb = _wrap(np.int64(y0), h, mv), _wrap(np.int64(y0) + 1, h, mv)
    first = _bilinear(texels, base, w, c, xa, xb, ya, yb, fx, fy, 0)
    if c < 3:
        alpha = _bilinear(texels, base, w, c, xa, xb, ya, yb, fx, fy, 1) if c == 2 else 1.0
        return first, first, first, alpha
    return (first, _bilinear(texels, base, w, c, xa, xb, ya, yb, fx, fy, 1),
            _bilinear(texels, base, w, c, xa, xb, ya, yb, fx, fy, 2),
            _bilinear(texels, base, w, c, xa, xb, ya, yb, fx, fy, 3) if c == 4 else 1.0)
