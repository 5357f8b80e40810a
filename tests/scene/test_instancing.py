"""Meshes placed many times: built once, placed by Embree instances (rtmesh.scene.instances)."""

import dataclasses
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
from scenes import block_means, reusing_glb, scattered_transforms
import wavefront


def placed_scene(count=50, subdivisions=2, textured=False):
    """A floor and ``count`` placements of one smooth sphere; ``textured``: the sphere and
    the floor have texture coordinates, the sphere a checker texture, and a flat-shaded
    cylinder (64 triangles) is placed ``count`` times too (a second prototype)."""
    from rtmesh.io.texture_images import Texture

    sphere = trimesh.creation.icosphere(subdivisions)
    floor = trimesh.creation.box((12, 0.2, 12))
    materials = [Material(diffuse=np.array([0.6, 0.6, 0.6])), Material(diffuse=np.array([0.8, 0.3, 0.2]))]
    uv = floor_uv = None
    if textured:
        uv = sphere.vertices[:, :2] * 0.5 + 0.5
        floor_uv = floor.vertices[:, [0, 2]] / 12 + 0.5
        checker = (np.indices((8, 8)).sum(0) % 2)[..., None] * np.array([0.7, 0.2, 0.1]) + 0.15
        materials[1] = Material(diffuse=np.array([1.0, 1.0, 1.0]), diffuse_texture=Texture(checker))
        materials.append(Material(diffuse=np.array([0.2, 0.5, 0.8])))
    prototype = MeshPart("ball", sphere.vertices.copy(), sphere.faces.copy(), 1, sphere.vertex_normals.copy(), uv=uv)
    placements = [Placement(prototype, scattered_transforms(count), [f"ball {j}" for j in range(count)])]
    if textured:
        can = trimesh.creation.cylinder(0.5, 1.0, sections=16)
        placements.append(Placement(MeshPart("can", can.vertices.copy(), can.faces.copy(), 2,
                                             uv=can.vertices[:, :2] * 0.5 + 0.5),
                                    scattered_transforms(count, seed=5), [f"can {j}" for j in range(count)]))
    return Scene.from_parts([MeshPart("floor", floor.vertices, floor.faces, 0, uv=floor_uv)], materials,
                            physical=True, placements=placements)


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


def test_whitted_traces_instances_through_the_kernel():
    scene = placed_scene(count=5)
    scene.ambient = np.array([0.3, 0.3, 0.3])
    settings = RenderSettings(width=48, height=36, spp=4, integrator="whitted",
                              passes=("object_id", "instance_id", "ao"), ao_samples=4)
    placed = Integrator(scene, settings)
    assert placed.instances is not None and placed.path_stage is not None and placed.direct_stage is None
    result = placed.render()
    copies = Integrator(instances.flattened(scene), settings).render()
    a, b = block_means(result.image), block_means(copies.image)
    # the same scene to float32 rounding of the triangles, as under path
    assert np.abs(a - b).max() <= 0.01 * b.mean()
    # every placement is an object: the id passes tell the copies apart
    seen = set(np.unique(result.passes["instance_id"]).tolist()) - {-1.0, 0.0}
    assert len(seen) >= 2 and seen <= set(range(1, 6))
    assert np.mean(result.passes["object_id"] == copies.passes["object_id"]) > 0.99
    # the ambient-occlusion pass and rays see the placements as the copies
    ao, ao_copies = block_means(result.passes["ao"]), block_means(copies.passes["ao"])
    assert np.abs(ao - ao_copies).max() <= 0.01 * ao_copies.mean() and ao_copies.min() < 0.95


def test_whitted_through_the_wavefront_renders_the_copies(caplog, monkeypatch):
    from rtmesh.rendering import integrator as integrator_module

    monkeypatch.setattr(integrator_module, "REFERENCE_STAGE", wavefront.attach)
    scene = placed_scene(count=5)
    settings = RenderSettings(width=32, height=24, spp=2, integrator="whitted", passes=("object_id", "instance_id"))
    with caplog.at_level(logging.INFO, logger="rtmesh.rendering.built_scene"):
        it = Integrator(scene, settings)
    assert it.instances is None and "flattened into 5 copies" in caplog.text
    expected = Integrator(instances.flattened(scene), settings).render()
    result = it.render()
    assert np.array_equal(result.image, expected.image)
    assert np.array_equal(result.passes["object_id"], expected.passes["object_id"])


