"""Image output through OpenImageIO: linear float EXR, 8-bit sRGB PNG/JPEG.

Writes are atomic: the image goes to a temporary file in the destination folder and is
renamed over the destination only once complete, so a failed or interrupted write never
leaves a partial image (and never destroys an existing one).

A rendered image can be written to 8 bits with blue-noise dithering (``dither=True``,
``--dither``): a smooth gradient then shows no bands of equal values, and the mean of every
region stays the mean of its display values.  It is off by default: rtmesh's 8-bit images
are also data (datasets, tests comparing pixels), which round-to-nearest keeps a pure
function of the display value, and at 8 bits the bands show only in dark, smooth gradients.
"""

import functools
import logging
import os
import sys

import numpy as np
import OpenImageIO as oiio

from rtmesh.core.errors import OutputError
from rtmesh.io.atomic_files import replace_atomically
from rtmesh.io.colour import linear_to_srgb, tonemap
from rtmesh.io.passes import exr_channel_names

FLOAT_FORMATS = (".exr",)
DISPLAY_FORMATS = (".png", ".jpg", ".jpeg")
# the largest value a 16-bit depth PNG stores
DEPTH_PNG_MAX = 65535
# side of the tile of dither thresholds repeated over an image: large enough that the
# repetition does not show as a pattern; the tile ships as data (made by
# rtmesh.sampling.dither_tile from the zsobol sampler, a layer above this one)
DITHER_TILE = 128
DITHER_TILE_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "dither_tile.npy")

log = logging.getLogger(__name__)


