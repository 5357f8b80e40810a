"""Meshes placed many times: built once, placed by Embree instances (rtmesh.scene.instances)."""

import logging

import numpy as np
import pytest
import trimesh

from rtmesh.core.errors import MeshError
from rtmesh.materials.table import Material
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene import instances
from rtmesh.scene.model import MeshPart, Placement, Scene
from scenes import block_means, scattered_transforms


def placed_scene(count=50, subdivisions=2):
    """A floor and ``count`` placements of one smooth sphere."""
    sphere = trimesh.creation.icosphere(subdivisions)
    floor = trimesh.creation.box((12, 0.2, 12))
    materials = [Material(diffuse=np.array([0.6, 0.6, 0.6])), Material(diffuse=np.array([0.8, 0.3, 0.2]))]
    prototype = MeshPart("ball", sphere.vertices.copy(), sphere.faces.copy(), 1, sphere.vertex_normals.copy())
    return Scene.from_parts([MeshPart("floor", floor.vertices, floor.faces, 0)], materials, physical=True,
                            placements=[Placement(prototype, scattered_transforms(count),
                                                  [f"ball {j}" for j in range(count)])])


def test_a_placed_mesh_is_kept_once():
    scene = placed_scene()
    inst = scene.instances
    assert len(inst) == 50
    assert len(scene.faces) == 12 + 320  # the floor, the sphere once
    assert len(scene.object_names) == 51 and scene.object_names[1:3] == ["ball 0", "ball 1"]
    flat = instances.flattened(scene)
    assert flat.instances is None and len(flat.faces) == 12 + 50 * 320
    np.testing.assert_allclose(scene.bounds, flat.bounds, rtol=0, atol=1e-12)
    assert set(np.unique(flat.object_id)) == set(range(51))


def test_instances_render_as_their_copies_under_path():
    scene = placed_scene()
    settings = RenderSettings(width=64, height=48, spp=8, integrator="path")
    placed = Integrator(scene, settings)
    assert placed.instances is not None
    image = placed.render().image
    copies = Integrator(instances.flattened(scene), settings).render().image
    a, b = block_means(image), block_means(copies)
    # the same scene to float32 rounding of the triangles (the copies' world-space corners
    # against the prototype's model-space ones under Embree's float32 transform): measured,
    # the largest block difference 0.28 % of the block (0.5 % of the image mean); 1 % is
    # the requirement
    assert np.abs(a - b).max() <= 0.01 * b.mean()
    assert (np.abs(a - b) <= 0.01 * np.maximum(b, 0.05)).all()


def test_whitted_and_passes_render_the_copies(caplog):
    scene = placed_scene(count=5)
    for settings in (RenderSettings(width=32, height=24, spp=2, integrator="whitted"),
                     RenderSettings(width=32, height=24, spp=2, integrator="path",
                                    passes=("object_id", "instance_id"))):
        with caplog.at_level(logging.INFO, logger="rtmesh.rendering.integrator"):
            it = Integrator(scene, settings)
        assert it.instances is None and "flattened into 5 copies" in caplog.text
        expected = Integrator(instances.flattened(scene), settings).render()
        result = it.render()
        assert np.array_equal(result.image, expected.image)
        if settings.passes:
            assert np.array_equal(result.passes["object_id"], expected.passes["object_id"])
            # every placement is an object: the id passes tell the copies apart
            seen = set(np.unique(result.passes["instance_id"]).tolist()) - {-1.0, 0.0}
            assert len(seen) >= 2 and seen <= set(range(1, 6))


@pytest.mark.parametrize("bad, why", [(np.nan, "non-finite"), (0.0, "singular")])
def test_a_bad_placement_is_one_line(bad, why):
    transforms = scattered_transforms(3)
    transforms[1, 1, :3] = bad  # NaN, or a zero row: singular
    sphere = trimesh.creation.icosphere(1)
    with pytest.raises(MeshError) as error:
        Scene.from_parts([], placements=[Placement(MeshPart("ball", sphere.vertices, sphere.faces), transforms,
                                                   ["a", "b", "c"])], source="file.glb")
    message = str(error.value)
    assert "\n" not in message and message.startswith("file.glb: instance 'b'") and why in message