# every pass the path integrator offers
PATH_PASSES = ("depth", "normal", "albedo", "position", "uv", "alpha", "ao", "variance", "spp", "object_id",
               "material_id", "instance_id", "depth_center", "position_center", "normal_center", "motion",
               "emission", "direct_diffuse", "direct_glossy", "direct_transmission", "indirect_diffuse",
               "indirect_glossy", "indirect_transmission")
# the passes read from the camera rays' first hits: equal to the copies' but for the
# rounding of the hit (the copies' float32 world triangles against the prototype's float32
# triangle under a float64 transform: Embree's distances and barycentrics differ in their
# last float32 bits), which moves the point, the interpolated normal and UV and the
# bilinear texture lookup by as much; measured largest differences (hits 4-30 units away):
# depth 1.5e-5, position 1.0e-5, albedo 7.3e-6, uv 3.5e-6, depth_center 3.8e-6,
# position_center 5.0e-6, normal_center 1.4e-5; the normal pass is the path kernel's shading
# normal, 1.5e-3 (27 of 768 pixels above 1e-4): under a non-uniform scale a placement's
# interpolated normal is carried to the world, while a copy's vertex normals are carried and
# normalised one by one before they are interpolated
ROUNDED = {"depth": 1e-4, "position": 5e-5, "normal": 3e-3, "albedo": 1e-4, "uv": 5e-5, "depth_center": 1e-4,
           "position_center": 5e-5, "normal_center": 1e-4}
# what the sampled paths add up (the image's parts and its variance): as the image
SAMPLED = ("variance", "emission", "direct_diffuse", "direct_glossy", "direct_transmission", "indirect_diffuse",
           "indirect_glossy", "indirect_transmission")


def test_passes_come_out_of_the_instanced_scene():
    scene = placed_scene(count=12, textured=True)
    settings = RenderSettings(width=32, height=24, spp=2, integrator="path", passes=PATH_PASSES)
    it = Integrator(scene, settings)
    # no copies: the faces and Embree's triangles are the floor's and the prototypes' once
    assert it.instances is not None and len(it.scene.faces) == len(it.accel.triangles) == 12 + 320 + 64
    placed = it.render()
    copies = Integrator(instances.flattened(scene), settings).render()
    # the image is the path kernel's, with or without passes
    alone = Integrator(scene, RenderSettings(width=32, height=24, spp=2, integrator="path")).render()
    assert np.array_equal(placed.image, alone.image)
    assert set(placed.passes) == set(PATH_PASSES)
    for name in PATH_PASSES:
        a, b = placed.passes[name], copies.passes[name]
        if name in ROUNDED:
            assert np.array_equal(np.isfinite(a), np.isfinite(b)), name
            assert np.allclose(a, b, rtol=0, atol=ROUNDED[name], equal_nan=True), name
        elif name in SAMPLED:
            assert np.abs(block_means(a) - block_means(b)).max() <= 0.02 * max(b.mean(), 0.05), name
        else:
            # ids, coverage, ao, spp, motion: bit-identical
            assert np.array_equal(a, b), name
    ids = placed.passes["instance_id"]
    # copies told apart: balls 1..12 and cans 13..24 are all objects of their own
    assert len(set(np.unique(ids).tolist()) & set(range(1, 25))) >= 6
    assert set(np.unique(placed.passes["material_id"]).tolist()) == {-1.0, 0.0, 1.0, 2.0}


def test_the_denoiser_and_a_transparent_background_keep_instances():
    from rtmesh.scene.background import TransparentBackground

    scene = placed_scene(count=8, textured=True)
    scene.background = TransparentBackground()
    settings = RenderSettings(width=32, height=24, spp=2, integrator="path", denoise=True)
    assert instances.unsupported(scene, settings) == []
    it = Integrator(scene, settings)
    assert it.instances is not None
    placed = it.render()
    copies = Integrator(instances.flattened(scene), settings).render()
    assert np.array_equal(placed.alpha, copies.alpha) and (placed.alpha == 0).any()
    # the guides are the copies' to rounding; the denoised images alike
    assert np.abs(block_means(placed.image) - block_means(copies.image)).max() <= 0.02 * copies.image.mean()
    assert np.abs(block_means(placed.noisy) - block_means(copies.noisy)).max() <= 0.02 * copies.noisy.mean()


