"""Turntable movies: animated WebP and GIF and MP4 read back with the right frame count and size."""

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


@pytest.mark.usefixtures("in_process_jobs")
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


@pytest.mark.usefixtures("in_process_jobs")
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


def test_mp4_movies_read_back_with_every_frame_at_an_even_size(tmp_path):
    import imageio_ffmpeg

    frames = []
    for k in range(6):
        pixels = np.zeros((9, 13, 3), dtype=np.uint8)  # odd sides: padded to 14 x 10 for yuv420p
        pixels[:, 2 * k] = 255
        path = tmp_path / f"f{k}.png"
        Image.fromarray(pixels).save(path)
        frames.append(str(path))
    movie = write_movie(str(tmp_path / "a.mp4"), frames, "mp4", fps=6)
    reader = imageio_ffmpeg.read_frames(movie)
    meta = next(reader)
    decoded = [np.frombuffer(f, dtype=np.uint8).reshape(meta["size"][1], meta["size"][0], 3) for f in reader]
    assert tuple(meta["size"]) == (14, 10) and len(decoded) == 6
    # the bright column moves right by two pixels a frame (H.264 is lossy: look for the peak)
    peaks = [int(np.argmax(frame[:, :13, 0].mean(axis=0))) for frame in decoded]
    assert peaks == [0, 2, 4, 6, 8, 10]
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix != ".png") == ["a.mp4"]  # no temporary left


def test_mp4_without_the_movie_extra_is_one_line_naming_it(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # import imageio_ffmpeg raises ImportError
    trimesh.creation.box().export(tmp_path / "a.obj")
    with pytest.raises(rtmesh.RtmeshError, match=r"movie: MP4 needs ffmpeg: pip install 'rtmesh\[movie\]'"):
        rtmesh.batch_convert([tmp_path / "a.obj"], tmp_path / "out", movie="mp4", turntable=3)
    assert not (tmp_path / "out").exists()
