"""Turntable movies: animated WebP and GIF read back with the right frame count and size."""

import numpy as np
import pytest
import trimesh
from PIL import Image

import rtmesh
from rtmesh.batch.movies import write_movie


def _check_movie(path, frames, size):
    with Image.open(path) as movie:
        assert movie.n_frames == frames and movie.size == size and getattr(movie, "is_animated", False)
        # frames differ (the camera moves)
        movie.seek(0)
        first = movie.convert("RGB").tobytes()
        movie.seek(2)
        assert movie.convert("RGB").tobytes() != first


def test_turntable_movies_have_every_frame_at_the_image_size(tmp_path):
    trimesh.creation.box(extents=(1.0, 2.0, 0.5)).export(tmp_path / "a.obj")
    out = tmp_path / "out"
    report = rtmesh.batch_convert([tmp_path / "a.obj"], out, workers=1, width=12, height=10, spp=1,
                                  turntable=5, movie="webp", progress="none")
    assert report.exit_code == 0
    _check_movie(out / "a.obj.turntable.webp", 5, (12, 10))
    # the same frames as a GIF
    frames = [str(out / f"a.obj.turn{k:03d}.png") for k in range(5)]
    _check_movie(write_movie(str(tmp_path / "a.gif"), frames, "gif"), 5, (12, 10))


def test_a_movie_needs_a_turntable_and_8_bit_frames(tmp_path):
    with pytest.raises(rtmesh.RtmeshError, match="movie: .*--turntable"):
        rtmesh.batch_convert([tmp_path], tmp_path / "out", movie="gif")
    with pytest.raises(rtmesh.RtmeshError, match="movie: .*png"):
        rtmesh.batch_convert([tmp_path], tmp_path / "out", movie="gif", turntable=3, formats=("exr",))
    assert not (tmp_path / "out").exists()


def test_contact_sheet_has_a_named_thumbnail_per_image_per_folder(tmp_path):
    src = tmp_path / "src"
    for name in ("a.obj", "b.obj", "sub/c.obj"):
        (src / name).parent.mkdir(parents=True, exist_ok=True)
        trimesh.creation.box().export(src / name)
    out = tmp_path / "out"
    rtmesh.batch_convert([src], out, workers=1, width=20, height=10, spp=1, progress="none", contact_sheet=True)
    # a resume that skips every image makes the sheets from the finished images too
    (out / "rtmesh-contact-sheet.png").unlink()
    report = rtmesh.batch_convert([src], out, workers=1, width=20, height=10, spp=1, progress="none",
                                  contact_sheet=True)
    assert report.counts["skipped"] == 3
    with Image.open(out / "rtmesh-contact-sheet.png") as sheet:  # a, b: 2 columns, 1 row
        assert sheet.size == (2 * 128, 128 + 14)
        pixels = np.asarray(sheet.convert("L"))
    # each thumbnail (20x10 scaled to 128x64) centred in its tile, its name written below
    for column in range(2):
        tile = pixels[:128, 128 * column:128 * (column + 1)]
        assert (tile[32:96] != 255).any() and (tile[:30] == 255).all()
        assert pixels[128:, 128 * column:128 * (column + 1)].min() < 128
    with Image.open(out / "sub" / "rtmesh-contact-sheet.png") as sheet:
        assert sheet.size == (128, 128 + 14)
