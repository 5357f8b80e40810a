"""The camera JSON: intrinsics and poses that project the rendered surfaces onto their pixels."""

import json

import numpy as np
from scenes import render, sphere_on_floor_scene

from rtmesh.cli import main
from rtmesh.scene.camera_json import camera_record

WIDTH, HEIGHT = 40, 30


def test_k_and_the_opencv_pose_project_every_hit_onto_its_pixel_centre():
    """At one sample per pixel with the regular sampler each camera ray goes through its
    pixel's centre; projecting the hit position (the position pass) with K [R | t] must give
    that centre back."""
    scene = sphere_on_floor_scene()
    result = render(scene, width=WIDTH, height=HEIGHT, spp=1, sampler="regular", passes=("position", "alpha"))
    record = camera_record(scene.camera, WIDTH, HEIGHT, scene.bounds)
    hit = result.passes["alpha"][..., 0] > 0
    rows, columns = np.nonzero(hit)
    world = result.passes["position"][rows, columns].astype(np.float64)
    w2c = np.array(record["world_to_camera_opencv"])
    camera_points = world @ w2c[:3, :3].T + w2c[:3, 3]
    assert (camera_points[:, 2] > 0).all()
    projected = camera_points @ np.array(record["K"]).T
    pixel = projected[:, :2] / projected[:, 2:]
    # float32 positions: a few 1e-4 of a pixel
    np.testing.assert_allclose(pixel, np.column_stack([columns + 0.5, rows + 0.5]), atol=2e-3)
    assert record["near"] <= camera_points[:, 2].min() and camera_points[:, 2].max() <= record["far"]


def test_the_conventions_agree_with_each_other():
    scene = sphere_on_floor_scene()
    record = camera_record(scene.camera, WIDTH, HEIGHT, scene.bounds)
    opencv, opengl = np.array(record["camera_to_world_opencv"]), np.array(record["camera_to_world_opengl"])
    # OpenGL is OpenCV with y and z flipped; both are rigid, and world_to_camera inverts OpenCV
    np.testing.assert_allclose(opengl, opencv @ np.diag([1.0, -1.0, -1.0, 1.0]), atol=1e-12)
    np.testing.assert_allclose(opencv[:3, :3].T @ opencv[:3, :3], np.eye(3), atol=1e-12)
    assert np.linalg.det(opencv[:3, :3]) > 0
    np.testing.assert_allclose(np.array(record["world_to_camera_opencv"]) @ opencv, np.eye(4), atol=1e-12)
    # fy from the vertical field of view: a point at the top edge of the view projects to y = 0
    k = np.array(record["K"])
    half = np.tan(np.radians(record["fov_y_degrees"]) / 2)
    assert abs((k @ [0.0, -half, 1.0])[1]) < 1e-9 and record["cx"] == WIDTH / 2 and record["cy"] == HEIGHT / 2


def test_render_writes_the_camera_json_next_to_the_image(tmp_path, capsys):
    out, cam = tmp_path / "show.png", tmp_path / "show.json"
    assert main(["render", "assets/showcase.toml", "-o", str(out), "--width", "32", "--height", "24",
                 "--spp", "1", "--camera-json", str(cam), "-q"]) == 0
    record = json.loads(cam.read_text())
    assert record["width"] == 32 and record["height"] == 24 and record["projection"] == "perspective"
    assert np.array(record["K"]).shape == (3, 3) and np.array(record["asset_to_world"]).shape == (4, 4)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([out.name, cam.name])  # no temporary left
    # a folder that does not exist: one line, exit 2, no image
    code = main(["render", "assets/showcase.toml", "-o", str(tmp_path / "x.png"), "--width", "8", "--height", "8",
                 "--camera-json", str(tmp_path / "missing" / "c.json"), "-q"])
    assert code == 2 and not (tmp_path / "x.png").exists()
    assert "no such folder" in capsys.readouterr().err


def orthographic_spheres_scene():
    """Two unit spheres, one 6 units farther from the camera than the other, seen
    orthographically from +z with a 10-unit-high view."""
    from scenes import icosphere, part

    from rtmesh.lights.point_lights import DirectionalLight
    from rtmesh.materials.table import Material
    from rtmesh.scene.camera import Camera
    from rtmesh.scene.model import Scene

    near, far = icosphere(3, 1.0, (-2.5, 0.0, 0.0)), icosphere(3, 1.0, (2.5, 0.0, -6.0))
    camera = Camera([0.0, 0.0, 10.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], projection="orthographic",
                    ortho_height=10.0)
    return Scene.from_parts([part("near", near), part("far", far)], [Material("m", diffuse=0.7)],
                            [DirectionalLight([0.0, 0.0, -1.0], 1.0)], camera)


