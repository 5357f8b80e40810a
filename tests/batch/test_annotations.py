"""COCO instance annotations: masks, boxes and areas against pycocotools (the test oracle, a
test extra), visible fractions of an analytic occlusion, amodal boxes, keypoints and poses."""

import json

import numpy as np
import pycocotools.coco as coco_api
import pycocotools.mask as mask_api
import pytest

from rtmesh.cli import main
from rtmesh.io.images import read_image
from rtmesh.io.rle import encode, mask_box

# pycocotools' decode passes copy=False to an __array__ without it (NumPy 2), not our concern
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

W, H = 64, 48
# a 2x2 square 5 units in front of the camera, its left half hidden by a nearer square
# whose right edge is at x = 0: on the image's centre line, which is a pixel boundary
SCENE = f"""
[render]
width = {W}
height = {H}
spp = 2
[camera]
position = [0.0, 0.0, 0.0]
look_at = [0.0, 0.0, -1.0]
up = [0.0, 1.0, 0.0]
fov = 40
[[objects]]
name = "far"
category = "tile"
primitive = "plane"
size = [2.0, 2.0]
translate = [0.0, 0.0, -5.0]
[[objects]]
name = "near"
category = "cover"
primitive = "plane"
size = [1.5, 1.8]
translate = [-0.75, 0.0, -4.0]
[[objects]]
name = "hidden"
primitive = "plane"
size = [0.5, 0.5]
translate = [-0.5, 0.0, -6.0]
[[objects]]
name = "outside"
primitive = "box"
translate = [0.0, 30.0, -5.0]
"""


@pytest.fixture(scope="module")
def annotated(tmp_path_factory):
    folder = tmp_path_factory.mktemp("coco")
    (folder / "tiles.toml").write_text(SCENE)
    out, path = folder / "tiles.exr", folder / "tiles.coco.json"
    assert main(["render", str(folder / "tiles.toml"), "-o", str(out), "--passes", "object_id",
                 "--annotations", str(path), "-q"]) == 0
    pixels, names = read_image(out)
    return json.loads(path.read_text()), pixels[..., names.index("object_id.id")], path


def test_masks_areas_and_boxes_agree_with_pycocotools_and_the_object_id_pass(annotated):
    document, object_id, path = annotated
    coco = coco_api.COCO(str(path))  # the file loads in COCO's own reader
    assert coco.getImgIds() == [1] and coco.imgs[1]["file_name"] == "tiles.exr"
    names = {a["object_name"]: a for a in document["annotations"]}
    # objects with no visible pixel (behind the far tile, out of view) get no annotation
    assert set(names) == {"far", "near"}
    categories = {c["id"]: c["name"] for c in document["categories"]}
    assert {categories[a["category_id"]] for a in document["annotations"]} == {"tile", "cover"}
    for annotation in document["annotations"]:
        index = ["far", "near", "hidden", "outside"].index(annotation["object_name"])
        rle = dict(annotation["segmentation"], counts=annotation["segmentation"]["counts"].encode())
        decoded = mask_api.decode(rle).astype(bool)
        np.testing.assert_array_equal(decoded, object_id == index)
        assert mask_api.area(rle) == annotation["area"] == decoded.sum()
        np.testing.assert_array_equal(mask_api.toBbox(rle), annotation["bbox"])
        assert annotation["iscrowd"] == 0
        x, y, w, h = annotation["bbox"]
        xa, ya, wa, ha = annotation["bbox_amodal"]
        assert xa <= x and ya <= y and x + w <= xa + wa and y + h <= ya + ha


def test_a_square_half_hidden_is_half_visible_and_an_unoccluded_one_wholly(annotated):
    document, _, _ = annotated
    names = {a["object_name"]: a for a in document["annotations"]}
    far, near = names["far"], names["near"]
    assert far["visible_fraction"] == pytest.approx(0.5, abs=0.01)
    assert near["visible_fraction"] == 1.0 and near["area"] == near["area_amodal"]
    # the far tile's amodal box is its whole projection: 2 units at 5, f = 24 / tan(20 deg)
    f = 24 / np.tan(np.radians(20))
    side = 2 * f / 5
    x, y, w, h = far["bbox_amodal"]
    assert abs(w - side) <= 1 and abs(h - side) <= 1 and x + w / 2 == W / 2 and y + h / 2 == H / 2


def test_keypoints_and_pose_place_the_model_box(annotated):
    document, _, _ = annotated
    far = next(a for a in document["annotations"] if a["object_name"] == "far")
    pose = np.array(far["pose"])
    # the plane's model frame is moved 5 units ahead; OpenCV axes flip y and z
    np.testing.assert_allclose(pose, [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 5], [0, 0, 0, 1]], atol=1e-12)
    keypoints = np.array(far["keypoints_3d_box"]).reshape(8, 3)
    f = 24 / np.tan(np.radians(20))
    expected_u = W / 2 + np.array([-1, 1] * 4) * f / 5
    np.testing.assert_allclose(keypoints[:, 0], expected_u, atol=1e-9)
    assert (keypoints[:, 2] == 2).all()


