"""What rays that leave the scene see: solid colour, vertical gradient, equirectangular
environment image, or nothing (a transparent background).

Every background answers one vectorised question, :meth:`radiance` of a batch of unit ray
directions.  Camera rays and reflected/refracted rays that miss ask the same question, so an
environment shows in mirrors and through glass exactly as it does behind the model.

Orientation convention (environment maps)
-----------------------------------------
+Y is up.  A latitude-longitude image of width W and height H covers every direction:
the top row is straight up (+Y), the bottom row straight down, the middle row the horizon.
Columns sweep the azimuth ``atan2(z, x)`` from -pi at the left edge to +pi at the right
edge, so the image centre looks along +X, a quarter in from the left along -Z, three
quarters along +Z, and the left/right edges along -X (the convention of three.js's
``equirectUv``).  Seen from inside, an image is not mirrored: turning right from -Z turns
toward +X.  ``rotation`` turns the environment about +Y by that many degrees (right-handed:
at 90 degrees, what the image showed along +X is seen along -Z).
"""

import math
import os

import numpy as np

from rtmesh.core.errors import SceneError
from rtmesh.io.colour import srgb_to_linear
from rtmesh.io.texture_images import Texture
from rtmesh.sampling.warps import direction_to_latlong

BACKGROUND_TYPES = ("solid", "gradient", "environment", "transparent")
# files whose values are linear radiance; anything else is taken as 8-bit sRGB
LINEAR_IMAGE_FORMATS = (".exr", ".hdr")


class SolidBackground:
    """The same radiance in every direction.

    Parameters
    ----------
    colour : (3,) float
        Linear radiance.

    Attributes
    ----------
    lighting : bool or None
        Whether the background also lights the scene (see
        :mod:`rtmesh.lights.environment`); every background has it.  None (unset): it
        lights scenes with physically based (glTF metallic-roughness) materials and no
        others.
    """

    transparent = False
    lighting = None

    def __init__(self, colour):
        self.colour = np.asarray(colour, dtype=np.float64).reshape(3)

    @property
    def is_black(self):
        return not (self.colour > 0).any()

    def radiance(self, directions):
        """(k, 3) float64 radiance seen along unit ``directions`` (k, 3)."""
        return np.broadcast_to(self.colour, (len(directions), 3))


class TransparentBackground(SolidBackground):
    """No background: misses see black and the image gets an alpha channel (coverage).

    The colour written where nothing is hit is 0, so the image is premultiplied by alpha.
    Reflected and refracted rays that miss see black too.
    """

    transparent = True

    def __init__(self):
        super().__init__(np.zeros(3))


class GradientBackground:
    """A vertical gradient over the sky: ``bottom`` straight down, ``top`` straight up.

    The radiance is linear in the up-component of the direction:
    ``bottom + (top - bottom) * (1 + d.y) / 2``, so the horizon is the average of the two.

    Parameters
    ----------
    top, bottom : (3,) float
        Linear radiance straight up (+Y) and straight down (-Y).
    """

    transparent = False
    lighting = None  # see SolidBackground

    def __init__(self, top, bottom):
        self.top = np.asarray(top, dtype=np.float64).reshape(3)
        self.bottom = np.asarray(bottom, dtype=np.float64).reshape(3)

    @property
    def is_black(self):
        return not ((self.top > 0).any() or (self.bottom > 0).any())

    def radiance(self, directions):
        """(k, 3) float64 radiance seen along unit ``directions`` (k, 3)."""
        s = np.clip(0.5 + 0.5 * directions[:, 1], 0.0, 1.0)[:, None]
        return self.bottom + (self.top - self.bottom) * s


