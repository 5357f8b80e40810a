"""Image textures as compiled code reads them: every texture of a scene packed into one flat
float32 array with a descriptor row each, and the bilinear lookup of
:meth:`rtmesh.io.texture_images.Texture.sample` (UV transform, wrap modes, texel centres at
half-integers) as one row.

Textures decoded from 8-bit images (most of them) are packed as their bytes, in the same
array read as bytes, and decoded at each lookup through a table of the 256 values each
encoding (linear, sRGB) decodes to, rounded to float32 as the float textures are: the
lookups return what float32 texels would, bit for bit, from a quarter of their memory and
with four times as many texels in a cache line (waiting on texel loads is half of the
shading stage's time on a heavily textured asset; docs/BENCHMARKS.md, "Session 22"). HDR
textures keep float32 (24 bits of mantissa).
"""

import math

import numpy as np

from rtmesh.core.compiled import row
from rtmesh.io.texture_images import WRAP_MODES, Texture

# descriptor columns
OFFSET, WIDTH, HEIGHT, CHANNELS, WRAP_U, WRAP_V, TRANSFORM, ENCODING = 0, 1, 2, 3, 4, 5, 6, 12
DESCRIPTOR_WIDTH = 13
REPEAT, CLAMP, MIRROR = (WRAP_MODES.index(name) for name in ("repeat", "clamp", "mirror"))
# how a texture's texels are stored: float32 values (OFFSET counts float32 words), or bytes
# (OFFSET counts bytes) decoded linearly or, in their first three channels, from sRGB
FLOAT32, LINEAR8, SRGB8 = 0, 1, 2


def _decoding_table():
    """(3, 256) float32: row LINEAR8 and SRGB8 hold what :meth:`Texture.from_8bit` decodes
    each byte to, rounded to float32 (row FLOAT32 unused)."""
    every_byte = np.arange(256, dtype=np.uint8).reshape(1, 256, 1).repeat(3, axis=2)
    table = np.zeros((3, 256), np.float32)
    table[LINEAR8] = Texture.from_8bit(every_byte, srgb=False).pixels[0, :, 0]
    table[SRGB8] = Texture.from_8bit(every_byte, srgb=True).pixels[0, :, 0]
    return table


DECODE = _decoding_table()


class TextureAtlas:
    """Textures packed for kernels.

    Parameters
    ----------
    textures : sequence of Texture
        Distinct textures; their index here is what kernels name them by.

    Attributes
    ----------
    texels : (n,) float32
        Float textures' texels, and 8-bit textures' bytes (four to a word), each texture's
        region starting at a word.
    descriptors : (t, DESCRIPTOR_WIDTH) float64
        Offset, width, height, channels, wrap modes (u, v), the 2 x 3 UV transform and the
        encoding.
    """

    def __init__(self, textures):
        self.textures = list(textures)
        rows, words = [], 0
        for texture in self.textures:
            h, w, c = texture.shape
            encoding = FLOAT32 if texture.bytes is None else (SRGB8 if texture.srgb else LINEAR8)
            size = h * w * c if encoding == FLOAT32 else -(-h * w * c // 4)
            rows.append([words if encoding == FLOAT32 else 4 * words, w, h, c, WRAP_MODES.index(texture.wrap_u),
                         WRAP_MODES.index(texture.wrap_v), *np.asarray(texture.transform, dtype=np.float64).ravel(),
                         encoding])
            words += size
        # each image converted straight into its place: one copy of the texels (a float32
        # copy of each, concatenated, took twice the memory and time)
        self.texels = np.zeros(max(words, 1), np.float32)
        as_bytes = self.texels.view(np.uint8)
        for descriptor, texture in zip(rows, self.textures):
            start = int(descriptor[OFFSET])
            if descriptor[ENCODING] == FLOAT32:
                pixels = np.asarray(texture.pixels)
                self.texels[start:start + pixels.size].reshape(pixels.shape)[...] = pixels
            else:
                as_bytes[start:start + texture.bytes.size].reshape(texture.bytes.shape)[...] = texture.bytes
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
def _bilinear_bytes(as_bytes, table, base, w, c, xa, xb, ya, yb, fx, fy, k):
    """:func:`_bilinear` of a texture kept as bytes, each decoded through ``table`` (a row
    of :data:`DECODE`).  A row of its own, chosen once a lookup: one row deciding the
    encoding at each of a lookup's texel values made textured renders 30 % slower."""
    top = (np.float64(table[as_bytes[base + (ya * w + xa) * c + k]]) * (1.0 - fx)
           + np.float64(table[as_bytes[base + (ya * w + xb) * c + k]]) * fx)
    bottom = (np.float64(table[as_bytes[base + (yb * w + xa) * c + k]]) * (1.0 - fx)
              + np.float64(table[as_bytes[base + (yb * w + xb) * c + k]]) * fx)
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
    encoding = np.int64(d[ENCODING])
    if encoding == FLOAT32:
        first = _bilinear(texels, base, w, c, xa, xb, ya, yb, fx, fy, 0)
        if c < 3:
            alpha = _bilinear(texels, base, w, c, xa, xb, ya, yb, fx, fy, 1) if c == 2 else 1.0
            return first, first, first, alpha
        return (first, _bilinear(texels, base, w, c, xa, xb, ya, yb, fx, fy, 1),
                _bilinear(texels, base, w, c, xa, xb, ya, yb, fx, fy, 2),
                _bilinear(texels, base, w, c, xa, xb, ya, yb, fx, fy, 3) if c == 4 else 1.0)
    # bytes: the first three channels through the texture's table, alpha (the fourth)
    # linear, as Texture.from_8bit decodes them
    as_bytes = texels.view(np.uint8)
    colour = DECODE[encoding]
    first = _bilinear_bytes(as_bytes, colour, base, w, c, xa, xb, ya, yb, fx, fy, 0)
    if c < 3:
        alpha = _bilinear_bytes(as_bytes, colour, base, w, c, xa, xb, ya, yb, fx, fy, 1) if c == 2 else 1.0
        return first, first, first, alpha
    return (first, _bilinear_bytes(as_bytes, colour, base, w, c, xa, xb, ya, yb, fx, fy, 1),
            _bilinear_bytes(as_bytes, colour, base, w, c, xa, xb, ya, yb, fx, fy, 2),
            _bilinear_bytes(as_bytes, DECODE[LINEAR8], base, w, c, xa, xb, ya, yb, fx, fy, 3) if c == 4 else 1.0)
