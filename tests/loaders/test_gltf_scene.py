"""glTF scene graphs, cameras and KHR_lights_punctual lights, from a small file written here.

The file (written by hand, JSON + an embedded buffer) has a cube mesh placed twice (once
under a rotated and scaled parent), a mesh with two primitives, a nested camera, a camera at
the root, and a point, a directional and a nested spot light.
"""

import base64
import json
import math

import numpy as np
import pytest
import trimesh
from scenes import assert_finite

from rtmesh.api import load_scene
from rtmesh.core.errors import SceneError
from rtmesh.lights.point_lights import DirectionalLight, PointLight, SpotLight
from rtmesh.loaders.gltf_nodes import cameras_from_gltf, lights_from_gltf, node_world_transforms, read_gltf_json
from rtmesh.loaders.importers import load_trimesh
from rtmesh.loaders.scene_file import scene_from_dict
from rtmesh.loaders.trimesh_parts import parts_from_trimesh
from rtmesh.rendering.integrator import Integrator

HALF = 0.1  # the cube's half side
SQRT_HALF = math.sqrt(0.5)


def _cube():
    """A closed axis-aligned cube of side 2 * HALF, outward winding: (positions, indices)."""
    mesh = trimesh.creation.box(extents=[2 * HALF] * 3)
    return np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.uint16).ravel()


def _quad(z):
    """A unit quad in the plane z facing +Z."""
    v = np.array([[-0.5, -0.5, z], [0.5, -0.5, z], [0.5, 0.5, z], [-0.5, 0.5, z]], np.float32)
    return v, np.array([0, 1, 2, 0, 2, 3], np.uint16)


def write_gltf(path):
    """Write the test file; returns its path."""
    blobs, views, accessors = [], [], []

    def add(array, target):
        data = array.tobytes()
        while len(data) % 4:
            data += b"\0"
        offset = sum(len(b) for b in blobs)
        blobs.append(data)
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": array.nbytes, "target": target})
        accessor = {"bufferView": len(views) - 1, "count": int(array.size if array.ndim == 1 else len(array))}
        if array.dtype == np.float32:
            accessor.update(componentType=5126, type="VEC3", min=array.min(axis=0).tolist(),
                            max=array.max(axis=0).tolist())
        else:
            accessor.update(componentType=5123, type="SCALAR")
        accessors.append(accessor)
        return len(accessors) - 1

    def primitive(vertices, indices, material):
        return {"attributes": {"POSITION": add(vertices, 34962)}, "indices": add(indices, 34963),
                "material": material}

    cube = primitive(*_cube(), 0)
    near, far = primitive(*_quad(0.0), 1), primitive(*_quad(-0.5), 0)
    buffer = b"".join(blobs)
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0, 2, 3, 4, 6, 7, 8]}],
        "nodes": [
            # parent: rotated 90 degrees about +Y and scaled 2; its child sits at +X 1
            {"name": "parent", "rotation": [0.0, SQRT_HALF, 0.0, SQRT_HALF], "scale": [2.0, 2.0, 2.0],
             "children": [1, 9]},
            {"name": "child", "mesh": 0, "translation": [1.0, 0.0, 0.0]},
            {"name": "instance", "mesh": 0, "translation": [0.0, 0.0, -3.0]},
            {"name": "two_primitives", "mesh": 1, "translation": [0.0, -2.0, 0.0]},
            {"name": "front_cam_node", "camera": 0, "translation": [0.0, 0.0, 10.0]},
            {"name": "unused"},
            {"name": "rig", "translation": [0.0, 1.0, 0.0], "children": [5, 10]},
            {"name": "lamp", "translation": [0.0, 5.0, 0.0],
             "extensions": {"KHR_lights_punctual": {"light": 0}}},
            {"name": "sun", "rotation": [-SQRT_HALF, 0.0, 0.0, SQRT_HALF],
             "extensions": {"KHR_lights_punctual": {"light": 1}}},
            {"name": "spot_node", "translation": [0.0, 0.0, 1.0],
             "extensions": {"KHR_lights_punctual": {"light": 2}}},
            # looks straight down from (0, 6, 0): rotated -90 degrees about +X
            {"name": "top_cam_node", "camera": 1, "translation": [0.0, 5.0, 0.0],
             "rotation": [-SQRT_HALF, 0.0, 0.0, SQRT_HALF]},
        ],
        "cameras": [
            {"name": "front", "type": "perspective",
             "perspective": {"yfov": 0.2, "znear": 0.1, "aspectRatio": 1.0}},
            {"name": "top", "type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}},
        ],
        "meshes": [{"name": "cube", "primitives": [cube]}, {"name": "pair", "primitives": [near, far]}],
        "materials": [
            {"name": "red", "pbrMetallicRoughness": {"baseColorFactor": [1, 0, 0, 1], "metallicFactor": 0}},
            {"name": "green", "pbrMetallicRoughness": {"baseColorFactor": [0, 1, 0, 1], "metallicFactor": 0}},
        ],
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "point", "color": [1.0, 0.5, 0.25], "intensity": 100.0},
            {"type": "directional", "intensity": 3.0},
            {"type": "spot", "intensity": 20.0, "spot": {"innerConeAngle": 0.1, "outerConeAngle": 0.3}},
        ]}},
        "buffers": [{"byteLength": len(buffer),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(buffer).decode()}],
        "bufferViews": views,
        "accessors": accessors,
    }
    path.write_text(json.dumps(doc))
    return path