def test_run_length_encoding_matches_pycocotools_on_random_and_edge_masks():
    rng = np.random.default_rng(7)
    masks = [rng.random((h, w)) < rng.random() for h, w in rng.integers(1, 30, (40, 2))]
    masks += [np.zeros((5, 7), bool), np.ones((5, 7), bool), np.eye(9, dtype=bool)]
    big = np.zeros((600, 700), bool)
    big[3:, 5:] = True  # runs longer than 2^10: several 5-bit groups, negative differences
    masks.append(big)
    for mask in masks:
        reference = mask_api.encode(np.asfortranarray(mask.astype(np.uint8)))
        ours = encode(mask)
        assert ours["counts"] == reference["counts"].decode() and ours["size"] == list(reference["size"])
        assert mask_box(mask) == list(mask_api.toBbox(reference))


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    import trimesh

    import rtmesh

    folder = tmp_path_factory.mktemp("coco_batch")
    (folder / "src" / "shapes").mkdir(parents=True)
    trimesh.creation.box(extents=(1.0, 0.6, 0.8)).export(folder / "src" / "shapes" / "brick.obj")
    trimesh.creation.icosphere(subdivisions=2).export(folder / "src" / "ball.obj")
    options = dict(workers=1, width=32, height=24, spp=1, views=("front", "iso"), ground=True,
                   annotations=True, progress="none")
    from local_jobs import jobs_in_this_process

    with jobs_in_this_process():
        report = rtmesh.batch_convert([folder / "src"], folder / "out", **options)
    assert report.exit_code == 0
    return folder, options


def test_a_batch_merges_every_views_annotations_per_output_folder(batch):
    folder, _ = batch
    out = folder / "out"
    for merged, asset, category in ((out / "annotations.coco.json", "ball.obj", "ball.obj"),
                                    (out / "shapes" / "annotations.coco.json", "brick.obj", "shapes/brick.obj")):
        coco = coco_api.COCO(str(merged))
        assert sorted(image["file_name"] for image in coco.imgs.values()) == [f"{asset}.front.png",
                                                                             f"{asset}.iso.png"]
        # the category is the asset's name (relative to its input root)
        assert [c["name"] for c in coco.cats.values()] == [category]
        # one instance per view (the ground plane is not annotated), wholly visible
        assert len(coco.anns) == 2
        for annotation in coco.anns.values():
            assert annotation["visible_fraction"] == 1.0
            mask = coco.annToMask(annotation)
            assert mask.sum() == annotation["area"] > 20


def test_a_resumed_batch_writes_the_same_merged_annotations(batch):
    import rtmesh

    folder, options = batch
    merged = folder / "out" / "annotations.coco.json"
    before = merged.read_bytes()
    merged.unlink()
    report = rtmesh.batch_convert([folder / "src"], folder / "out", **options)
    assert report.counts["skipped"] == 2 and report.counts["done"] == 0
    assert merged.read_bytes() == before


def test_an_annotations_file_in_a_missing_folder_is_one_line_before_rendering(tmp_path, capsys):
    (tmp_path / "s.toml").write_text('[[objects]]\nprimitive = "box"\n')
    missing = tmp_path / "nowhere" / "a.json"
    assert main(["render", str(tmp_path / "s.toml"), "-o", str(tmp_path / "o.png"), "--annotations",
                 str(missing)]) == 2
    err = capsys.readouterr().err
    assert str(missing) in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o.png").exists()


@pytest.mark.parametrize("shutter", [(1.0, 1.0), (1.0, 2.0)])
def test_a_moving_objects_pose_is_where_the_shutter_opens(tmp_path, shutter):
    scene = (f"[render]\nwidth = 32\nheight = 24\nspp = 1\n[camera]\nposition = [0.0, 0.0, 0.0]\n"
             f"look_at = [0.0, 0.0, -1.0]\nfov = 40\nshutter = [{shutter[0]}, {shutter[1]}]\n"
             "[[objects]]\nname = \"slider\"\nprimitive = \"box\"\ntranslate = [-0.5, 0.0, -5.0]\n"
             "motion = { translate = [0.5, 0.25, 0.0] }\n")
    (tmp_path / "s.toml").write_text(scene)
    assert main(["render", str(tmp_path / "s.toml"), "-o", str(tmp_path / "s.png"), "--annotations",
                 str(tmp_path / "s.json"), "-q"]) == 0
    (annotation,) = json.loads((tmp_path / "s.json").read_text())["annotations"]
    # at t = 1 the box's centre is at (0, 0.25, -5): OpenCV axes flip y and z
    np.testing.assert_allclose(np.array(annotation["pose"])[:3, 3], [0.0, -0.25, 5.0], atol=1e-12)
    keypoints = np.array(annotation["keypoints_3d_box"]).reshape(8, 3)
    f = 12 / np.tan(np.radians(20))
    # corners at y = 0.25 +- 0.5, depths 4.5 and 5.5: their mean image row
    np.testing.assert_allclose(keypoints[:, :2].mean(axis=0), [16.0, 12 - f * 0.25 * (1 / 4.5 + 1 / 5.5) / 2],
                               atol=1e-9)