def test_the_batched_queries_report_the_placement():
    from rtmesh.geometry.accel import Accel

    scene = placed_scene(count=12, textured=True)
    inst = scene.instances
    placed = Accel(scene.vertices, scene.faces, instances=inst)
    flat_scene = instances.flattened(scene)
    flat = Accel(flat_scene.vertices, flat_scene.faces)
    rng = np.random.default_rng(1)
    origins = rng.uniform(-6, 6, (4000, 3)) * [1, 0, 1] + [0, 6, 0]
    directions = rng.normal(size=(4000, 3)) - [0, 2, 0]
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    a, b = placed.intersect(origins, directions), flat.intersect(origins, directions)
    assert b.instance is None and a.instance.dtype == np.int32
    hit = b.prim >= 0
    on_placement = a.instance >= 0
    assert on_placement.sum() > 200 and (a.prim[~on_placement] < inst.first_face).all()
    # the placement and the face of its prototype hit, as the copies number them
    objects = inst.hit_objects(scene.object_id, a.prim, a.instance)
    same = (a.prim >= 0) == hit
    assert same.mean() > 0.999
    rows = np.flatnonzero(same & hit)
    assert (objects[rows] == flat_scene.object_id[b.prim[rows]]).mean() > 0.999
    assert np.array_equal(scene.material_id[a.prim[rows]], flat_scene.material_id[b.prim[rows]])
    np.testing.assert_allclose(a.t[rows], b.t[rows], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(placed.hit_points(a, same & hit), flat.hit_points(b, same & hit), atol=1e-5)
    t_max = np.full(len(origins), 3.0)
    assert (placed.occluded(origins, directions, t_max) == flat.occluded(origins, directions, t_max)).mean() > 0.999


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


def test_a_gltf_reusing_a_mesh_renders_as_its_copies(tmp_path, monkeypatch):
    from rtmesh import api

    path = reusing_glb(tmp_path / "reuse.glb")
    options = dict(width=64, height=48, spp=8, caustics="off", passes=("albedo", "normal", "instance_id"))
    scene, settings = api.load_scene(path, **options)
    assert settings.integrator == "path" and len(scene.instances) == 50
    assert len(scene.faces) == 12 + 1280
    placed = api.render(scene, settings)
    # the same file with every node its own copy (the mesh below the instancing size)
    monkeypatch.setattr(instances, "MIN_TRIANGLES", 10 ** 9)
    copies, _ = api.load_scene(path, **options)
    assert copies.instances is None and len(copies.faces) == 12 + 50 * 1280
    expected = api.render(copies, settings)
    a, b = block_means(placed.image), block_means(expected.image)
    # measured: largest block difference 0.4 % of the block (float32 rounding of the
    # placed triangles moves hits by ulps; the sampled paths stay the same)
    assert (np.abs(a - b) <= 0.01 * np.maximum(b, 0.05)).all()
    # the passes through the placements: the textured albedo to rounding (measured 2.6e-5),
    # the normals as the kernel shades them (measured 3.2e-4: a placement's interpolated
    # normal is carried to the world, a copy's vertex normals are carried and normalised
    # one by one before they are interpolated), every pixel's placement the same node (the
    # loader numbers the objects of the two files in another order)
    for name, tolerance in (("albedo", 2e-4), ("normal", 1e-3)):
        assert np.abs(placed.passes[name] - expected.passes[name]).max() < tolerance, name
    names = [np.array(["-"] + result_scene.object_names)[result.passes["instance_id"].astype(int) + 1]
             for result, result_scene in ((placed, scene), (expected, copies))]
    assert np.array_equal(*names) and len(np.unique(names[0])) > 10


def test_gpu_instancing_places_one_mesh(tmp_path):
    from rtmesh import api

    path = reusing_glb(tmp_path / "gpu.glb", count=20, instancing=True)
    scene, _ = api.load_scene(path, width=32, height=24)
    assert len(scene.instances) == 20 and len(scene.faces) == 12 + 1280
    assert sorted(scene.object_names[1:]) == sorted(f"ball0[{k}]" for k in range(20))


@pytest.mark.parametrize("column, value, why", [(0, np.nan, "not finite"), (2, 0.0, "singular")])
def test_a_bad_gpu_instance_is_one_line(tmp_path, capsys, caplog, column, value, why):
    import gltf_codecs
    from rtmesh.cli import main

    path = reusing_glb(tmp_path / "one.glb", count=1)
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


@pytest.mark.parametrize("integrator", ["path", "whitted"])
def test_glass_prototypes_stay_placed_and_refract_as_their_copies(integrator):
    """Glass spheres placed twelve times (mirroring placements among them: the probes and
    the refraction read a placed face's side in the world), the camera inside one of them."""
    scene = placed_scene(count=12)
    glass = scene.materials.materials[1]
    glass.transmission, glass.ior, glass.diffuse = np.full(3, 0.9), 1.5, np.full(3, 0.05)
    scene.materials = type(scene.materials)(scene.materials.materials)
    assert instances.unsupported(scene, RenderSettings(integrator=integrator)) == []
    settings = RenderSettings(width=48, height=36, spp=8, integrator=integrator)
    refracts = (scene.materials.transmission > 0).any(axis=1)
    # outside every sphere, then at the centre of the first (a mirroring placement)
    for camera, inside in ((scene.camera, False),
                           (dataclasses.replace(scene.camera, position=scene.instances.transforms[0, :3, 3]), True)):
        view = dataclasses.replace(scene, camera=camera)
        it = Integrator(view, settings)
        assert it.instances is not None
        copies_it = Integrator(instances.flattened(view), settings)
        stack = it.camera_media(refracts)
        assert np.array_equal(stack, copies_it.camera_media(refracts)) and (stack[0] == 1) == inside
        # paths through glass part ways at the last bits of a hit (placed triangles against
        # copies), so the two renders differ by noise: measured 0.4-2.1 % block RMSE against
        # 3.3-5.5 % from seed to seed at 8 spp (0.5 % against 0.8 % at 256 spp, inside)
        a, b = block_means(it.render().image), block_means(copies_it.render().image)
        other_seed = block_means(Integrator(instances.flattened(view), dataclasses.replace(settings, seed=1))
                                 .render().image)
        assert _block_rmse(a, b) <= 0.6 * _block_rmse(other_seed, b)


def _block_rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)) / b.mean())


