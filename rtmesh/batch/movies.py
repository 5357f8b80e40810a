"""Turntable movies: the frames of an asset's turntable as one animated image.

``rtmesh batch ... --turntable N --movie webp|gif|mp4`` writes ``<asset>.turntable.webp``
(or ``.gif``, ``.mp4``) once all the asset's frames are there, from its PNG (or JPEG) frames
in order, at :data:`FPS` frames per second.  Pillow writes the animated images (WebP
quality 90, GIF with a palette per frame; both loop forever); MP4 (H.264, yuv420p, for
players and web pages) is written by the ffmpeg that the optional ``movie`` extra
(``imageio-ffmpeg``) installs.
"""

import os

import numpy as np
from PIL import Image

from rtmesh.core.errors import MissingExtraError
from rtmesh.io.atomic_files import replace_atomically

MOVIE_FORMATS = ("webp", "gif", "mp4")
MP4_INSTALL = "pip install 'rtmesh[movie]'"
FPS = 12
_FRAME_FORMATS = (".png", ".jpg")


def movie_frames(outdir, images):
    """The frame files (absolute paths) of an asset's turntable ``images`` (dicts with
    ``key`` and ``files``), in key order, one 8-bit image per frame."""
    frames = []
    for image in sorted(images, key=lambda i: i["key"]):
        pictures = [f for f in image["files"] if os.path.splitext(f)[1].lower() in _FRAME_FORMATS]
        if pictures:
            frames.append(os.path.join(outdir, pictures[0]))
    return frames


def write_movie(path, frames, kind, fps=FPS):
    """Assemble ``frames`` (image files) into an animated ``kind`` file at ``path``.

    Parameters
    ----------
    path : str
    frames : list of str
        Image files, all of one size, in playing order.
    kind : {"webp", "gif", "mp4"}
    fps : float
        Frames per second.

    The file is written whole or not at all (a temporary file renamed into place).
    """
    images = [Image.open(f).convert("RGB") for f in frames]
    if kind == "mp4":
        replace_atomically(path, lambda tmp: _write_mp4(tmp, images, fps))
        return path
    options = {"save_all": True, "append_images": images[1:], "duration": int(round(1000.0 / fps)), "loop": 0}
    if kind == "webp":
        options.update(quality=90)
    replace_atomically(path, lambda tmp: images[0].save(tmp, format=kind.upper(), **options))
    return path


def require_mp4():
    """The ``imageio_ffmpeg`` module, or :class:`MissingExtraError` naming the pip command."""
    try:
        import imageio_ffmpeg
    except ImportError:
        raise MissingExtraError(f"movie: MP4 needs ffmpeg: {MP4_INSTALL}") from None
    return imageio_ffmpeg


def _write_mp4(path, images, fps):
    """H.264 in an MP4 container; frames padded to even sides (yuv420p halves the chroma)."""
    imageio_ffmpeg = require_mp4()
    width, height = images[0].size
    even = (width + width % 2, height + height % 2)
    writer = imageio_ffmpeg.write_frames(path, even, fps=fps, codec="libx264", pix_fmt_out="yuv420p",
                                         macro_block_size=2, output_params=["-f", "mp4"], ffmpeg_log_level="error")
    writer.send(None)
    try:
        for image in images:
            pixels = np.asarray(image, dtype=np.uint8)
            # repeat the last row and column to reach even sides
            pixels = np.pad(pixels, ((0, even[1] - height), (0, even[0] - width), (0, 0)), mode="edge")
            writer.send(np.ascontiguousarray(pixels))
    finally:
        writer.close()
