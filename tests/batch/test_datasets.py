"""Dataset files of multi-view batch renders: nerfstudio transforms.json and COLMAP text,
read back by small readers that follow each tool's documented format."""

import dataclasses
import json
import logging
import os

import numpy as np
import OpenImageIO as oiio
import pytest
import trimesh
from local_jobs import jobs_in_this_process
from scipy.spatial.transform import Rotation

import rtmesh
from rtmesh.batch.datasets import rotation_to_quaternion, write_dataset
from rtmesh.io.images import read_image, write_depth_png
from rtmesh.scene.camera import frame_bounds
from rtmesh.scene.camera_json import camera_record

W, H = 21, 16


def read_nerfstudio(path):
    """A reader after nerfstudio's ``transforms.json`` parser (its "nerfstudio" data
    format): ``camera_model``, intrinsics ``fl_x fl_y cx cy w h`` taken from the top level
    for every frame whenever the top level has them (nerfstudio's ``fx_fixed = "fl_x" in
    meta``: per-frame values are then ignored), else from each frame; ``frames`` with
    ``file_path`` (relative to the JSON's folder) and a 4x4 camera-to-world
    ``transform_matrix`` (OpenGL axes: +y up, the camera looks along -z); optional
    ``depth_file_path`` and ``mask_path`` per frame."""
    with open(path, encoding="utf-8") as f:
        meta = json.load(f)
    folder = os.path.dirname(path)
    model = meta["camera_model"]
    assert model in ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE", "ORTHOPHOTO")
    frames = []
    for frame in meta["frames"]:
        intrinsics = {k: float(meta[k] if k in meta else frame[k]) for k in ("fl_x", "fl_y", "cx", "cy", "w", "h")}
        c2w = np.array(frame["transform_matrix"], dtype=np.float64)
        assert c2w.shape == (4, 4) and np.allclose(c2w[3], [0, 0, 0, 1])
        entry = {"image": os.path.join(folder, frame["file_path"]), "c2w": c2w, "model": model, **intrinsics}
        for key in ("depth_file_path", "mask_path"):
            if key in frame:
                entry[key] = os.path.join(folder, frame[key])
        frames.append(entry)
    return frames


def project_nerfstudio(frame, points):
    """Pixel positions of world points in a nerfstudio frame (pixel centres at +0.5); an
    ``ORTHOPHOTO`` frame's rays start on a grid of ``(pixel - c) / f`` scene units."""
    w2c = np.linalg.inv(frame["c2w"])
    p = points @ w2c[:3, :3].T + w2c[:3, 3]
    depth = 1.0 if frame["model"] == "ORTHOPHOTO" else -p[:, 2]
    return frame["fl_x"] * p[:, 0] / depth + frame["cx"], -frame["fl_y"] * p[:, 1] / depth + frame["cy"]


def read_colmap(folder):
    """cameras.txt and images.txt of COLMAP's text model (PINHOLE: fx fy cx cy; images:
    IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, then a line of 2D points)."""
    def data_lines(name):
        with open(os.path.join(folder, name), encoding="utf-8") as f:
            return [line.rstrip("\n") for line in f if not line.startswith("#")]

    cameras = {}
    for line in data_lines("cameras.txt"):
        if line.strip():
            cid, model, w, h, *params = line.split()
            assert model == "PINHOLE" and len(params) == 4
            cameras[int(cid)] = (int(w), int(h), *map(float, params))
    lines = data_lines("images.txt")
    images = []
    for first in range(0, len(lines) - 1, 2):
        iid, qw, qx, qy, qz, tx, ty, tz, cid, name = lines[first].split()
        assert lines[first + 1].strip() == ""  # no 2D points
        rotation = Rotation.from_quat([float(qx), float(qy), float(qz), float(qw)]).as_matrix()
        images.append({"name": name, "R": rotation, "t": np.array([float(tx), float(ty), float(tz)]),
                       "camera": cameras[int(cid)], "qw": float(qw)})
    assert not [line for line in data_lines("points3D.txt") if line.strip()]
    return images


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    folder = tmp_path_factory.mktemp("dataset")
    mesh = trimesh.creation.icosphere(subdivisions=2)
    mesh.apply_translation([3.0, 1.0, -2.0])
    (folder / "src").mkdir()
    mesh.export(folder / "src" / "ball.obj")
    out = folder / "out"
    with jobs_in_this_process():
        report = rtmesh.batch_convert([folder / "src"], out, workers=1, width=W, height=H, spp=4,
                                      views=("fibonacci:5",), formats=("png", "exr"), passes=("depth", "alpha"),
                                      dataset="nerfstudio", normalize="unit-sphere", progress="none")
    assert report.exit_code == 0
    return out, np.asarray(mesh.vertices), report


def _camera_json_projection(record, points):
    w2c, K = np.array(record["world_to_camera_opencv"]), np.array(record["K"])
    p = (points @ w2c[:3, :3].T + w2c[:3, 3]) @ K.T
    return p[:, 0] / p[:, 2], p[:, 1] / p[:, 2]