def test_moving_placements_beyond_the_memory_limit_stop_before_their_copies():
    from rtmesh.core.errors import ResourceError
    from rtmesh.geometry.motion import Motion
    from rtmesh.rendering import memory

    scene = placed_scene(count=50, subdivisions=4)
    scene.motions = {k: Motion(translate=np.array([0.1, 0.0, 0.0])) for k in range(1, 51)}
    scene.camera = dataclasses.replace(scene.camera, shutter=(0.0, 1.0))
    with memory.loading_limit(1_000_000), pytest.raises(ResourceError, match="50 placements flattened into copies "
                                                        "of 256000 triangles in all .instances are not traced with "
                                                        "moving objects. would need about"):
        Integrator(scene, RenderSettings(width=16, height=12, spp=1, integrator="path"))


@pytest.mark.parametrize("integrator", ["path", "whitted"])
def test_emissive_prototypes_stay_placed_and_light_as_their_copies(integrator):
    """Glowing spheres placed twelve times (mirroring and non-uniform scales among the
    placements) light the floor as their copies do: every placed face is a light of its own
    in the world, and a path that meets one weighs it by that light's density (MIS)."""
    scene = placed_scene(count=12)
    scene.materials.materials[1].emission = np.full(3, 2.0)
    scene.materials = type(scene.materials)(scene.materials.materials)
    assert instances.unsupported(scene, RenderSettings(integrator=integrator)) == []
    # (16 spp: the light choice's alias tables differ in the last bits of the areas, the
    # placed triangles' against the copies'; at 8 spp one block of 24 took another face in
    # a sample, 2.7 %; at 16 spp 0.06-0.08 %, at 64 spp 0.02-0.1 %)
    settings = RenderSettings(width=48, height=36, spp=16, integrator=integrator)
    it = Integrator(scene, settings)
    assert it.instances is not None
    placed = it.render()
    lights = it.path_stage.lights
    assert (lights.rows[:, 0] == 5).sum() == 12 * 320 and (lights.placement_light >= 0).all()
    copies = Integrator(instances.flattened(scene), settings).render()
    a, b = block_means(placed.image), block_means(copies.image)
    assert (np.abs(a - b) <= 0.01 * np.maximum(b, 0.05)).all()


