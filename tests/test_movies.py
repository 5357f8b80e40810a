"""Turntable movies: animated WebP and GIF read back with the right frame count and size."""

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