def test_nerfstudio_transforms_load_and_project_like_the_camera_json(rendered):
    out, vertices, _ = rendered
    frames = read_nerfstudio(str(out / "ball.obj.transforms.json"))
    assert [os.path.basename(f["image"]) for f in frames] == [f"ball.obj.fib{i:03d}.png" for i in range(5)]
    document = json.loads((out / "ball.obj.transforms.json").read_text())
    # one set of intrinsics, at the top level only
    assert document["camera_model"] == "OPENCV" and document["w"] == W
    assert not any("fl_x" in frame for frame in document["frames"])
    for i, frame in enumerate(frames):
        for key in ("image", "depth_file_path", "mask_path"):
            assert os.path.isfile(frame[key]), frame[key]
        assert (frame["w"], frame["h"]) == (W, H) and frame["cx"] == W / 2 and frame["cy"] == H / 2
        record = json.loads((out / f"ball.obj.fib{i:03d}.camera.json").read_text())
        to_world = np.array(record["asset_to_world"])
        world = vertices @ to_world[:3, :3].T + to_world[:3, 3]
        # unit sphere: the bounding box is centred with a half diagonal of 1
        box = np.array([world.min(axis=0), world.max(axis=0)])
        np.testing.assert_allclose(box.mean(axis=0), 0.0, atol=1e-12)
        assert 0.5 * np.linalg.norm(box[1] - box[0]) == pytest.approx(1.0, abs=1e-12)
        u, v = project_nerfstudio(frame, world)
        u_ref, v_ref = _camera_json_projection(record, world)
        np.testing.assert_allclose(np.c_[u, v], np.c_[u_ref, v_ref], atol=1e-6)
        # depth (mm, 16-bit) and mask PNGs agree with the EXR's passes
        exr, channels = read_image(str(out / f"ball.obj.fib{i:03d}.exr"))
        depth = exr[..., channels.index("depth.Z")]
        alpha = exr[..., channels.index("A")]
        stored = oiio.ImageInput.open(frame["depth_file_path"]).read_image("uint16")[..., 0].astype(float)
        hit = depth > 0
        assert hit.any() and (~hit).any()
        np.testing.assert_allclose(stored[hit], np.round(depth[hit] * 1000.0), atol=1)
        assert (stored[~hit] == 0).all()
        mask = oiio.ImageInput.open(frame["mask_path"]).read_image("uint8")
        assert mask.shape == (H, W, 1)
        np.testing.assert_array_equal(mask[..., 0] == 255, alpha > 0.5)


def test_colmap_text_model_matches_the_camera_json(rendered, tmp_path):
    out, vertices, _ = rendered
    images = [{"key": f"ball.obj.fib{i:03d}",
               "files": [f"ball.obj.fib{i:03d}.png", f"ball.obj.fib{i:03d}.camera.json"]} for i in range(5)]
    written = write_dataset("colmap", str(out), "ball.obj", images)
    assert sorted(os.path.basename(p) for p in written) == ["cameras.txt", "images.txt", "points3D.txt"]
    model = read_colmap(str(out / "ball.obj.colmap"))
    assert [m["name"] for m in model] == [f"ball.obj.fib{i:03d}.png" for i in range(5)]
    for i, image in enumerate(model):
        record = json.loads((out / f"ball.obj.fib{i:03d}.camera.json").read_text())
        w, h, fx, fy, cx, cy = image["camera"]
        assert (w, h, cx, cy) == (W, H, W / 2, H / 2) and fx == fy == record["fx"]
        assert image["qw"] >= 0
        p = vertices @ image["R"].T + image["t"]
        u, v = fx * p[:, 0] / p[:, 2] + cx, fy * p[:, 1] / p[:, 2] + cy
        u_ref, v_ref = _camera_json_projection(record, vertices)
        np.testing.assert_allclose(np.c_[u, v], np.c_[u_ref, v_ref], atol=1e-6)


def test_quaternions_round_trip_every_rotation_branch():
    rotations = list(Rotation.random(200, random_state=5).as_matrix())
    # near 180 degrees about each axis: Shepperd's other branches
    rotations += [Rotation.from_rotvec(np.pi * 0.999 * axis).as_matrix() for axis in np.eye(3)]
    for r in rotations:
        q = rotation_to_quaternion(r)
        assert q[0] >= 0 and abs(np.linalg.norm(q) - 1.0) < 1e-12
        np.testing.assert_allclose(Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix(), r, atol=1e-12)


def test_nerfstudio_takes_orthographic_views(tmp_path):
    from rtmesh.batch.options import BatchOptions

    BatchOptions(dataset="nerfstudio", ortho=True).validate()  # ORTHOPHOTO: no error


def test_colmap_with_ortho_is_refused(tmp_path):
    with pytest.raises(rtmesh.RtmeshError, match="colmap"):
        rtmesh.batch_convert([tmp_path], tmp_path / "out", dataset="colmap", ortho=True)
    assert not (tmp_path / "out").exists()