def check_output_path(path):
    """Fail early (before rendering) if ``path`` cannot be written.

    Parameters
    ----------
    path : str or os.PathLike

    Raises
    ------
    OutputError
        Unknown extension, missing folder or a folder without write permission.
    """
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in FLOAT_FORMATS + DISPLAY_FORMATS:
        raise OutputError(
            f"{path}: unsupported output format {ext or '(none)'!r}; use "
            + ", ".join(FLOAT_FORMATS + DISPLAY_FORMATS)
        )
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise OutputError(f"{path}: output folder {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise OutputError(f"{path}: output folder {folder} is not writable")
    if os.path.isdir(path):
        raise OutputError(f"{path}: is a folder, not a file name")


def write_image(path, image, passes=None, exposure=0.0, operator="reinhard", alpha=None, header=None,
                dither=False):
    """Write a rendered image; the format follows the file extension.

    Parameters
    ----------
    path : str or os.PathLike
        ``.exr`` is written as linear float32 with every pass as extra named channels;
        ``.png``/``.jpg``/``.jpeg`` as 8-bit sRGB after exposure and tone mapping (passes
        are not written to them).
    image : (h, w, 3) float
        Linear radiance.
    passes : dict of str to (h, w) or (h, w, k) float, optional
        Extra channels for EXR, one OpenEXR layer per pass named as in
        :func:`rtmesh.io.passes.exr_channel_names` (``depth.Z``, ``normal.X``...); the ``alpha``
        pass is the image's ``A`` channel.
    exposure : float
        Stops, for 8-bit formats.
    operator : str
        Tone-mapping operator for 8-bit formats (see :func:`rtmesh.io.colour.tonemap`).
    alpha : (h, w) or (h, w, 1) float, optional
        Coverage of a render on a transparent background; ``image`` is premultiplied by it.
        EXR stores it as channel ``A`` (premultiplied RGBA, the OpenEXR convention); PNG as
        straight (unassociated) alpha: the colour is divided by alpha before tone mapping.
        JPEG has no alpha: the image is written over black.
    header : dict of str to str, int or float, optional
        Attributes written into an EXR's header (the render settings,
        :meth:`rtmesh.rendering.settings.RenderSettings.header`); 8-bit formats leave them out.
    dither : bool
        Quantise an 8-bit image's colour with blue-noise dithering (:func:`dither_thresholds`)
        instead of rounding to nearest; EXR and the alpha channel are not affected.

    Raises
    ------
    OutputError
        If the file cannot be written; nothing is left at ``path`` (nor beside it).
    """
    check_output_path(path)
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    image = np.asarray(image, dtype=np.float32)
    h, w = image.shape[:2]
    if alpha is not None:
        alpha = np.asarray(alpha, dtype=np.float32).reshape(h, w, 1)
    if ext in FLOAT_FORMATS:
        passes = dict(passes or {})
        if alpha is not None:
            passes["alpha"] = alpha
        channels, names = _exr_channels(image, passes)
        spec = oiio.ImageSpec(w, h, len(names), oiio.FLOAT)
        spec.channelnames = tuple(names)
        if "A" in names:
            spec.alpha_channel = names.index("A")
        spec.attribute("compression", "zip")
        for name, value in (header or {}).items():
            spec.attribute(name, value)
        pixels = channels
    else:
        straight_alpha = alpha is not None and ext == ".png"
        if straight_alpha:
            # PNG alpha is straight: un-premultiply (nothing to divide where alpha is 0)
            image = np.where(alpha > 0, image / np.maximum(alpha, 1e-30), 0.0)
        display = linear_to_srgb(tonemap(image, exposure, operator))
        if straight_alpha:
            display = np.concatenate([display, np.clip(alpha, 0.0, 1.0)], axis=2)
        pixels, spec = _8bit(display, ext, dither)
    _write_atomically(path, spec, pixels)


def write_display_image(path, display, srgb=False):
    """Write display values in [0, 1] as an 8-bit image (a pass shown as a PNG).

    Parameters
    ----------
    path : str or os.PathLike
        ``.png`` or ``.jpg``.
    display : (h, w, 3) or (h, w, 4) float
        Values in [0, 1], written as they are or sRGB-encoded.
    srgb : bool
        Encode the colour channels with the sRGB transfer function (linear colour data);
        False writes data (normals, grey ramps) unchanged.

    Raises
    ------
    OutputError
    """
    check_output_path(path)
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in DISPLAY_FORMATS:
        raise OutputError(f"{path}: a pass image must be one of {', '.join(DISPLAY_FORMATS)}")
    display = np.clip(np.asarray(display, dtype=np.float64), 0.0, 1.0)
    if srgb:
        display = np.concatenate([linear_to_srgb(display[:, :, :3]), display[:, :, 3:]], axis=2)
    pixels, spec = _8bit(display, ext)
    _write_atomically(path, spec, pixels)


def write_depth_png(path, depth, scale=1000.0):
    """Write a depth map as a 16-bit grey PNG of ``round(depth * scale)`` (millimetres for
    metre units at the default scale), 0 where nothing was hit (depth 0 or not finite),
    clipped at 65535.

    A depth map that clips (a hit farther than ``65535 / scale`` scene units) logs one
    warning naming the file, the farthest depth and the largest depth the PNG holds.

    Parameters
    ----------
    path : str
    depth : (h, w) float
        Z-depth, scene units.
    scale : float
        Stored units per scene unit.
    """
    check_output_path(path)
    depth = np.asarray(depth, dtype=np.float64)
    stored = np.where(np.isfinite(depth) & (depth > 0.0), depth * scale, 0.0)
    farthest = float(stored.max(initial=0.0))
    if farthest > DEPTH_PNG_MAX + 0.5:
        log.warning("%s: depth clipped at %.6g scene units (16-bit PNG at %g per unit); the farthest "
                    "depth is %.6g", os.fspath(path), DEPTH_PNG_MAX / scale, scale, farthest / scale)
    pixels = np.round(np.clip(stored, 0.0, DEPTH_PNG_MAX)).astype(np.uint16)
    h, w = pixels.shape
    _write_atomically(os.fspath(path), oiio.ImageSpec(w, h, 1, oiio.UINT16), np.ascontiguousarray(pixels[:, :, None]))


@functools.cache
def dither_thresholds():
    """Blue-noise dither thresholds: a (:data:`DITHER_TILE`, :data:`DITHER_TILE`) float64
    tile of values in [0, 1), repeated over an image (what
    :func:`rtmesh.sampling.dither_tile.blue_noise_tile` computes, read once per process)."""
    return np.load(DITHER_TILE_PATH)


def dither_offsets(height, width):
    """(height, width) float64 in [-0.5, 0.5): :func:`dither_thresholds` repeated over an
    image, centred, to add to values in 8-bit steps before rounding."""
    tile = dither_thresholds()
    reps = (-(-height // DITHER_TILE), -(-width // DITHER_TILE))
    return np.tile(tile, reps)[:height, :width] - 0.5


def _8bit(display, ext, dither=False):
    """Quantised pixels and the spec of an 8-bit image of display values in [0, 1]; with
    ``dither`` the colour channels are dithered (:func:`dither_offsets`), not alpha."""
    h, w, c = display.shape
    # in the display values' own precision: undithered output stays what it always was
    scaled = display * 255.0
    if dither:
        scaled = scaled.astype(np.float64)
        # an offset uniform in [-1/2, 1/2) step before rounding gives the upper of the two
        # nearest steps with a chance equal to the value's fraction of a step: the mean of
        # a region is kept, its error is the thresholds' blue noise; one offset for the
        # three channels, so that greys stay grey.  Clipped: 255 + 0.49 must not wrap.
        colours = min(c, 3)
        scaled[:, :, :colours] = np.clip(scaled[:, :, :colours] + dither_offsets(h, w)[:, :, None], 0.0, 255.0)
    # round to nearest: 8-bit quantisation error at most half a step
    pixels = np.round(scaled).astype(np.uint8)
    spec = oiio.ImageSpec(w, h, c, oiio.UINT8)
    if c == 4:
        spec.alpha_channel = 3
    if ext in (".jpg", ".jpeg"):
        if c == 4:
            pixels, spec = pixels[:, :, :3].copy(), oiio.ImageSpec(w, h, 3, oiio.UINT8)
        spec.attribute("Compression", "jpeg:95")
    return np.ascontiguousarray(pixels), spec


def _exr_channels(image, passes):
    """Stack the RGB image and the passes into one (h, w, c) array with channel names.

    The image's channels come first (R, G, B, then A when there is an ``alpha`` pass), then
    every other pass in the order given.
    """
    arrays, names = [image], ["R", "G", "B"]
    ordered = sorted(passes.items(), key=lambda item: item[0] != "alpha")
    for name, values in ordered:
        values = np.asarray(values, dtype=np.float32)
        if values.ndim == 2:
            values = values[:, :, None]
        arrays.append(values)
        names.extend(exr_channel_names(name, values.shape[2]))
    return np.ascontiguousarray(np.concatenate(arrays, axis=2)), names


def _write_atomically(path, spec, pixels):
    """Write ``pixels`` with OpenImageIO, whole or not at all (see
    :func:`rtmesh.io.atomic_files.replace_atomically`; the temporary keeps the extension, by
    which OpenImageIO picks its writer)."""
    def write(tmp):
        out = oiio.ImageOutput.create(tmp)
        if out is None:
            raise OutputError(f"{path}: no image writer for {os.path.splitext(path)[1]}: {oiio.geterror()}")
        try:
            if not out.open(tmp, spec):
                raise OutputError(f"{path}: cannot write: {out.geterror() or oiio.geterror()}")
            if not out.write_image(pixels):
                raise OutputError(f"{path}: cannot write: {out.geterror() or oiio.geterror()}")
        finally:
            out.close()

    replace_atomically(path, write, keep_extension=True)


def read_image(path):
    """Read an image as float32 (h, w, c) and its channel names.

    8-bit images come back as stored (sRGB-encoded values in [0, 1]); EXR as linear floats.

    Raises
    ------
    OutputError
        If the file cannot be read.
    """
    path = os.fspath(path)
    # OpenImageIO opens the file natively, where Python's audit hooks cannot see it: announce
    # the read as Python's own open does, so whoever records the files a load reads (the
    # batch's dependency fingerprints) sees this one too
    sys.audit("open", path, "rb", 0)
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise OutputError(f"{path}: cannot read: {oiio.geterror()}")
    try:
        pixels = inp.read_image(oiio.FLOAT)
        names = list(inp.spec().channelnames)
    finally:
        inp.close()
    if pixels is None:
        raise OutputError(f"{path}: cannot read pixels")
    return np.asarray(pixels, dtype=np.float32), names
