"""Optical flow of batch view sequences and motion vectors: flow against the projection of
the pixel-centre points, forward-backward consistency, occlusion, Middlebury .flo files."""

import json

import numpy as np
import pytest
import trimesh
from local_jobs import jobs_in_this_process

import rtmesh
from rtmesh.io.images import read_image

W, H, FRAMES = 40, 30, 24


@pytest.fixture(scope="module")
def turntable(tmp_path_factory):
    """A slab with a small block in front of it, so the block hides different parts of the
    slab from neighbouring turntable frames."""
    folder = tmp_path_factory.mktemp("flow")
    (folder / "src").mkdir()
    slab = trimesh.creation.box(extents=(2.0, 1.2, 0.3))
    slab.apply_translation([0.0, 0.0, -0.8])
    block = trimesh.creation.box(extents=(0.45, 0.45, 0.45))
    block.apply_translation([0.1, 0.0, 0.5])
    trimesh.util.concatenate([slab, block]).export(folder / "src" / "pair.obj")
    with jobs_in_this_process():
        report = rtmesh.batch_convert([folder / "src"], folder / "out", workers=1, width=W, height=H, spp=1,
                                      turntable=FRAMES, formats=("exr",),
                                      passes=("position_center", "depth_center", "normal_center"),
                                      camera_json=True, flow=True, flow_format="flo", progress="none")
    assert report.exit_code == 0
    views = []
    for i in range(FRAMES):
        key = folder / "out" / f"pair.obj.turn{i:03d}"
        pixels, names = read_image(f"{key}.exr")
        layer = {name: pixels[..., names.index(f"{name}.X"):names.index(f"{name}.X") + 3]
                 for name in ("position_center", "normal_center", "flow_forward", "flow_backward")}
        layer["depth"] = pixels[..., names.index("depth_center.Z")]
        layer["record"] = json.loads(open(f"{key}.camera.json").read())
        layer["key"] = key
        views.append(layer)
    return views


def _project(record, points):
    w2c, k = np.array(record["world_to_camera_opencv"]), np.array(record["K"])
    p = points @ w2c[:3, :3].T + w2c[:3, 3]
    q = p @ k.T
    return q[..., :2] / q[..., 2:], p[..., 2]


def _centres():
    columns, rows = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    return np.stack([columns, rows], axis=-1)


def _neighbours(i):
    return (("flow_forward", i + 1), ("flow_backward", i - 1))


def test_flow_lands_on_the_other_views_projection_of_the_centre_point(turntable):
    checked = 0
    for i, view in enumerate(turntable):
        for name, j in _neighbours(i):
            flow = view[name].astype(np.float64)
            valid = flow[..., 2] == 1
            if not 0 <= j < FRAMES:
                assert not valid.any() and (flow == 0).all()
                continue
            assert set(np.unique(flow[..., 2])) <= {0.0, 1.0}
            uv, _ = _project(turntable[j]["record"], view["position_center"].astype(np.float64))
            landed = _centres() + flow[..., :2]
            np.testing.assert_allclose(landed[valid], uv[valid], atol=0.01)
            assert (flow[~valid, :2] == 0).all()
            assert (~np.isfinite(view["depth"]) <= ~valid).all()  # nothing seen: invalid
            checked += valid.sum()
    assert checked > 500


def _bilinear(image, xy):
    """Bilinear lookup at continuous pixel positions (pixel centres at +0.5)."""
    x, y = xy[:, 0] - 0.5, xy[:, 1] - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    x0, y0 = np.clip(x0, 0, W - 2), np.clip(y0, 0, H - 2)
    a, b = image[y0, x0], image[y0, x0 + 1]
    c, d = image[y0 + 1, x0], image[y0 + 1, x0 + 1]
    return ((1 - fy) * (1 - fx))[:, None] * a + ((1 - fy) * fx)[:, None] * b + \
        (fy * (1 - fx))[:, None] * c + (fy * fx)[:, None] * d


def test_forward_then_backward_flow_comes_back_away_from_silhouettes(turntable):
    errors = []
    for i in range(FRAMES - 1):
        forward = turntable[i]["flow_forward"].astype(np.float64)
        backward = turntable[i + 1]["flow_backward"].astype(np.float64)
        start = _centres().reshape(-1, 2)
        valid = forward[..., 2].reshape(-1) == 1
        landed = start[valid] + forward.reshape(-1, 3)[valid, :2]
        # all four pixels around the landing point valid backwards and of one plane
        # (within 2 px of the image border the lookup clamps)
        inner = (landed[:, 0] > 1.5) & (landed[:, 0] < W - 1.5) & (landed[:, 1] > 1.5) & (landed[:, 1] < H - 1.5)
        back = _bilinear(backward, landed)
        # one plane under the four pixels: their normals agree and their points lie in one
        # plane (not across a silhouette or a crease, where the flow field jumps or bends)
        normal = np.nan_to_num(turntable[i + 1]["normal_center"].astype(np.float64), nan=9.0)
        x0 = np.clip(np.floor(landed[:, 0] - 0.5).astype(int), 0, W - 2)
        y0 = np.clip(np.floor(landed[:, 1] - 0.5).astype(int), 0, H - 2)
        corners = [normal[y0 + dy, x0 + dx] for dy in (0, 1) for dx in (0, 1)]
        points = np.nan_to_num(turntable[i + 1]["position_center"].astype(np.float64))
        offsets = [points[y0 + dy, x0 + dx] - points[y0, x0] for dy in (0, 1) for dx in (0, 1)]
        planar = np.all([np.abs(c - corners[0]).max(axis=1) < 1e-4 for c in corners]
                        + [np.abs(np.sum(o * corners[0], axis=1)) < 1e-4 for o in offsets], axis=0)
        smooth = inner & (back[:, 2] == 1) & planar
        returned = landed[smooth] + back[smooth, :2]
        errors.append(np.linalg.norm(returned - start[valid][smooth], axis=1))
    errors = np.concatenate(errors)
    assert len(errors) > 300
    assert errors.max() < 0.05, errors.max()