def _records(tmp_path, cameras, sizes):
    """Camera JSON files and image names of views of a unit box, as a batch leaves them."""
    bounds = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
    images = []
    for i, (camera, (w, h)) in enumerate(zip(cameras, sizes)):
        key = f"box.obj.v{i}"
        (tmp_path / f"{key}.camera.json").write_text(json.dumps(camera_record(camera, w, h, bounds)))
        (tmp_path / f"{key}.png").write_bytes(b"")
        images.append({"key": key, "files": [f"{key}.png", f"{key}.camera.json"]})
    return images


def _camera(direction, **fields):
    return dataclasses.replace(frame_bounds(np.array([[-1.0] * 3, [1.0] * 3]), direction=direction), **fields)


def test_differing_intrinsics_go_into_the_frames_only(tmp_path):
    cameras = [_camera((0.3, 0.4, 1.0)), _camera((1.0, 0.2, 0.1), fov=30.0), _camera((0.0, 1.0, 0.2))]
    images = _records(tmp_path, cameras, [(W, H), (W, H), (2 * W, H)])
    path = write_dataset("nerfstudio", str(tmp_path), "box.obj", images)[0]
    document = json.loads(open(path).read())
    # any top-level intrinsic would make nerfstudio ignore every frame's own
    assert not {"fl_x", "fl_y", "cx", "cy", "w", "h"} & set(document)
    frames = read_nerfstudio(path)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    for frame, image in zip(frames, images):
        record = json.loads((tmp_path / f"{image['key']}.camera.json").read_text())
        assert (frame["fl_x"], frame["w"]) == (record["fx"], record["width"])
        np.testing.assert_allclose(np.c_[project_nerfstudio(frame, corners)],
                                   np.c_[_camera_json_projection(record, corners)], atol=1e-9)


def test_orthographic_views_are_orthophoto_and_project_like_the_camera_json(tmp_path):
    cameras = [_camera(d, projection="orthographic", ortho_height=3.0) for d in ((0, 0, 1), (1, 0.5, 0.2))]
    images = _records(tmp_path, cameras, [(W, H)] * 2)
    frames = read_nerfstudio(write_dataset("nerfstudio", str(tmp_path), "box.obj", images)[0])
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    for frame, image in zip(frames, images):
        assert frame["model"] == "ORTHOPHOTO"
        record = json.loads((tmp_path / f"{image['key']}.camera.json").read_text())
        w2c, K = np.array(record["world_to_camera_opencv"]), np.array(record["K"])
        p = corners @ w2c[:3, :3].T + w2c[:3, 3]  # u = fx x + cx: no division by depth
        expected = np.c_[K[0, 0] * p[:, 0] + K[0, 2], K[1, 1] * p[:, 1] + K[1, 2]]
        np.testing.assert_allclose(np.c_[project_nerfstudio(frame, corners)], expected, atol=1e-9)


def test_mixing_orthographic_and_perspective_views_is_refused_in_one_line(tmp_path):
    cameras = [_camera((0, 0, 1)), _camera((0, 0, 1), projection="orthographic", ortho_height=3.0)]
    images = _records(tmp_path, cameras, [(W, H)] * 2)
    with pytest.raises(rtmesh.RtmeshError, match="box.obj.transforms.json: camera_model") as error:
        write_dataset("nerfstudio", str(tmp_path), "box.obj", images)
    assert "\n" not in str(error.value)
    assert not (tmp_path / "box.obj.transforms.json").exists()


def test_a_clipping_depth_png_warns_once_naming_the_file_and_the_farthest_depth(tmp_path, caplog):
    depth = np.array([[1.0, 70.25], [np.inf, 80.5]])
    path = tmp_path / "far.depth.png"
    with caplog.at_level(logging.WARNING, logger="rtmesh.io.images"):
        write_depth_png(str(path), depth)
        write_depth_png(str(tmp_path / "near.depth.png"), np.minimum(depth, 65.0))
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 1 and str(path) in lines[0] and "80.5" in lines[0] and "65.535" in lines[0]
    stored = oiio.ImageInput.open(str(path)).read_image("uint16")[..., 0]
    np.testing.assert_array_equal(stored, [[1000, 65535], [0, 65535]])


def test_a_resumed_batch_writes_the_dataset_of_skipped_assets(rendered):
    out, _, _ = rendered
    os.unlink(out / "ball.obj.transforms.json")
    report = rtmesh.batch_convert([out.parent / "src"], out, workers=1, width=W, height=H, spp=4,
                                  views=("fibonacci:5",), formats=("png", "exr"), passes=("depth", "alpha"),
                                  dataset="nerfstudio", normalize="unit-sphere", progress="none")
    assert report.counts["skipped"] == 1 and report.counts["done"] == 0
    assert len(read_nerfstudio(str(out / "ball.obj.transforms.json"))) == 5