@pytest.fixture
def gltf_file(tmp_path):
    return write_gltf(tmp_path / "scene.gltf")


# ---------------------------------------------------------------- scene graph
def test_nested_transform_places_the_child_at_parent_times_child(gltf_file):
    parts, _ = parts_from_trimesh(load_trimesh(gltf_file), "scene")
    by_name = {p.name: p for p in parts}
    # B @ A: the child's (1, 0, 0) scaled by 2 and turned 90 degrees about +Y is (0, 0, -2),
    # and the child's own cube is scaled by 2 too
    child = by_name["child"].vertices
    np.testing.assert_allclose(child.mean(axis=0), [0.0, 0.0, -2.0], atol=1e-6)
    np.testing.assert_allclose(np.ptp(child, axis=0), [4 * HALF] * 3, atol=1e-6)
    # the same mesh instanced at the root keeps its own size and place
    instance = by_name["instance"].vertices
    np.testing.assert_allclose(instance.mean(axis=0), [0.0, 0.0, -3.0], atol=1e-6)
    np.testing.assert_allclose(np.ptp(instance, axis=0), [2 * HALF] * 3, atol=1e-6)


def test_both_primitives_of_a_mesh_become_parts_with_their_own_materials(gltf_file):
    # flat (smooth=False) keeps the parts' vertices as stored (smoothing by angle keeps the
    # materials too: tests/loaders/test_material_files.py)
    parts, materials = parts_from_trimesh(load_trimesh(gltf_file), "scene", smooth=False)
    pair = [p for p in parts if abs(p.vertices[:, 1].mean() + 2.0) < 1e-6]
    assert len(pair) == 2
    assert sorted(p.vertices[:, 2].mean() for p in pair) == pytest.approx([-0.5, 0.0])
    colours = {tuple(np.round(materials[p.material].diffuse, 3)) for p in pair}
    assert colours == {(1.0, 0.0, 0.0), (0.0, 1.0, 0.0)}
    assert len(parts) == 4  # child, instance and the two primitives


