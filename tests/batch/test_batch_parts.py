"""Direct tests of the small batch modules that the end-to-end batch tests exercise only
through whole runs: normalize, progress, publish and contact_sheet."""

import io
import json
import os

import numpy as np
import pytest
from PIL import Image

from rtmesh.batch import contact_sheet, normalize, progress, publish
from rtmesh.batch.identity import describe


# ---------------------------------------------------------------- normalize
@pytest.mark.parametrize("mode", ["unit-cube", "unit-sphere"])
def test_normalised_bounds_are_centred_and_of_unit_size(mode):
    bounds = np.array([[-3.0, 2.0, 10.0], [5.0, 4.0, 11.0]])
    matrix = normalize.asset_to_world(bounds, mode)
    corners = np.array([[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]])
    moved = normalize.transform_points(matrix, corners)
    np.testing.assert_allclose(moved.mean(axis=0), 0.0, atol=1e-12)
    if mode == "unit-cube":
        assert np.isclose(np.ptp(moved, axis=0).max(), 1.0)
    else:
        assert np.isclose(np.linalg.norm(moved, axis=1).max(), 1.0)
    # one scale for every axis: shapes and normals are kept
    linear = matrix[:3, :3]
    assert np.array_equal(linear, matrix[0, 0] * np.eye(3))


def test_no_normalisation_and_a_single_point():
    assert np.array_equal(normalize.asset_to_world([[1, 2, 3], [4, 5, 6]], ""), np.eye(4))
    point = normalize.asset_to_world([[1.0, 2.0, 3.0], [1.0, 2.0, 3.0]], "unit-cube")
    np.testing.assert_allclose(normalize.transform_points(point, [[1.0, 2.0, 3.0]]), [[0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="normalize: unknown 'unit-box'"):
        normalize.asset_to_world([[0, 0, 0], [1, 1, 1]], "unit-box")


# ---------------------------------------------------------------- progress
def _record(status="done", images=2):
    return {"asset": "a.obj", "status": status, "seconds": 1.5, "errors": [],
            "images": [{"status": "done"}] * images}


def test_json_progress_writes_one_line_per_finished_asset():
    stream = io.StringIO()
    p = progress.JsonProgress(total=3, finished=1, stream=stream)
    p.update(_record())
    p.update(_record("failed", images=0))
    lines = [json.loads(line) for line in stream.getvalue().splitlines()]
    assert [line["finished"] for line in lines] == [2, 3] and {line["total"] for line in lines} == {3}
    assert lines[0]["images"] == 2 and lines[1]["status"] == "failed" and lines[1]["images"] == 0


def test_log_progress_counts_failures_and_says_what_is_left():
    stream = io.StringIO()  # not a terminal: a line at the end (and every log_every seconds)
    bar = progress.BatchProgress(total=2, skipped=0, stream=stream, log_every=3600.0)
    bar.update(_record())
    assert stream.getvalue() == ""  # too soon for a log line, and not the last asset
    bar.update(_record("failed"))
    line = stream.getvalue().strip()
    assert line.startswith("rtmesh batch: [") and "2/2 assets, 1 failed" in line and "left" in line
    bar.close()


def test_progress_is_silent_when_everything_was_skipped():
    stream = io.StringIO()
    bar = progress.BatchProgress(total=2, skipped=2, stream=stream)
    bar.update(_record())
    bar.close()
    assert stream.getvalue() == ""


@pytest.mark.parametrize("seconds,text", [(5, "5s"), (61, "1m01s"), (3725, "1h02m")])
def test_durations(seconds, text):
    assert progress._duration(seconds) == text


# ---------------------------------------------------------------- publish
def test_publish_renames_in_order_and_names_the_file_that_failed(tmp_path):
    (tmp_path / ".a.png.x.tmp.png").write_bytes(b"a")
    (tmp_path / ".b.png.y.tmp.png").write_bytes(b"b")
    publish.publish(str(tmp_path), [(".a.png.x.tmp.png", "a.png")])
    assert (tmp_path / "a.png").read_bytes() == b"a"
    with pytest.raises(OSError) as failure:
        publish.publish(str(tmp_path), [(".b.png.y.tmp.png", "b.png"), ("missing.tmp", "c.png")])
    assert failure.value.filename == "c.png" and (tmp_path / "b.png").is_file()
    publish.discard(str(tmp_path), ["never-there.tmp"])  # no error


def test_leftovers_roll_forward_only_what_the_ledger_recorded(tmp_path):
    # temporaries as replace_atomically names them: ".STEM.RANDOM.tmp.EXT" stands for STEM.EXT
    good, bad = tmp_path / ".img.k2j4_x9q.tmp.png", tmp_path / ".other.k2j4_x9q.tmp.png"
    good.write_bytes(b"recorded bytes")
    bad.write_bytes(b"something else")
    (tmp_path / "mine.txt").write_text("a user's file")
    entry = describe(str(good), "img.png")
    leftovers = publish.Leftovers(str(tmp_path))
    assert sorted(os.path.basename(p) for p in leftovers.paths) == sorted([good.name, bad.name])
    assert leftovers.roll_forward(entry, str(tmp_path / "img.png"))
    assert (tmp_path / "img.png").read_bytes() == b"recorded bytes"
    other_entry = describe(str(tmp_path / "img.png"), "other.png")
    assert not leftovers.roll_forward(other_entry, str(tmp_path / "other.png"))
    leftovers.remove()
    assert sorted(os.listdir(tmp_path)) == ["img.png", "mine.txt"]


# ---------------------------------------------------------------- contact sheet
def test_contact_sheet_lays_out_every_picture_of_a_folder(tmp_path):
    (tmp_path / "cars").mkdir()
    colours = {"a": (255, 0, 0), "b": (0, 255, 0), "c": (0, 0, 255)}
    images = []
    for name, colour in colours.items():
        Image.new("RGB", (64, 32), colour).save(tmp_path / "cars" / f"{name}.png")
        images.append((f"cars/{name}", [f"cars/{name}.exr", f"cars/{name}.png", f"cars/{name}.depth.png"]))
    images.append(("cars/d", ["cars/d.exr"]))  # no picture: left out
    written = contact_sheet.write_contact_sheets(str(tmp_path), images)
    assert written == [str(tmp_path / "cars" / contact_sheet.SHEET_NAME)]
    sheet = np.asarray(Image.open(written[0]).convert("RGB"))
    tile, label = contact_sheet.TILE, contact_sheet.LABEL
    # ceil(sqrt(3)) = 2 columns, 2 rows, in name order; each thumbnail centred in its tile
    assert sheet.shape == (2 * (tile + label), 2 * tile, 3)
    for i, name in enumerate(sorted(colours)):
        y = (i // 2) * (tile + label) + tile // 2
        x = (i % 2) * tile + tile // 2
        assert tuple(sheet[y, x]) == colours[name], name
    assert (sheet[tile + label + tile // 2, tile + tile // 2] == 255).all()  # the empty fourth tile
