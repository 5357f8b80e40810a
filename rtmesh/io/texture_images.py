"""Image textures: decoding to linear float and bilinear lookup with wrap modes."""

import contextlib
import os
import re
import warnings

import numpy as np

from rtmesh.core.errors import MeshError, RtmeshError
from rtmesh.io.colour import srgb_to_linear

# formats whose values are linear already (everything else is 8/16-bit display-encoded)
_LINEAR_FORMATS = (".exr", ".hdr")

WRAP_MODES = ("repeat", "clamp", "mirror")

# the 2 x 3 affine UV transform of a texture that has none: ``uv' = A uv + b`` as ``[A | b]``
IDENTITY_UV_TRANSFORM = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

# The largest texture rtmesh reads, in pixels (8192 x 8192): an 8-bit texture is kept as its
# bytes (and the kernels' copy, 6-8 bytes a pixel), a float one as float64 texels and a float32
# copy (36-48 bytes a pixel, 3 GiB at this size); the scene build decodes an 8-bit one to
# float64 for its NumPy lookups, one texture at a time.  A larger one is refused with a message
# naming the file (docs/LIMITS.md); PIL's own limit (its decompression-bomb guard) lies
# above it and is reported the same way.
MAX_TEXTURE_PIXELS = 1 << 26


def _too_large(source, width=None, height=None, pixels=None):
    size = f"{width}x{height} pixels" if width is not None else f"{pixels} pixels"
    return MeshError(f"{source}: texture of {size} is larger than rtmesh reads ({MAX_TEXTURE_PIXELS} "
                     "pixels, e.g. 8192x8192): downsample it")


def check_texture_size(image, source):
    """Raise MeshError for a PIL image above :data:`MAX_TEXTURE_PIXELS` (its header's size:
    nothing is decoded)."""
    width, height = image.size
    if width * height > MAX_TEXTURE_PIXELS:
        raise _too_large(source, width, height)


@contextlib.contextmanager
def image_size_guard(source):
    """Decode images inside: PIL's decompression-bomb warning (an image above its limit)
    and error (twice that) become one MeshError naming ``source`` and the size, instead of
    a warning on stderr or an exception from inside trimesh."""
    from PIL import Image

    with warnings.catch_warnings():
        warnings.simplefilter("error", Image.DecompressionBombWarning)
        try:
            yield
        except (Image.DecompressionBombWarning, Image.DecompressionBombError) as exc:
            found = re.search(r"\((\d+) pixels\)", str(exc))
            raise _too_large(source, pixels=found.group(1) if found else "too many") from None