def test_points_hidden_in_the_other_view_are_invalid(turntable):
    hidden = 0
    for i, view in enumerate(turntable[:-1]):
        other = turntable[i + 1]
        points = view["position_center"].astype(np.float64)
        uv, z = _project(other["record"], points)
        uv = np.nan_to_num(uv, nan=-1.0)  # pixels that see nothing
        inside = np.isfinite(z) & (z > 0) & (uv[..., 0] >= 1) & (uv[..., 0] < W - 1) & (uv[..., 1] >= 1) & (uv[..., 1] < H - 1)
        column = np.clip(np.floor(uv[..., 0]).astype(int), 1, W - 2)
        row = np.clip(np.floor(uv[..., 1]).astype(int), 1, H - 2)
        # the other view's depth in the 3x3 pixels around where the point lands
        depths = np.stack([other["depth"][row + dy, column + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
        valid = view["flow_forward"][..., 2] == 1
        clearly_hidden = inside & (depths.max(axis=0) < 0.9 * z)  # something well in front, all around
        clearly_seen = inside & (np.abs(depths - z).max(axis=0) < 0.002 * z)
        assert not (valid & clearly_hidden).any()
        assert valid[clearly_seen].all()
        hidden += clearly_hidden.sum()
    assert hidden > 10  # the block hides part of the slab from the next frame


def test_flo_files_hold_the_flow_with_unknown_where_invalid(turntable):
    view = turntable[2]
    for name in ("flow_forward", "flow_backward"):
        data = open(f"{view['key']}.{name}.flo", "rb").read()
        assert np.frombuffer(data[:4], "<f4")[0] == 202021.25
        assert tuple(np.frombuffer(data[4:12], "<i4")) == (W, H)
        uv = np.frombuffer(data[12:], "<f4").reshape(H, W, 2)
        valid = view[name][..., 2] == 1
        np.testing.assert_array_equal(uv[valid], view[name][valid, :2])
        assert (uv[~valid] == 1e10).all() and valid.any() and (~valid).any()


def test_flow_without_exr_is_refused(tmp_path):
    with pytest.raises(rtmesh.RtmeshError, match="flow"):
        rtmesh.batch_convert([tmp_path], tmp_path / "out", flow=True, formats=("png",))
    assert not (tmp_path / "out").exists()


def test_a_flow_format_without_flow_is_refused(tmp_path):
    with pytest.raises(rtmesh.RtmeshError, match="flow format"):
        rtmesh.batch_convert([tmp_path], tmp_path / "out", flow_format="flo", formats=("exr",))


def test_orthographic_flow_lands_on_the_projection_and_sees_occlusion():
    import dataclasses

    from scenes import box, part

    from rtmesh.batch.flow import view_flow
    from rtmesh.materials.table import Material
    from rtmesh.rendering.centre_rays import centre_passes
    from rtmesh.rendering.integrator import Integrator
    from rtmesh.rendering.settings import RenderSettings
    from rtmesh.scene.camera import Camera
    from rtmesh.scene.camera_json import camera_record
    from rtmesh.scene.model import Scene

    # a wall with a block in front of it; the second camera looks from the side, so the
    # block hides part of the wall that the first camera sees
    wall = part("wall", box(extents=(4.0, 3.0, 0.2), centre=(0.0, 0.0, -1.0)))
    block = part("block", box(extents=(0.8, 0.8, 0.8), centre=(0.0, 0.0, 0.6)))
    first = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], projection="orthographic", ortho_height=4.0)
    scene = Scene.from_parts([wall, block], [Material("m")], [], first)
    settings = RenderSettings(width=32, height=24, spp=1, threads=1)
    one = Integrator(scene, settings)
    other = one.with_view(dataclasses.replace(first, position=np.array([3.0, 0.0, 4.0])))
    position = centre_passes(one, ("position_center",))["position_center"]
    record = camera_record(other.scene.camera, 32, 24, scene.bounds)
    flow = view_flow(position, other, record)
    valid = flow[..., 2] == 1
    w2c, k = np.array(record["world_to_camera_opencv"]), np.array(record["K"])
    p = np.nan_to_num(position.astype(np.float64), nan=1e6) @ w2c[:3, :3].T + w2c[:3, 3]
    uv = p[..., :2] @ k[:2, :2].T + k[:2, 2]
    np.testing.assert_allclose((_centres_of(32, 24) + flow[..., :2])[valid], uv[valid], atol=0.01)
    # points of the wall that land inside the other image: most valid, those behind the
    # block (seen from the side) not
    inside = (uv[..., 0] > 0) & (uv[..., 0] < 32) & (uv[..., 1] > 0) & (uv[..., 1] < 24)
    assert valid.sum() > 100 and (inside & ~valid).sum() > 5


def _centres_of(w, h):
    columns, rows = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    return np.stack([columns, rows], axis=-1)