def test_orthographic_views_keep_sizes_and_project_hits_without_perspective():
    scene = orthographic_spheres_scene()
    width, height = 60, 30
    result = render(scene, width=width, height=height, spp=1, sampler="regular", passes=("position", "alpha"))
    covered = result.passes["alpha"][..., 0] > 0
    # equal spheres at different depths cover the same number of pixels (no foreshortening):
    # each is a disk of radius 1 at 3 pixels per unit, about pi * 9 = 28 pixels
    left, right = covered[:, : width // 2].sum(), covered[:, width // 2:].sum()
    assert left == right and 20 < left < 36
    record = camera_record(scene.camera, width, height, scene.bounds)
    assert record["projection"] == "orthographic" and record["fov_y_degrees"] is None
    assert record["ortho_height"] == 10.0 and record["ortho_width"] == 20.0
    rows, columns = np.nonzero(covered)
    world = result.passes["position"][rows, columns].astype(np.float64)
    w2c = np.array(record["world_to_camera_opencv"])
    camera_points = world @ w2c[:3, :3].T + w2c[:3, 3]
    k = np.array(record["K"])
    pixel = camera_points[:, :2] @ k[:2, :2].T + k[:2, 2]  # no division by depth
    np.testing.assert_allclose(pixel, np.column_stack([columns + 0.5, rows + 0.5]), atol=2e-3)


def test_scene_files_and_gltf_files_give_orthographic_cameras(tmp_path):
    import pytest

    from rtmesh.core.errors import SceneError
    from rtmesh.loaders.gltf_nodes import cameras_from_gltf
    from rtmesh.loaders.scene_file import scene_from_dict

    doc = {"camera": {"position": [0, 0, 5], "look_at": [0, 0, 0], "projection": "orthographic",
                      "ortho_height": 3.0},
           "objects": [{"primitive": "box"}]}
    scene, _ = scene_from_dict(doc)
    assert scene.camera.orthographic and scene.camera.ortho_height == 3.0
    del doc["camera"]["ortho_height"]
    with pytest.raises(SceneError, match="camera: an orthographic camera needs ortho_height > 0"):
        scene_from_dict(doc)
    gltf = {"cameras": [{"type": "orthographic", "orthographic": {"xmag": 2.0, "ymag": 1.5, "znear": 0.1,
                                                                  "zfar": 100}}],
            "nodes": [{"camera": 0, "translation": [0, 0, 4], "scale": [2, 2, 2]}],
            "scenes": [{"nodes": [0]}], "scene": 0}
    ((names, camera),) = cameras_from_gltf(gltf)
    assert camera.orthographic and camera.ortho_height == pytest.approx(6.0)  # 2 ymag x node scale 2


def test_centre_positions_project_onto_pixel_centres_whatever_the_sampling_and_lens():
    """position_center is the hit of the ray K describes: with jittered samples and a thin
    lens (whose samples blur the image) it still projects back onto each pixel's centre."""
    import dataclasses

    for scene in (sphere_on_floor_scene(), orthographic_spheres_scene()):
        camera = scene.camera
        if not camera.orthographic:
            scene.camera = camera = dataclasses.replace(camera, aperture=0.3)
        result = render(scene, width=32, height=24, spp=3, sampler="jittered", passes=("position_center",))
        record = camera_record(camera, 32, 24, scene.bounds)
        world = result.passes["position_center"].astype(np.float64)
        hit = np.isfinite(world).all(axis=2)
        assert hit.sum() > 20 and (~hit).any()
        rows, columns = np.nonzero(hit)
        w2c, k = np.array(record["world_to_camera_opencv"]), np.array(record["K"])
        p = world[hit] @ w2c[:3, :3].T + w2c[:3, 3]
        if not camera.orthographic:
            p = p / p[:, 2:]
        pixel = p[:, :2] @ k[:2, :2].T + k[:2, 2]
        np.testing.assert_allclose(pixel, np.column_stack([columns + 0.5, rows + 0.5]), atol=2e-3)
