"""Per-image camera JSON in batch renders: vertices of the asset file, projected with the
exported K and world_to_camera_opencv (after asset_to_world), land where the position pass
holds them."""

import json

import numpy as np
import pytest
import trimesh

import rtmesh
from rtmesh.io.images import read_image

# one asset at an odd and one at an even image size (CSV manifest overrides)
SIZES = {"odd.obj": (33, 25), "even.obj": (32, 24)}


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    """A convex mesh (every vertex facing the camera is visible) far from the origin and
    not of unit size, so that auto-framing and normalisation both move it."""
    folder = tmp_path_factory.mktemp("assets")
    mesh = trimesh.creation.icosphere(subdivisions=2)
    mesh.apply_scale([3.0, 2.0, 2.5])
    mesh.apply_translation([5.0, -2.0, 1.0])
    rows = ["path,width,height"]
    for name, (w, h) in SIZES.items():
        mesh.export(folder / name)
        rows.append(f"{name},{w},{h}")
    (folder / "assets.csv").write_text("\n".join(rows) + "\n")
    return folder, np.asarray(mesh.vertices), np.asarray(mesh.vertex_normals)


def _bilinear(image, u, v):
    """``image`` (h, w, c) at film positions (u, v) (pixels; pixel centres at +0.5), and
    whether all four pixels around each position exist."""
    x, y = u - 0.5, v - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    h, w = image.shape[:2]
    inside = (x0 >= 0) & (y0 >= 0) & (x0 + 1 < w) & (y0 + 1 < h)
    x0, y0 = np.clip(x0, 0, w - 2), np.clip(y0, 0, h - 2)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    top = image[y0, x0] * (1 - fx) + image[y0, x0 + 1] * fx
    bottom = image[y0 + 1, x0] * (1 - fx) + image[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy, inside


@pytest.mark.usefixtures("in_process_jobs")
@pytest.mark.parametrize("ortho, normalize", [(False, ""), (True, "unit-sphere"), (False, "unit-cube")])
def test_vertices_project_onto_the_pixels_whose_position_pass_holds_them(assets, tmp_path, ortho, normalize):
    folder, vertices, normals = assets
    out = tmp_path / "out"
    report = rtmesh.batch_convert([folder / "assets.csv"], out, workers=1, spp=16, views=("iso", "front", "top"),
                                  formats=("exr",), passes=("position", "alpha"), camera_json=True,
                                  normalize=normalize, ortho=ortho, progress="none")
    assert report.exit_code == 0
    tested = 0
    for name, (w, h) in SIZES.items():
        for view in ("iso", "front", "top"):
            record = json.loads((out / f"{name}.{view}.camera.json").read_text())
            assert (record["width"], record["height"]) == (w, h)
            assert record["projection"] == ("orthographic" if ortho else "perspective")
            to_world = np.array(record["asset_to_world"])
            if not normalize:
                np.testing.assert_array_equal(to_world, np.eye(4))
            world = vertices @ to_world[:3, :3].T + to_world[:3, 3]
            w2c = np.array(record["world_to_camera_opencv"])
            camera = world @ w2c[:3, :3].T + w2c[:3, 3]
            K = np.array(record["K"])

            def project(points):
                """Film positions (pixels) of world points, with the exported camera."""
                xyz = points @ w2c[:3, :3].T + w2c[:3, 3]
                if ortho:  # no division by depth
                    return K[0, 0] * xyz[:, 0] + K[0, 2], K[1, 1] * xyz[:, 1] + K[1, 2]
                uvw = xyz @ K.T
                return uvw[:, 0] / uvw[:, 2], uvw[:, 1] / uvw[:, 2]

            u, v = project(world)
            if ortho:
                towards = np.tile(w2c[2, :3], (len(world), 1))
            else:
                assert (camera[:, 2] > 0).all()
                towards = world - np.array(record["camera_to_world_opencv"])[:3, 3]
            # visible (convex mesh): facing the camera, away from the silhouette
            cosine = np.einsum("ij,ij->i", normals, towards) / np.linalg.norm(towards, axis=1)
            image, channels = read_image(str(out / f"{name}.{view}.exr"))
            position = image[..., [channels.index(f"position.{c}") for c in "XYZ"]].astype(np.float64)
            alpha = image[..., channels.index("A")].astype(np.float64)
            held, inside = _bilinear(position, u, v)
            coverage, _ = _bilinear(alpha[..., None], u, v)
            use = (cosine < -0.3) & inside & (coverage[:, 0] > 0.999)
            # the surface point the position pass holds at each vertex's projection is the
            # vertex itself up to the pixel grid's interpolation: its own projection lands
            # back on the vertex's (an error in K or the pose moves one and not the other)
            hu, hv = project(held[use])
            error = np.hypot(hu - u[use], hv - v[use])
            assert np.linalg.norm(held[use] - world[use], axis=1).max() < 2.0 * np.abs(world).max() / min(w, h)
            assert use.sum() >= 5, (name, view)
            assert error.max() < 0.5, (name, view, error.max())
            tested += use.sum()
    assert tested > 100


@pytest.mark.usefixtures("in_process_jobs")
def test_camera_json_changes_the_fingerprint_only_when_asked(assets, tmp_path):
    """Without the new options, images keep the fingerprints of earlier batches (nothing is
    redone); asking for the camera files redoes the images with them."""
    folder, _, _ = assets
    out = tmp_path / "out"
    first = rtmesh.batch_convert([folder / "odd.obj"], out, workers=1, width=12, height=10, spp=1,
                                 progress="none")
    assert first.counts["done"] == 1 and not (out / "odd.obj.camera.json").exists()
    again = rtmesh.batch_convert([folder / "odd.obj"], out, workers=1, width=12, height=10, spp=1,
                                 progress="none", camera_json=True)
    assert again.counts["done"] == 1 and (out / "odd.obj.camera.json").exists()
    record = json.loads((out / "odd.obj.camera.json").read_text())
    assert record["width"] == 12 and record["projection"] == "perspective"
    resumed = rtmesh.batch_convert([folder / "odd.obj"], out, workers=1, width=12, height=10, spp=1,
                                   progress="none", camera_json=True)
    assert resumed.counts["skipped"] == 1