def _reusing_glb(path, count=50, subdivisions=3, instancing=False):
    """A GLB whose ``count`` nodes place one textured, smooth sphere (1280 triangles) over a
    floor; with ``instancing`` one node places it by EXT_mesh_gpu_instancing instead."""
    from PIL import Image

    ball = trimesh.creation.icosphere(subdivisions, radius=0.6)
    uv = ball.vertices[:, :2] * (0.5 / 0.6) + 0.5
    checker = (np.indices((8, 8)).sum(0) % 2)[..., None] * np.array([200, 60, 30]) + 40
    ball.visual = trimesh.visual.TextureVisuals(uv=uv, material=trimesh.visual.material.PBRMaterial(
        baseColorTexture=Image.fromarray(checker.astype(np.uint8)), metallicFactor=0.0, roughnessFactor=0.5))
    floor = trimesh.creation.box(extents=[14, 0.2, 14])
    floor.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(
        baseColorFactor=[0.3, 0.6, 0.9, 1.0], metallicFactor=0.0, roughnessFactor=0.7))
    scene = trimesh.Scene()
    scene.add_geometry(floor, node_name="floor", transform=trimesh.transformations.translation_matrix([0, -0.1, 0]))
    transforms = scattered_transforms(count)
    scene.add_geometry(ball, node_name="ball0", geom_name="ball", transform=np.eye(4) if instancing else transforms[0])
    for j in range(1, 1 if instancing else count):
        scene.graph.update(frame_to=f"ball{j}", frame_from=scene.graph.base_frame, geometry="ball",
                           matrix=transforms[j])  # the same mesh again
    data = trimesh.exchange.gltf.export_glb(scene, include_normals=True)
    if instancing:
        import gltf_codecs

        doc, _ = gltf_codecs.split_glb(data)
        node = next(k for k, n in enumerate(doc["nodes"]) if n.get("name") == "ball0")
        quaternions = np.array([trimesh.transformations.quaternion_from_matrix(t) for t in transforms])
        data = gltf_codecs.gpu_instanced_glb(data, node, transforms[:, :3, 3], quaternions[:, [1, 2, 3, 0]],
                                             np.full((count, 3), 0.5))
    path.write_bytes(data)
    return path


def test_a_gltf_reusing_a_mesh_renders_as_its_copies(tmp_path, monkeypatch):
    from rtmesh import api

    path = _reusing_glb(tmp_path / "reuse.glb")
    options = dict(width=64, height=48, spp=8, caustics="off")
    scene, settings = api.load_scene(path, **options)
    assert settings.integrator == "path" and len(scene.instances) == 50
    assert len(scene.faces) == 12 + 1280
    image = api.render(scene, settings).image
    # the same file with every node its own copy (the mesh below the instancing size)
    monkeypatch.setattr(instances, "MIN_TRIANGLES", 10 ** 9)
    copies, _ = api.load_scene(path, **options)
    assert copies.instances is None and len(copies.faces) == 12 + 50 * 1280
    expected = api.render(copies, settings).image
    a, b = block_means(image), block_means(expected)
    # measured: largest block difference 0.4 % of the block (float32 rounding of the
    # placed triangles moves hits by ulps; the sampled paths stay the same)
    assert (np.abs(a - b) <= 0.01 * np.maximum(b, 0.05)).all()


def test_gpu_instancing_places_one_mesh(tmp_path):
    from rtmesh import api

    path = _reusing_glb(tmp_path / "gpu.glb", count=20, instancing=True)
    scene, _ = api.load_scene(path, width=32, height=24)
    assert len(scene.instances) == 20 and len(scene.faces) == 12 + 1280
    assert sorted(scene.object_names[1:]) == sorted(f"ball0[{k}]" for k in range(20))


@pytest.mark.parametrize("column, value, why", [(0, np.nan, "not finite"), (2, 0.0, "singular")])
def test_a_bad_gpu_instance_is_one_line(tmp_path, capsys, caplog, column, value, why):
    import gltf_codecs
    from rtmesh.cli import main

    path = _reusing_glb(tmp_path / "one.glb", count=1)
    doc, _ = gltf_codecs.split_glb(path.read_bytes())
    node = next(k for k, n in enumerate(doc["nodes"]) if n.get("name") == "ball0")
    translations = np.zeros((4, 3))
    scales = np.full((4, 3), 0.5)
    (translations if column == 0 else scales)[2, 0] = value
    bad = tmp_path / "bad.glb"
    bad.write_bytes(gltf_codecs.gpu_instanced_glb(path.read_bytes(), node, translations,
                                                  np.tile([0.0, 0.0, 0.0, 1.0], (4, 1)), scales))
    out = tmp_path / "out.png"
    status = main(["render", str(bad), "-o", str(out), "--width", "24", "--height", "18", "-q"])
    err = capsys.readouterr().err
    assert status == 2 and not out.exists()
    assert err.count("\n") == 1 and str(bad) in err and f"nodes[{node}]" in err and why in err


def test_instanced_images_do_not_depend_on_the_thread_count():
    scene = placed_scene(count=20)
    images = [Integrator(scene, RenderSettings(width=40, height=30, spp=4, integrator="path", threads=threads))
              .render().image for threads in (1, 2)]
    assert np.array_equal(*images)


@pytest.mark.parametrize("change, why", [
    (lambda m: m[0].__setattr__("alpha_mode", "blend"), "alpha cut-outs"),
    (lambda m: m[1].__setattr__("emission", np.full(3, 2.0)), "emissive prototypes")])
def test_what_the_kernel_cannot_trace_through_instances_renders_the_copies(change, why):
    scene = placed_scene(count=5)
    change(scene.materials.materials)
    scene.materials = type(scene.materials)(scene.materials.materials)
    assert why in instances.unsupported(scene, RenderSettings(integrator="path"))
    assert Integrator(scene, RenderSettings(width=16, height=12, spp=1, integrator="path")).instances is None


def test_a_view_with_a_transparent_background_is_refused_on_instances():
    from rtmesh.scene.background import TransparentBackground

    it = Integrator(placed_scene(count=5), RenderSettings(width=16, height=12, spp=1, integrator="path"))
    assert it.instances is not None
    with pytest.raises(ValueError, match="transparent background"):
        it.with_view(it.scene.camera, background=TransparentBackground())
    assert it.with_view(it.scene.camera).instances is not None
