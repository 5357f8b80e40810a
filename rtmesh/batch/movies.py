"""Turntable movies: the frames of an asset's turntable as one animated image.

``rtmesh batch ... --turntable N --movie webp|gif`` writes ``<asset>.turntable.webp`` (or
``.gif``) once all the asset's frames are there, from its PNG (or JPEG) frames in order,
looping forever at :data:`FPS` frames per second.  Pillow writes both formats (WebP
lossless-quality 90, GIF with a palette per frame).  MP4 is not written (it needs a video
encoder that is not among rtmesh's dependencies).
"""

import os

from PIL import Image

from rtmesh.batch.files import replace_atomically

MOVIE_FORMATS = ("webp", "gif")
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
    kind : {"webp", "gif"}
    fps : float
        Frames per second.

    The file is written whole or not at all (a temporary file renamed into place).
    """
    images = [Image.open(f).convert("RGB") for f in frames]
    options = {"save_all": True, "append_images": images[1:], "duration": int(round(1000.0 / fps)), "loop": 0}
    if kind == "webp":
        options.update(quality=90)
    replace_atomically(path, lambda tmp: images[0].save(tmp, format=kind.upper(), **options))
    return path
