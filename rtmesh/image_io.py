"""Image output through OpenImageIO: linear float EXR, 8-bit sRGB PNG/JPEG.

Writes are atomic: the image goes to a temporary file in the destination folder and is
renamed over the destination only once complete, so a failed or interrupted write never
leaves a partial image (and never destroys an existing one).
"""

import os
import tempfile

import numpy as np
import OpenImageIO as oiio

from .errors import OutputError
from .film import linear_to_srgb, tonemap

FLOAT_FORMATS = (".exr",)
DISPLAY_FORMATS = (".png", ".jpg", ".jpeg")


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


def write_image(path, image, passes=None, exposure=0.0, operator="reinhard"):
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
        Extra channels for EXR: a one-channel pass ``ao`` becomes channel ``AO``, a k-channel
        pass ``normal`` becomes ``normal.X``, ``normal.Y``, ... (k = 3) or ``name.0``...
    exposure : float
        Stops, for 8-bit formats.
    operator : str
        Tone-mapping operator for 8-bit formats (see :func:`rtmesh.film.tonemap`).

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
    if ext in FLOAT_FORMATS:
        channels, names = _exr_channels(image, passes or {})
        spec = oiio.ImageSpec(w, h, len(names), oiio.FLOAT)
        spec.channelnames = tuple(names)
        spec.attribute("compression", "zip")
        pixels = channels
    else:
        display = linear_to_srgb(tonemap(image, exposure, operator))
        # round to nearest: 8-bit quantisation error at most half a step
        pixels = np.round(display * 255.0).astype(np.uint8)
        spec = oiio.ImageSpec(w, h, 3, oiio.UINT8)
        if ext in (".jpg", ".jpeg"):
            spec.attribute("Compression", "jpeg:95")
    _write_atomically(path, spec, pixels)


def _exr_channels(image, passes):
    """Stack the RGB image and the passes into one (h, w, c) array with channel names."""
    arrays, names = [image], ["R", "G", "B"]
    for name, values in passes.items():
        values = np.asarray(values, dtype=np.float32)
        if values.ndim == 2:
            values = values[:, :, None]
        k = values.shape[2]
        arrays.append(values)
        if k == 1:
            names.append(name.upper() if len(name) <= 2 else name)
        else:
            suffixes = "XYZ" if k == 3 else [str(i) for i in range(k)]
            names.extend(f"{name}.{s}" for s in suffixes)
    return np.ascontiguousarray(np.concatenate(arrays, axis=2)), names


def _write_atomically(path, spec, pixels):
    folder = os.path.dirname(os.path.abspath(path))
    base, ext = os.path.splitext(os.path.basename(path))
    # same extension so OpenImageIO picks the right writer; hidden name so nothing half
    # written is mistaken for a result
    fd, tmp = tempfile.mkstemp(prefix=f".{base}.", suffix=f".tmp{ext}", dir=folder)
    os.close(fd)
    try:
        out = oiio.ImageOutput.create(tmp)
        if out is None:
            raise OutputError(f"{path}: no image writer for {ext}: {oiio.geterror()}")
        try:
            if not out.open(tmp, spec):
                raise OutputError(f"{path}: cannot write: {out.geterror() or oiio.geterror()}")
            if not out.write_image(pixels):
                raise OutputError(f"{path}: cannot write: {out.geterror() or oiio.geterror()}")
        finally:
            out.close()
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    # mkstemp creates 0600 files; give the image the permissions a normal file would get
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o666 & ~umask)


def read_image(path):
    """Read an image as float32 (h, w, c) and its channel names.

    8-bit images come back as stored (sRGB-encoded values in [0, 1]); EXR as linear floats.

    Raises
    ------
    OutputError
        If the file cannot be read.
    """
    path = os.fspath(path)
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