@pytest.mark.parametrize("integrator", ["path", "whitted"])
@pytest.mark.parametrize("mover", [0, 3])
def test_moving_objects_beside_placements_render_as_the_copies(integrator, mover):
    """A moving floor under placed spheres (the placements stay placed, traced in the static
    scene), or one moving placement (copied into the world, the other eleven placed): the
    image and the ids are those of every placement copied."""
    from rtmesh.geometry.motion import Motion

    scene = placed_scene(count=12)
    scene.motions = {mover: Motion(translate=np.array([0.8, 0.0, 0.3]))}
    scene.camera = dataclasses.replace(scene.camera, shutter=(0.0, 1.0))
    settings = RenderSettings(width=48, height=36, spp=8, integrator=integrator,
                              passes=("object_id", "instance_id", "depth"))
    it = Integrator(scene, settings)
    assert it.motion is not None and it.instances is not None
    assert len(it.instances) == (12 if mover == 0 else 11)
    placed = it.render()
    copies = Integrator(instances.flattened(scene), settings).render()
    a, b = block_means(placed.image), block_means(copies.image)
    assert (np.abs(a - b) <= 0.01 * np.maximum(b, 0.05)).all()
    # ids bit for bit where both see the same object (float32 rounding may move an edge)
    same = placed.passes["object_id"] == copies.passes["object_id"]
    assert same.mean() > 0.99 and np.isin(mover, placed.passes["object_id"])
    assert np.array_equal(placed.passes["instance_id"][same], copies.passes["instance_id"][same])


@pytest.mark.parametrize("integrator", ["path", "whitted"])
def test_normal_maps_bend_placed_meshes_as_their_copies(integrator):
    """A normal-mapped prototype: its faces' UV tangents carried to the world by each
    placement (mirroring ones among them), as the copies' own tangents are."""
    from rtmesh.io.texture_images import Texture

    unmapped = placed_scene(count=12, textured=True)
    scene = placed_scene(count=12, textured=True)
    # ridges along u: a map that tilts the normal one way, then the other
    ridges = np.zeros((8, 8, 3))
    ridges[:, :, 0] = np.where(np.arange(8) % 4 < 2, 0.85, 0.15)[None, :]
    ridges[:, :, 2] = 0.9
    scene.materials.materials[1].normal_texture = Texture(ridges)
    scene.materials = type(scene.materials)(scene.materials.materials)
    assert instances.unsupported(scene, RenderSettings(integrator=integrator)) == []
    settings = RenderSettings(width=48, height=36, spp=4, integrator=integrator, passes=("normal",))
    it = Integrator(scene, settings)
    assert it.instances is not None and it.textures.tangents is not None
    placed = it.render()
    copies = Integrator(instances.flattened(scene), settings).render()
    a, b = block_means(placed.image), block_means(copies.image)
    assert (np.abs(a - b) <= 0.01 * np.maximum(b, 0.05)).all()
    # the map bends the normals: far more than the placements and the copies differ
    bent = np.abs(placed.passes["normal"] - Integrator(unmapped, settings).render().passes["normal"]).max()
    assert bent > 0.1
    assert np.abs(placed.passes["normal"] - copies.passes["normal"]).max() < 3e-3
    # the centre-ray normals (the general path's surface records) likewise
    centre = dataclasses.replace(settings, passes=("normal_center",))
    np.testing.assert_allclose(Integrator(scene, centre).render().passes["normal_center"],
                               Integrator(instances.flattened(scene), centre).render().passes["normal_center"],
                               atol=3e-3)


@pytest.mark.parametrize("integrator", ["path", "whitted"])
@pytest.mark.parametrize("mode", ["mask", "blend"])
def test_cutout_prototypes_stay_placed_and_render_as_their_copies(integrator, mode):
    """A prototype whose checker texture cuts holes in it (alpha mask) or fades it (blend):
    camera, bounce and shadow rays pass its layers at the placement's world-space point."""
    from rtmesh.io.texture_images import Texture

    scene = placed_scene(count=12, textured=True)
    holes = np.ones((8, 8, 4))
    holes[..., 3] = np.where(np.indices((8, 8)).sum(0) % 2, 0.1, 0.9)
    ball = scene.materials.materials[1]
    ball.diffuse_texture, ball.alpha_mode, ball.alpha_cutoff = Texture(holes), mode, 0.5
    scene.materials = type(scene.materials)(scene.materials.materials)
    assert scene.materials.any_cutout and instances.unsupported(scene, RenderSettings(integrator=integrator)) == []
    settings = RenderSettings(width=48, height=36, spp=8, integrator=integrator, passes=("alpha",))
    it = Integrator(scene, settings)
    assert it.instances is not None and it.cutouts is not None
    placed = it.render()
    copies = Integrator(instances.flattened(scene), settings).render()
    a, b = block_means(placed.image), block_means(copies.image)
    # the same layers and coins, but the texture's alpha crosses the cutoff all over the
    # ball, where float32 rounding of the placed triangles can decide a layer the other way
    # and the path then goes on differently: measured under path (mask), 22 of 1728
    # pixels, 8x8 blocks 0.27 % relative RMSE apart (2.5 % the largest block) against
    # 4.1 % (10 %) from one seed to another; under whitted 0.02 % at most
    assert np.sqrt(((a - b) ** 2).mean()) <= 0.01 * b.mean()
    if integrator == "whitted":
        assert (np.abs(a - b) <= 0.01 * np.maximum(b, 0.05)).all()
    assert np.abs(block_means(placed.passes["alpha"]) - block_means(copies.passes["alpha"])).max() <= 0.01
    # the holes are seen: the alpha pass has pixels between covered and empty
    assert ((placed.passes["alpha"] > 0.05) & (placed.passes["alpha"] < 0.95)).any()