def test_node_world_transforms_compose_trs_down_the_tree(gltf_file):
    doc = read_gltf_json(gltf_file)
    world = dict(node_world_transforms(doc))
    assert 5 in world  # a child of a root is reached
    np.testing.assert_allclose(world[10][:3, 3], [0.0, 6.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(world[9][:3, 3], [2.0, 0.0, 0.0], atol=1e-12)


# ---------------------------------------------------------------- cameras and lights
def test_cameras_have_their_nodes_position_direction_and_yfov(gltf_file):
    cameras = dict(cameras_from_gltf(read_gltf_json(gltf_file)))
    front = cameras[("front_cam_node", "front")]
    np.testing.assert_allclose(front.position, [0.0, 0.0, 10.0])
    np.testing.assert_allclose(front.look_at - front.position, [0.0, 0.0, -1.0], atol=1e-12)
    assert front.fov == pytest.approx(math.degrees(0.2))
    top = cameras[("top_cam_node", "top")]
    np.testing.assert_allclose(top.position, [0.0, 6.0, 0.0], atol=1e-12)
    forward, _, up = top.frame()
    np.testing.assert_allclose(forward, [0.0, -1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(up, [0.0, 0.0, -1.0], atol=1e-12)


def test_punctual_lights_in_rtmesh_units(gltf_file):
    lights = lights_from_gltf(read_gltf_json(gltf_file))
    kinds = {type(light): light for light in lights}
    assert len(lights) == 3
    point, sun, spot = kinds[PointLight], kinds[DirectionalLight], kinds[SpotLight]
    np.testing.assert_allclose(point.position, [0.0, 5.0, 0.0])
    # candela / pi: a white Lambertian 1 m away shows radiance cd / pi, as in glTF viewers
    np.testing.assert_allclose(point.intensity, np.array([1.0, 0.5, 0.25]) * 100.0 / math.pi)
    np.testing.assert_allclose(sun.direction, [0.0, -1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(sun.irradiance, 3.0 / math.pi)
    # the spot hangs under the rotated, scaled parent: (0, 0, 1) -> (2, 0, 0), -Z -> -X
    np.testing.assert_allclose(spot.position, [2.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(spot.direction, [-1.0, 0.0, 0.0], atol=1e-12)
    assert spot.inner_angle == pytest.approx(math.degrees(0.1))
    assert spot.outer_angle == pytest.approx(math.degrees(0.3))


def test_bare_gltf_renders_from_its_first_camera_with_its_lights(gltf_file):
    scene, settings = load_scene(gltf_file, width=24, height=24, spp=1, threads=1,
                                 passes=("depth", "object_id"))
    np.testing.assert_allclose(scene.camera.position, [0.0, 0.0, 10.0])
    assert len(scene.lights) == 3  # the file's, not the default rig
    result = Integrator(scene, settings).render()
    assert_finite(result)
    # the centre ray meets the nested child cube's front face at z = -2 + 2 * HALF
    centre = result.passes["depth"][11:13, 11:13, 0]
    np.testing.assert_allclose(centre, 10.0 - (-2.0 + 2 * HALF), rtol=1e-6)
    child = scene.object_names.index("child")
    assert (result.passes["object_id"][11:13, 11:13, 0] == child).all()


def test_scene_file_picks_a_camera_by_name_and_applies_the_object_transform(gltf_file):
    doc = {"objects": [{"mesh": str(gltf_file), "translate": [0.0, 0.0, 1.0]}],
           "camera": {"from_file": "top", "aperture": 0.0}}
    scene, _ = scene_from_dict(doc)
    np.testing.assert_allclose(scene.camera.position, [0.0, 6.0, 1.0], atol=1e-12)
    assert len(scene.lights) == 3
    doc["objects"][0]["import_lights"] = False
    scene, _ = scene_from_dict(doc)
    assert len(scene.lights) == 3 and all(isinstance(light, DirectionalLight) for light in scene.lights)


def test_a_file_placed_by_instances_brings_its_lights_to_every_placement(gltf_file, tmp_path):
    """A lamp file placed three times by ``instances`` lights the scene from three places
    (its lights at each row, after the object's transform); its cameras stay the object's."""
    rows = np.tile(np.eye(4), (3, 1, 1))
    rows[:, 0, 3] = [-10.0, 0.0, 10.0]
    np.save(tmp_path / "rows.npy", rows)
    doc = {"objects": [{"mesh": str(gltf_file), "translate": [0.0, 0.0, 1.0], "instances": "rows.npy"}],
           "camera": {"from_file": "top", "aperture": 0.0}}
    scene, _ = scene_from_dict(doc, base_dir=str(tmp_path))
    np.testing.assert_allclose(scene.camera.position, [0.0, 6.0, 1.0], atol=1e-12)
    points = sorted(tuple(light.position) for light in scene.lights if isinstance(light, PointLight))
    np.testing.assert_allclose(points, [(-10.0, 5.0, 1.0), (0.0, 5.0, 1.0), (10.0, 5.0, 1.0)], atol=1e-12)
    assert len(scene.lights) == 9


@pytest.mark.parametrize("import_lights", [True, False])
def test_lights_not_imported_are_not_read_or_warned_about(gltf_file, caplog, import_lights):
    doc = json.loads(gltf_file.read_text())
    lamp = next(node for node in doc["nodes"] if node["name"] == "lamp")
    lamp["scale"] = [0.0, 0.0, 0.0]  # a hidden light: a warning when its lights are read
    gltf_file.write_text(json.dumps(doc))
    with caplog.at_level("WARNING"):
        scene, _ = scene_from_dict({"objects": [{"mesh": str(gltf_file), "import_lights": import_lights}]})
    warned = [r for r in caplog.records if "light node 'lamp'" in r.getMessage()]
    assert len(warned) == int(import_lights)
    assert sum(isinstance(light, SpotLight) for light in scene.lights) == int(import_lights)


@pytest.mark.parametrize("camera, message", [
    ({"from_file": "nope"}, "no camera named 'nope'.*available: 'front_cam_node', 'top_cam_node'"),
    ({"from_file": "top", "fov": 30}, "camera.fov: does not apply with from_file"),
])
def test_bad_file_camera_is_a_one_line_error(gltf_file, camera, message):
    with pytest.raises(SceneError, match=message):
        scene_from_dict({"objects": [{"mesh": str(gltf_file)}], "camera": camera}, source="s.toml")


def test_import_lights_on_a_primitive_is_an_error():
    with pytest.raises(SceneError, match=r"objects\[0\]\.import_lights: does not apply to a primitive"):
        scene_from_dict({"objects": [{"primitive": "box", "import_lights": True}]}, source="s.toml")


def test_malformed_camera_is_a_one_line_error_naming_the_file(tmp_path, capsys):
    path = write_gltf(tmp_path / "bad.gltf")
    doc = json.loads(path.read_text())
    del doc["cameras"][1]["perspective"]["yfov"]  # required by the glTF schema
    path.write_text(json.dumps(doc))
    from rtmesh.cli import main
    out = tmp_path / "o.png"
    assert main(["render", str(path), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert "bad.gltf: malformed glTF camera or light" in err and err.count("\n") == 1
    assert not out.exists()