class EnvironmentBackground:
    """An equirectangular (latitude-longitude) environment image, bilinearly filtered.

    Parameters
    ----------
    pixels : (h, w, c) float
        Linear radiance, row 0 at the top (+Y); c >= 3 (extra channels ignored) or 1 (grey).
    rotation : float
        Degrees about +Y (see the module docstring).
    intensity : float
        Multiplies every texel.
    name : str
        For messages.
    """

    transparent = False
    lighting = None  # see SolidBackground

    def __init__(self, pixels, rotation=0.0, intensity=1.0, name="environment"):
        pixels = np.asarray(pixels, dtype=np.float64)
        if pixels.ndim == 2:
            pixels = pixels[:, :, None]
        if pixels.shape[2] == 1:
            pixels = np.repeat(pixels, 3, axis=2)
        pixels = pixels[:, :, :3] * float(intensity)
        if not np.isfinite(pixels).all() or (pixels < 0).any():
            raise ValueError(f"{name}: environment image holds negative, NaN or Inf values")
        self.width = pixels.shape[1]
        self.rotation = float(rotation)
        self.name = name
        self._black = not (pixels > 0).any()
        # the azimuth wraps around: one column from the opposite edge on each side lets a
        # clamped bilinear lookup blend across the seam, while the poles clamp (rows must
        # not wrap from straight up to straight down)
        padded = np.concatenate([pixels[:, -1:], pixels, pixels[:, :1]], axis=1)
        self._texture = Texture(padded, wrap="clamp", name=name)

    @property
    def is_black(self):
        return self._black

    def uv(self, directions):
        """Image coordinates of unit directions.

        Parameters
        ----------
        directions : (k, 3) float

        Returns
        -------
        (k, 2) float
            u in [0, 1] left to right (azimuth), v in [0, 1] bottom (-Y) to top (+Y), the
            texture convention of :class:`rtmesh.io.texture_images.Texture`.
        """
        return direction_to_latlong(directions, self.rotation)

    def radiance(self, directions):
        """(k, 3) float64 radiance seen along unit ``directions`` (k, 3)."""
        uv = self.uv(directions)
        w = self.width
        # u on the image -> u on the padded image (one extra column on each side)
        uv[:, 0] = (uv[:, 0] * w + 1.0) / (w + 2.0)
        return self._texture.sample(uv)


def latlong_directions(width, height):
    """Unit directions of the texel centres of a ``width`` x ``height`` lat-long image.

    The inverse of :meth:`EnvironmentBackground.uv` (rotation 0), for building
    environment maps procedurally.

    Returns
    -------
    (height, width, 3) float64
        Row 0 at the top (+Y).
    """
    u = (np.arange(width) + 0.5) / width
    v = 1.0 - (np.arange(height) + 0.5) / height
    azimuth = (u - 0.5) * 2.0 * math.pi
    elevation = (v - 0.5) * math.pi
    cos_el = np.cos(elevation)[:, None]
    return np.stack([cos_el * np.cos(azimuth)[None, :],
                     np.broadcast_to(np.sin(elevation)[:, None], (height, width)),
                     cos_el * np.sin(azimuth)[None, :]], axis=2)


def as_background(value):
    """A background object from a background or a colour ((3,) or a number)."""
    if hasattr(value, "radiance"):
        return value
    return SolidBackground(np.broadcast_to(np.asarray(value, dtype=np.float64), (3,)))


def read_environment(path, rotation=0.0, intensity=1.0):
    """Load an equirectangular environment image with OpenImageIO.

    ``.exr`` and ``.hdr`` files are linear radiance; 8-bit images (PNG, JPEG) are sRGB
    decoded to linear.

    Raises
    ------
    SceneError
        Missing or unreadable file, or an image with negative/NaN/Inf values.
    """
    from rtmesh.core.errors import OutputError
    from rtmesh.io.images import read_image

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise SceneError(f"{path}: no such environment image")
    try:
        pixels, _ = read_image(path)
    except OutputError as exc:
        raise SceneError(f"{path}: cannot read environment image: {str(exc).splitlines()[0]}") from None
    if os.path.splitext(path)[1].lower() not in LINEAR_IMAGE_FORMATS:
        pixels = np.concatenate([srgb_to_linear(pixels[:, :, :3]), pixels[:, :, 3:]], axis=2)
    try:
        return EnvironmentBackground(pixels, rotation, intensity, name=path)
    except ValueError as exc:
        raise SceneError(str(exc)) from None


def background_from_option(text):
    """The background a command-line ``--background`` value names.

    Parameters
    ----------
    text : str
        ``transparent``; a colour as one number or ``r,g,b`` (linear); or the path of an
        equirectangular environment image.

    Raises
    ------
    SceneError
        Not a colour, not ``transparent``, and no such image.
    """
    text = text.strip()
    if text == "transparent":
        return TransparentBackground()
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        return read_environment(text)
    if len(values) not in (1, 3) or not all(math.isfinite(v) and v >= 0 for v in values):
        raise SceneError(f"--background {text}: expected transparent, a colour (g or r,g,b >= 0) "
                         "or an environment image")
    return SolidBackground(np.broadcast_to(values, (3,)))