def test_photon_passes_trace_placed_mirrors_as_their_copies():
    """Caustics from placed mirror balls under a point light: the photons meet the
    prototype's faces at each placement's world-space point, as the copies'."""
    from rtmesh.lights.point_lights import PointLight

    scene = placed_scene(count=8)
    scene.materials.materials[1] = Material(model="conductor", mirror=np.array([1.0, 0.78, 0.34]))
    scene.materials = type(scene.materials)(scene.materials.materials)
    scene.lights = [PointLight(np.array([0.0, 6.0, 2.0]), 40.0)]
    settings = RenderSettings(width=48, height=36, spp=8, integrator="path", caustics="photons", photons=20_000)
    it = Integrator(scene, settings)
    assert it.instances is not None and it.path_stage.caustics.enabled
    placed = it.render()
    flat = Integrator(instances.flattened(scene), settings)
    assert flat.path_stage.caustics.enabled
    # the photons' aim: a sphere around each placement's box of the mirror, a little wider
    # than the one around the copies' corners (measured 8 %), holding them all
    aim, exact = it.path_stage.caustics.aim, flat.path_stage.caustics.aim
    assert exact[3] <= aim[3] <= 1.25 * exact[3] and np.linalg.norm(aim[:3] - exact[:3]) + exact[3] <= aim[3] * 1.001
    copies = flat.render()
    assert placed.stats.photons_stored > 0
    # measured: 8x8 block means 0.12 % relative RMSE apart (the copies against another seed:
    # 5.4 %)
    a, b = block_means(placed.image), block_means(copies.image)
    assert np.sqrt(((a - b) ** 2).mean()) <= 0.01 * b.mean()


def test_a_view_with_a_transparent_background_keeps_instances():
    from rtmesh.scene.background import TransparentBackground

    scene = placed_scene(count=5)
    settings = RenderSettings(width=16, height=12, spp=1, integrator="path")
    it = Integrator(scene, settings)
    assert it.instances is not None
    view = it.with_view(it.scene.camera, background=TransparentBackground())
    assert view.instances is not None
    scene.background = TransparentBackground()
    expected = Integrator(instances.flattened(scene), settings).render()
    assert np.array_equal(view.render().alpha, expected.alpha)


def test_annotations_of_placements_are_their_copies():
    from rtmesh.batch.coco import image_annotations, scene_instances
    from rtmesh.scene.camera_json import camera_record

    scene = placed_scene(count=8, textured=True)
    settings = RenderSettings(width=32, height=24, spp=1, integrator="path")

    def annotations(s):
        it = Integrator(s, settings)
        record = camera_record(s.camera, settings.width, settings.height, s.bounds)
        return it, {a["object_name"]: a for a in image_annotations(it, record, scene_instances(s))}

    it, placed = annotations(scene)
    assert it.instances is not None
    _, copies = annotations(instances.flattened(scene))
    assert placed.keys() == copies.keys() and len(placed) > 4
    for name, a in placed.items():
        b = copies[name]
        # the visible masks from the centre rays' placements, the amodal ones from the
        # placement's copy traced alone (the copy flattened makes)
        for key in ("bbox", "area", "segmentation", "bbox_amodal", "area_amodal", "visible_fraction"):
            assert a[key] == b[key], (name, key)
        np.testing.assert_allclose(a["keypoints_3d_box"], b["keypoints_3d_box"], atol=1e-6)
        np.testing.assert_allclose(a["pose"], b["pose"], atol=1e-9)