class Texture:
    """An image addressed by UV coordinates.

    Parameters
    ----------
    pixels : (h, w, c) float
        Texel values, row 0 at the top of the image; already linear.
    wrap : {"repeat", "clamp", "mirror"} or (str, str)
        What UVs outside [0, 1] read: one mode for both axes, or a mode for u and one for v
        (glTF samplers set ``wrapS`` and ``wrapT`` apart).
    name : str
        For messages.
    transform : (2, 3) float, optional
        An affine map ``[A | b]`` applied to every UV before the lookup, ``uv' = A uv + b``,
        in this class's UV convention (below); glTF's KHR_texture_transform, converted by
        :func:`rtmesh.loaders.gltf_materials.khr_texture_transform`.  None or the identity
        (the default) reads UVs as they are, with no arithmetic.

    Attributes
    ----------
    transform : (2, 3) float64
        The UV transform (the identity when none was given).
    transformed : bool
        Whether :attr:`transform` is not the identity.
    bytes : (h, w, c) uint8 or None
        The 8-bit texels :attr:`pixels` were decoded from (:meth:`from_8bit`), which the
        kernels' atlas keeps instead of float values; None for other textures.
    srgb : bool
        Whether :attr:`bytes`' first three channels are sRGB-encoded.

    Notes
    -----
    UV (0, 0) is the bottom-left corner of the image and (1, 1) the top-right (the OBJ and
    OpenGL convention; trimesh converts glTF's top-left origin to it).  Texel centres sit at
    half-integer positions, so a UV at a texel centre reads that texel exactly.  Wrap modes
    apply to the transformed UVs.
    """

    def __init__(self, pixels, wrap="repeat", name="texture", transform=None):
        modes = (wrap, wrap) if isinstance(wrap, str) else tuple(wrap)
        if len(modes) != 2 or any(mode not in WRAP_MODES for mode in modes):
            raise ValueError(f"unknown wrap mode {wrap!r}; expected one of {', '.join(WRAP_MODES)}"
                             " or a pair of them")
        matrix = IDENTITY_UV_TRANSFORM if transform is None else np.asarray(transform, dtype=np.float64)
        if matrix.shape != (2, 3) or not np.isfinite(matrix).all():
            raise ValueError(f"a UV transform is a finite 2 x 3 matrix [A | b], not {transform!r}")
        pixels = np.asarray(pixels, dtype=np.float64)
        if pixels.ndim == 2:
            pixels = pixels[:, :, None]
        self._pixels = pixels
        self.wrap = wrap
        self.wrap_u, self.wrap_v = modes
        self.name = name
        self.transform = matrix
        # the identity (every MTL texture, most glTF ones) skips the multiply in sample()
        self.transformed = not np.array_equal(matrix, IDENTITY_UV_TRANSFORM)
        self.bytes = None
        self.srgb = False

    @property
    def pixels(self):
        """(h, w, c) float64 texel values, linear.  A texture read from 8-bit texels keeps
        only its :attr:`bytes` and decodes them here at each access (the scene build's few
        NumPy lookups; the kernels read the bytes): float64 texels would take eight times
        their memory for the life of the scene."""
        if self._pixels is not None:
            return self._pixels
        return _decode_8bit(self.bytes, self.srgb)

    @property
    def shape(self):
        """``(h, w, c)``, without decoding anything."""
        return (self._pixels if self._pixels is not None else self.bytes).shape

    @classmethod
    def from_8bit(cls, pixels, srgb=True, **options):
        """A texture from 8-bit texels, sRGB-decoded for colour data.

        Parameters
        ----------
        pixels : (h, w, c) or (h, w) uint8
        srgb : bool
            True for colour textures (base colour, diffuse); False for data (normals,
            roughness), which are stored linearly.
        """
        encoded = np.asarray(pixels, dtype=np.uint8)
        if encoded.ndim == 2:
            # one channel (grey): channels are the last axis, as for the others
            encoded = encoded[:, :, None]
        # (one texel stands in for the image while the options are checked)
        texture = cls(np.zeros((1, 1, encoded.shape[2])), **options)
        texture._pixels = None
        texture.bytes = encoded
        texture.srgb = bool(srgb)
        return texture

    @classmethod
    def from_pil(cls, image, srgb=True, **options):
        """A texture from a PIL image (as trimesh decodes them), keeping alpha if present.

        Raises
        ------
        MeshError
            The image is larger than :data:`MAX_TEXTURE_PIXELS`, or cannot be decoded.
        """
        name = options.get("name", "texture")
        check_texture_size(image, name)
        mode = "RGBA" if image.mode in ("RGBA", "LA", "PA") or "transparency" in image.info else "RGB"
        try:  # trimesh opens images lazily: a corrupt one fails here, where it is decoded
            texels = np.asarray(image.convert(mode))
        except (OSError, SyntaxError, ValueError) as exc:
            raise MeshError(f"{name}: corrupt or unreadable texture ({exc})") from None
        return cls.from_8bit(texels, srgb=srgb, **options)

    @property
    def channels(self):
        return self.shape[2]

    @staticmethod
    def _wrap(i, size, mode):
        if mode == "repeat":
            return np.mod(i, size)
        if mode == "clamp":
            return np.clip(i, 0, size - 1)
        period = np.mod(i, 2 * size)
        return np.where(period < size, period, 2 * size - 1 - period)

    def sample(self, uv):
        """Bilinearly filtered texel values at UV coordinates.

        Parameters
        ----------
        uv : (k, 2) float
            Before :attr:`transform`, which is applied here.

        Returns
        -------
        (k, c) float64
        """
        if self.transformed:
            uv = uv @ self.transform[:, :2].T + self.transform[:, 2]
        h, w, _ = self.shape
        x = uv[:, 0] * w - 0.5
        y = (1.0 - uv[:, 1]) * h - 0.5  # v grows upward, rows grow downward
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
        xs = (self._wrap(x0, w, self.wrap_u), self._wrap(x0 + 1, w, self.wrap_u))
        ys = (self._wrap(y0, h, self.wrap_v), self._wrap(y0 + 1, h, self.wrap_v))
        p = self.pixels
        top = p[ys[0], xs[0]] * (1.0 - fx) + p[ys[0], xs[1]] * fx
        bottom = p[ys[1], xs[0]] * (1.0 - fx) + p[ys[1], xs[1]] * fx
        return top * (1.0 - fy) + bottom * fy

    def height_to_normals(self, strength=1.0):
        """A tangent-space normal map from this height map (first channel).

        Central differences in texels, times ``strength`` (MTL ``-bm``): the normal of the
        height field ``h(x, y)`` is ``(-dh/dx, -dh/dy, 1)`` normalised, with y growing with v
        (up the image), stored as the usual ``0.5 + 0.5 n``.

        Returns
        -------
        Texture
            Linear, 3 channels.
        """
        height = self.pixels[:, :, 0] * float(strength)
        dh_drow, dh_dx = np.gradient(height)
        n = np.stack([-dh_dx, dh_drow, np.ones_like(height)], axis=2)  # rows grow downward
        n /= np.linalg.norm(n, axis=2, keepdims=True)
        return Texture(0.5 + 0.5 * n, wrap=self.wrap, name=f"{self.name} (normals)",
                       transform=self.transform)


