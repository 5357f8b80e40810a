"""The BOP layout: poses, intrinsics, depth and masks read back with the BOP toolkit's
conventions (model vertices in mm, x = K (R X + t), depth_mm = PNG value x depth_scale)."""

import json

import numpy as np
import OpenImageIO as oiio
import pytest
import trimesh
from local_jobs import jobs_in_this_process

import rtmesh

W, H = 48, 36


@pytest.fixture(scope="module")
def bop(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bop")
    (folder / "src").mkdir()
    brick = trimesh.creation.box(extents=(4.0, 3.0, 2.0)).subdivide().subdivide()
    brick.apply_translation([10.0, -3.0, 5.0])
    brick.export(folder / "src" / "brick.obj")
    with jobs_in_this_process():
        report = rtmesh.batch_convert([folder / "src"], folder / "out", workers=1, width=W, height=H, spp=1,
                                      views=("front", "iso", "left"), ground=True, normalize="unit-cube",
                                      dataset="bop", units="cm", progress="none")
    assert report.exit_code == 0
    return folder / "out" / "brick.obj.bop"


def _png(path, kind="uint8"):
    return oiio.ImageInput.open(str(path)).read_image(kind)[..., 0].astype(np.float64)


def test_models_are_in_millimetres_with_their_info(bop):
    model = trimesh.load(bop / "models" / "obj_000001.ply", process=False)
    info = json.loads((bop / "models" / "models_info.json").read_text())["1"]
    # unit-cube: the longest side (4 cm) becomes 1 unit = 1 cm = 10 mm
    np.testing.assert_allclose(model.extents, [10.0, 7.5, 5.0], rtol=1e-6)
    np.testing.assert_allclose([info["size_x"], info["size_y"], info["size_z"]], [10.0, 7.5, 5.0], rtol=1e-6)
    assert info["diameter"] == pytest.approx(np.linalg.norm([10.0, 7.5, 5.0]), rel=1e-6)
    assert json.loads((bop / "scene_info.json").read_text())["mm_per_unit"] == 10.0


def test_model_vertices_project_into_the_masks_with_the_depth_of_the_depth_image(bop):
    model = trimesh.load(bop / "models" / "obj_000001.ply", process=False)
    vertices = np.asarray(model.vertices, dtype=np.float64)
    cameras = json.loads((bop / "scene_camera.json").read_text())
    gt = json.loads((bop / "scene_gt.json").read_text())
    info = json.loads((bop / "scene_gt_info.json").read_text())
    assert sorted(cameras) == sorted(gt) == sorted(info) == ["0", "1", "2"]
    compared = 0
    for image in sorted(cameras):
        camera, (pose,) = cameras[image], gt[image]
        assert pose["obj_id"] == 1
        K = np.array(camera["cam_K"]).reshape(3, 3)
        R, t = np.array(pose["cam_R_m2c"]).reshape(3, 3), np.array(pose["cam_t_m2c"])
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)  # a rotation: BOP poses are rigid
        p = vertices @ R.T + t
        uv = p @ K.T
        uv = uv[:, :2] / uv[:, 2:]
        column, row = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
        inside = (column >= 0) & (column < W) & (row >= 0) & (row < H)
        assert inside.all()
        mask = _png(bop / "mask" / f"{int(image):06d}_000000.png") > 0
        visib = _png(bop / "mask_visib" / f"{int(image):06d}_000000.png") > 0
        assert (visib <= mask).all() and visib.any()
        # every vertex lands in the (amodal) mask or one pixel from it
        near = np.zeros_like(mask)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                near |= np.roll(np.roll(mask, dy, axis=0), dx, axis=1)
        assert near[row, column].all()
        depth = _png(bop / "depth" / f"{int(image):06d}.png", "uint16") * camera["depth_scale"]
        entry = info[image][0]
        assert entry["px_count_visib"] == visib.sum() and entry["px_count_valid"] == mask.sum()
        assert entry["visib_fract"] == pytest.approx(entry["px_count_visib"] / entry["px_count_all"])
        x, y, w, h = entry["bbox_visib"]
        rows, columns = np.nonzero(visib)
        assert (x, y, w, h) == (columns.min(), rows.min(), columns.max() - columns.min(), rows.max() - rows.min())
        if image == "0":
            # the front view: only the front face (+z, parallel to the image) is visible,
            # at one depth, so each of its vertices that lands on a visible pixel has the
            # depth image's depth there
            front = vertices[:, 2] > vertices[:, 2].max() - 1e-6
            seen = front & visib[row, column]
            assert seen.sum() > 10 and entry["visib_fract"] == 1.0
            np.testing.assert_allclose(depth[row[seen], column[seen]], p[seen, 2], atol=1.0)
            compared += seen.sum()
    assert compared


def test_bop_refuses_orthographic_views_and_exr_alone(tmp_path):
    for options in ({"ortho": True}, {"formats": ("exr",)}):
        with pytest.raises(rtmesh.RtmeshError, match="bop"):
            rtmesh.batch_convert([tmp_path], tmp_path / "out", dataset="bop", **options)
    assert not (tmp_path / "out").exists()


def test_a_resume_leaves_no_temporary_file_in_the_bop_folder(tmp_path):
    """A resume links the images into the BOP folder again; a rename between two links to one
    file does nothing, so the temporary link must be removed by hand."""
    (tmp_path / "src").mkdir()
    trimesh.creation.box().export(tmp_path / "src" / "box.obj")
    settings = dict(workers=1, width=16, height=12, spp=1, views=("front",), dataset="bop", progress="none")
    with jobs_in_this_process():
        for run in range(2):
            report = rtmesh.batch_convert([tmp_path / "src"], tmp_path / "out", **settings)
            assert report.exit_code == 0
    names = [p.name for p in (tmp_path / "out").rglob("*")]
    assert any(name.endswith(".png") for name in names)
    assert not [name for name in names if "rtmesh-tmp" in name]


def test_an_output_folder_inside_the_input_folder_is_not_searched_for_assets(tmp_path):
    """The BOP folder holds the models as PLY meshes: a second run over the input folder
    would otherwise render them as new assets."""
    trimesh.creation.box().export(tmp_path / "box.obj")
    settings = dict(workers=1, width=16, height=12, spp=1, views=("front",), dataset="bop", progress="none")
    with jobs_in_this_process():
        for run in range(2):
            report = rtmesh.batch_convert([tmp_path], tmp_path / "out", **settings)
            assert report.exit_code == 0 and report.counts["assets"] == 1, report.counts
    assert not (tmp_path / "out" / "out").exists()