def _decode_8bit(encoded, srgb):
    """(h, w, c) uint8 texels as linear float64: divided by 255, the first three channels
    decoded from sRGB when ``srgb`` (alpha is always linear)."""
    values = encoded / 255.0
    if srgb:
        colour = srgb_to_linear(values[..., :3])
        values = np.concatenate([colour, values[..., 3:]], axis=-1)
    return values


def load_texture(path, srgb=True, wrap="repeat", cache=None, signed=False):
    """Read an image file as a :class:`Texture`, once per (path, srgb, wrap, signed) in ``cache``.

    Parameters
    ----------
    path : str
    srgb : bool
        Decode 8-bit colour channels from sRGB (colour maps); False for data maps.  EXR and
        HDR files (read with OpenImageIO) are linear already; other formats are read with
        PIL, 8 bits per channel.
    wrap : str
    cache : dict, optional
    signed : bool
        The map may hold negative values (a normal or height map); colours and weights
        may not.

    Raises
    ------
    MeshError
        The file exists but cannot be decoded, is larger than :data:`MAX_TEXTURE_PIXELS`, or
        (EXR, HDR) holds NaN or infinite texels, or negative ones where not ``signed`` (one
        line naming it).
    """
    key = (os.path.abspath(path), srgb, wrap, signed)
    if cache is not None and key in cache:
        return cache[key]
    if os.path.splitext(path)[1].lower() not in _LINEAR_FORMATS:
        # 8-bit images through PIL (trimesh's decoder): it reports a corrupt file as an
        # exception, where libpng under OpenImageIO also prints to stderr
        from PIL import Image, UnidentifiedImageError

        try:
            with image_size_guard(path), Image.open(path) as image:
                check_texture_size(image, path)
                image.load()
                return _cached(cache, key, Texture.from_pil(image, srgb=srgb, wrap=wrap,
                                                            name=os.path.basename(path)))
        except (OSError, UnidentifiedImageError, SyntaxError, ValueError) as exc:
            raise MeshError(f"{path}: corrupt or unreadable texture ({exc})") from None
    from rtmesh.io.images import read_image  # image_io imports the pass registry; keep this module light

    try:
        pixels, _ = read_image(path)
    except RtmeshError as exc:
        detail = str(exc).splitlines()[0].removeprefix(f"{path}: ")
        raise MeshError(f"{path}: corrupt or unreadable texture ({detail})") from None
    if pixels.shape[0] * pixels.shape[1] > MAX_TEXTURE_PIXELS:
        # (PIL's images are refused from their header above; OpenImageIO's once read)
        raise _too_large(path, pixels.shape[1], pixels.shape[0])
    check_texel_values(pixels, path, signed)
    return _cached(cache, key, Texture(pixels, wrap=wrap, name=os.path.basename(path)))


def check_texel_values(pixels, source, signed=False):
    """Raise MeshError for float texels (an EXR or HDR file's) that are NaN or infinite, or
    negative where the map is not ``signed``: a colour or a weight is finite and >= 0, and one
    such texel would make pixels NaN or negative wherever it is seen (environment images are
    refused alike, :class:`rtmesh.scene.background.EnvironmentBackground`); a normal or
    height map may be negative.

    Parameters
    ----------
    pixels : (h, w, c) float
    source : str
        For the message: ``n.exr: texture holds NaN or infinite values (16 of its 48 values); ...``.
    signed : bool
    """
    pixels = np.asarray(pixels)
    bad = ~np.isfinite(pixels)
    if bad.any():
        raise MeshError(f"{source}: texture holds NaN or infinite values ({int(bad.sum())} of its "
                        f"{pixels.size} values); a texture must be finite and >= 0")
    if not signed and (pixels < 0).any():
        raise MeshError(f"{source}: texture holds negative values (the least {float(pixels.min()):g}); "
                        "a texture must be finite and >= 0")


def _cached(cache, key, texture):
    if cache is not None:
        cache[key] = texture
    return texture
