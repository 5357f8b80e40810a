"""The MTL and glTF mapping tables of docs/MATERIALS.md, scene-file overrides, scene graphs."""

import numpy as np
import pytest
import trimesh
from PIL import Image
from trimesh.visual.material import PBRMaterial

from rtmesh.loaders.importers import load_mesh_scene
from rtmesh.loaders.gltf_materials import gltf_material
from rtmesh.loaders.mtl_materials import map_statement, mtl_material
from rtmesh.loaders.scene_file import scene_from_dict
from rtmesh.loaders.trimesh_parts import parts_from_trimesh

# ---------------------------------------------------------------- MTL


@pytest.mark.parametrize("statements, opacity, mode", [
    ({}, 1.0, "opaque"),
    ({"d": "0.4"}, 0.4, "blend"),  # dissolve on a non-glass model: blended transparency
    ({"tr": "0.25"}, 0.75, "blend"),  # Tr = transparency (Assimp, three.js)
    ({"tr": "1"}, 1.0, "opaque"),  # ... except Tr 1, which MeshLab writes for "opaque"
    ({"tr": "0"}, 1.0, "opaque"),
    ({"d": "1", "tr": "0.5"}, 1.0, "opaque"),  # d wins over Tr
    ({"d": "0.5", "illum": "4"}, 1.0, "opaque"),  # glass: 1 - d is refracted, not cut out
])
def test_mtl_opacity_table(statements, opacity, mode):
    m = mtl_material(statements, "m", ".")
    assert m.opacity == pytest.approx(opacity) and m.alpha_mode == mode


def test_mtl_colour_table():
    m = mtl_material({"ka": "0.1 0.2 0.3", "kd": "0.4 0.5 0.6", "ks": "0.7 0.8 0.9", "ns": "50",
                      "ke": "1 0 0", "ni": "1.7", "illum": "2"}, "m", ".")
    np.testing.assert_array_equal(m.ambient, [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(m.diffuse, [0.4, 0.5, 0.6])
    np.testing.assert_array_equal(m.specular, [0.7, 0.8, 0.9])
    np.testing.assert_array_equal(m.emission, [1, 0, 0])
    assert m.shininess == 50 and m.ior == 1.7 and not m.unlit


def test_mtl_ns_below_one_has_no_highlight():
    # MeshLab's "Ks 1 Ns 0" would add the whole specular colour to every lit point
    assert not mtl_material({"ks": "1 1 1", "ns": "0"}, "m", ".").specular.any()
    assert mtl_material({"ks": "1 1 1", "ns": "1"}, "m", ".").specular.all()


def test_mtl_illum_0_is_unlit_and_not_an_emitter():
    m = mtl_material({"kd": "0.3 0.6 0.9", "illum": "0"}, "m", ".")
    assert m.unlit and not m.emission.any()
    np.testing.assert_array_equal(m.diffuse, [0.3, 0.6, 0.9])


def test_map_statement_options_and_spaces():
    name, options = map_statement("-clamp on -bm 0.5 -o 0.1 0.2 0.3 my texture.png")
    assert name == "my texture.png"
    assert options == {"-clamp": ["on"], "-bm": ["0.5"], "-o": ["0.1", "0.2", "0.3"]}
    assert map_statement("fuze uv.jpg") == ("fuze uv.jpg", {})


def write_png(path, pixels):
    Image.fromarray(np.asarray(pixels, dtype=np.uint8)).save(path)


def test_mtl_texture_maps_are_loaded_once_and_decoded(tmp_path):
    write_png(tmp_path / "kd.png", [[[255, 128, 0]]])
    write_png(tmp_path / "d.png", [[0, 255]])
    write_png(tmp_path / "h.png", [[0, 255], [0, 255]])
    cache = {}
    m = mtl_material({"map_kd": "-clamp on kd.png", "map_ks": "kd.png", "map_d": "d.png",
                      "bump": "-bm 2 h.png", "ks": "1 1 1", "ns": "10"}, "m", str(tmp_path), cache)
    assert m.diffuse_texture.wrap == "clamp"
    np.testing.assert_allclose(m.diffuse_texture.pixels[0, 0], [1.0, ((128 / 255 + 0.055) / 1.055) ** 2.4, 0.0])
    assert m.specular_texture is not None and m.specular_texture.wrap == "repeat"
    np.testing.assert_allclose(m.opacity_texture.pixels[0, :, 0], [0.0, 1.0])  # data: not sRGB
    assert m.alpha_mode == "blend"
    # a height rising to the right (+u) tilts the normal toward -u
    normal = 2.0 * m.normal_texture.pixels[0, 0] - 1.0
    assert normal[0] < 0 and normal[2] > 0 and abs(normal[1]) < 1e-12
    assert len(cache) == 4  # kd.png once per wrap mode, d.png, h.png


def test_mtl_emission_map_multiplies_ke_or_stands_alone(tmp_path):
    write_png(tmp_path / "ke.png", [[[255, 0, 0], [0, 0, 0]]])
    with_ke = mtl_material({"ke": "2 2 2", "map_ke": "ke.png"}, "a", str(tmp_path))
    np.testing.assert_allclose(with_ke.emission, 2.0)
    np.testing.assert_allclose(with_ke.emission_texture.pixels[0], [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    alone = mtl_material({"map_ke": "ke.png"}, "b", str(tmp_path))
    np.testing.assert_allclose(alone.emission, 1.0)  # the map's own colours
    assert alone.emission_texture is not None
    plain = mtl_material({"ke": "1 1 1"}, "c", str(tmp_path))
    assert plain.emission_texture is None


# ---------------------------------------------------------------- glTF


def pbr(**values):
    return PBRMaterial(name="m", **values)


def test_gltf_materials_keep_the_metallic_roughness_model():
    m = gltf_material(pbr(baseColorFactor=[0.8, 0.6, 0.2, 1.0], metallicFactor=1.0, roughnessFactor=0.5))
    assert m.model == "metallic_roughness"
    np.testing.assert_allclose(m.base_color, [0.8, 0.6, 0.2], atol=1 / 255)  # trimesh keeps 8 bits
    assert m.metallic == 1.0 and m.perceptual_roughness == pytest.approx(0.5)
    # no Blinn-Phong terms: the BRDF reflects, nothing else does
    assert not m.diffuse.any() and not m.specular.any() and not m.mirror.any()
    d = gltf_material(pbr(baseColorFactor=[0.2, 0.4, 0.6, 1.0], metallicFactor=0.25, roughnessFactor=1.0))
    np.testing.assert_allclose(d.diffuse, np.array([0.2, 0.4, 0.6]) * 0.75, atol=1 / 255)  # for the ambient term


def test_transmissive_gltf_materials_refract_part_of_their_dielectric_diffuse_term():
    glass = gltf_material(pbr(baseColorFactor=[0.8, 0.6, 0.2, 1.0], metallicFactor=0.0, roughnessFactor=0.5),
                          {"extensions": {"KHR_materials_transmission": {"transmissionFactor": 0.75},
                                          "KHR_materials_ior": {"ior": 1.4},
                                          "KHR_materials_volume": {"attenuationColor": [0.5, 1.0, 1.0],
                                                                   "attenuationDistance": 2.0}}})
    assert glass.model == "metallic_roughness" and glass.transmission_factor == 0.75
    np.testing.assert_allclose(glass.transmission, 0.75 * np.array([0.8, 0.6, 0.2]), atol=1 / 255)
    np.testing.assert_allclose(glass.diffuse, 0.25 * np.array([0.8, 0.6, 0.2]), atol=1 / 255)
    assert glass.ior == 1.4
    np.testing.assert_allclose(glass.absorption, [np.log(2.0) / 2.0, 0.0, 0.0])
    # a metal transmits nothing: transmission is part of the dielectric term only
    metal = gltf_material(pbr(baseColorFactor=[0.8, 0.6, 0.2, 1.0], metallicFactor=1.0),
                          {"extensions": {"KHR_materials_transmission": {"transmissionFactor": 0.5}}})
    assert not metal.transmission.any()


def test_unlit_gltf_materials_show_their_base_colour_whatever_their_metalness():
    # glTF's metallicFactor defaults to 1: an unlit material must not turn black for it
    unlit = gltf_material(pbr(baseColorFactor=[0.2, 0.4, 0.6, 1.0]), {"extensions": {"KHR_materials_unlit": {}}})
    assert unlit.model == "blinn_phong" and unlit.unlit
    np.testing.assert_allclose(unlit.diffuse, [0.2, 0.4, 0.6], atol=1 / 255)


def test_gltf_alpha_modes_emission_and_unlit():
    # factors from the file's JSON at full precision (trimesh keeps 8 bits of base colour)
    m = gltf_material(pbr(), {"pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 0.3]},
                              "alphaMode": "MASK", "alphaCutoff": 0.6, "doubleSided": True,
                              "emissiveFactor": [0.5, 0.25, 0.0],
                              "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}}})
    assert m.alpha_mode == "mask" and m.alpha_cutoff == 0.6 and m.opacity == pytest.approx(0.3)
    np.testing.assert_allclose(m.emission, [2.0, 1.0, 0.0])
    assert m.double_sided
    assert gltf_material(pbr(alphaMode="BLEND")).alpha_mode == "blend"
    assert gltf_material(pbr()).alpha_mode == "opaque"
    assert gltf_material(pbr(), {"extensions": {"KHR_materials_unlit": {}}}).unlit


def test_gltf_transmission_ior_and_volume():
    ext = {"KHR_materials_transmission": {"transmissionFactor": 0.9},
           "KHR_materials_ior": {"ior": 1.33},
           "KHR_materials_volume": {"attenuationColor": [0.5, 1.0, 1.0], "attenuationDistance": 2.0}}
    m = gltf_material(pbr(metallicFactor=0.0),
                      {"pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.8, 1.0, 1.0]}, "extensions": ext})
    np.testing.assert_allclose(m.transmission, [0.9, 0.72, 0.9])
    assert m.ior == 1.33
    np.testing.assert_allclose(m.absorption, [np.log(2.0) / 2.0, 0.0, 0.0])
    np.testing.assert_allclose(m.diffuse, np.array([1.0, 0.8, 1.0]) * 0.1)


def test_gltf_file_extensions_reach_the_material(tmp_path):
    # trimesh drops material extensions; rtmesh reads them from the file's JSON by name
    box = trimesh.creation.box()
    box.visual = trimesh.visual.TextureVisuals(uv=np.zeros((len(box.vertices), 2)),
                                               material=pbr(baseColorFactor=[1, 1, 1, 1], metallicFactor=0.0))
    path = tmp_path / "glass.gltf"
    files = trimesh.Scene(box).export(file_type="gltf")
    import json
    doc = json.loads(files["model.gltf"])
    doc["materials"][0]["extensions"] = {"KHR_materials_transmission": {"transmissionFactor": 1.0}}
    # (trimesh 4 exports an 8-bit base colour divided by 255 twice: write the factor here)
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [1.0, 1.0, 1.0, 1.0]
    files["model.gltf"] = json.dumps(doc).encode()
    for name, data in files.items():
        (tmp_path / ("glass.gltf" if name == "model.gltf" else name)).write_bytes(data)
    scene = load_mesh_scene(path)
    assert scene.materials.transmission.max() == 1.0


# ---------------------------------------------------------------- scene files and graphs


def test_scene_file_material_overrides_an_imported_one_by_name(tmp_path):
    (tmp_path / "m.mtl").write_text("newmtl paint\nKd 1 0 0\nnewmtl other\nKd 0 1 0\n")
    (tmp_path / "t.obj").write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
                                    "usemtl paint\nf 1 2 3\nusemtl other\nf 2 4 3\n")
    doc = {"materials": {"paint": {"diffuse": [0.0, 0.0, 1.0]}},
           "objects": [{"mesh": "t.obj"}]}
    scene, _ = scene_from_dict(doc, base_dir=str(tmp_path))
    used = {scene.materials.materials[i].name: scene.materials.diffuse[i]
            for i in np.unique(scene.material_id)}
    np.testing.assert_array_equal(used["paint"], [0, 0, 1])  # the scene file's
    np.testing.assert_array_equal(used["other"], [0, 1, 0])  # the file's own


def test_nested_nodes_instances_and_primitives_are_placed_from_a_glb(tmp_path):
    box = trimesh.creation.box(extents=[1, 1, 1])
    small = trimesh.creation.box(extents=[0.5, 0.5, 0.5])
    scene = trimesh.Scene()
    parent = trimesh.transformations.translation_matrix([10, 0, 0]) @ trimesh.transformations.scale_matrix(2.0)
    scene.add_geometry(box, geom_name="box", node_name="parent", transform=parent)
    # a child of the scaled parent: its offset is scaled by 2, then moved by 10
    scene.add_geometry(small, geom_name="small", node_name="child", parent_node_name="parent",
                       transform=trimesh.transformations.translation_matrix([0, 3, 0]))
    # the same mesh instanced again elsewhere
    scene.add_geometry(box, geom_name="box", node_name="instance",
                       transform=trimesh.transformations.translation_matrix([0, 0, -5]))
    path = tmp_path / "nested.glb"
    path.write_bytes(scene.export(file_type="glb"))
    loaded = load_mesh_scene(path)
    boxes = {}
    for i, name in enumerate(loaded.object_names):
        used = loaded.vertices[np.unique(loaded.faces[loaded.object_id == i])]
        boxes[name] = (used.min(axis=0), used.max(axis=0))
    assert len(boxes) == 3
    lows = sorted((tuple(np.round(lo, 6)), tuple(np.round(hi, 6))) for lo, hi in boxes.values())
    assert lows == sorted([((9.0, -1.0, -1.0), (11.0, 1.0, 1.0)),      # parent: 2x box at x=10
                           ((9.5, 5.5, -0.5), (10.5, 6.5, 0.5)),       # child: 2 * 3 up, 2x size
                           ((-0.5, -0.5, -5.5), (0.5, 0.5, -4.5))])    # instance


def test_smoothing_by_angle_keeps_the_material_and_carries_uvs():
    # trimesh's smooth_shaded copy drops the visual: rtmesh maps UVs through the split
    box = trimesh.creation.box()
    box = trimesh.Trimesh(box.vertices, box.faces, process=False)
    uv = box.vertices[:, :2] + 0.5
    box.visual = trimesh.visual.TextureVisuals(uv=uv, material=pbr(baseColorFactor=[0.2, 0.4, 0.6, 1.0],
                                                                   metallicFactor=0.0))
    (part, *_), materials = parts_from_trimesh(box, smooth=None)
    assert len(part.vertices) > len(box.vertices)  # split at the 90 degree creases
    np.testing.assert_allclose(materials[0].diffuse, np.round(np.array([0.2, 0.4, 0.6]) * 255) / 255)
    np.testing.assert_allclose(part.uv, part.vertices[:, :2] + 0.5)


def test_gltf_sampler_wrap_modes_reach_the_textures():
    # glTF keeps wrapS / wrapT in samplers, which trimesh drops: read from the JSON
    from rtmesh.loaders.gltf_materials import OPTIONS_KEY, gltf_json_materials

    doc = {"samplers": [{"wrapS": 33071, "wrapT": 33648}, {}],
           "textures": [{"source": 0, "sampler": 0}, {"source": 0, "sampler": 1}, {"source": 0}],
           "materials": [{"name": "a", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}},
                          "normalTexture": {"index": 1}},
                         {"name": "b", "pbrMetallicRoughness": {"baseColorTexture": {"index": 2}}},
                         {"name": "c", "pbrMetallicRoughness": {"baseColorTexture": {"index": 9}}}]}
    materials = gltf_json_materials(doc)
    assert {role: o["wrap"] for role, o in materials["a"][OPTIONS_KEY].items()} == {
        "baseColorTexture": ("clamp", "mirror"), "normalTexture": ("repeat", "repeat")}
    assert materials["b"][OPTIONS_KEY]["baseColorTexture"]["wrap"] == ("repeat", "repeat")
    assert materials["c"][OPTIONS_KEY]["baseColorTexture"]["wrap"] == ("repeat", "repeat")  # bad index
    image = Image.new("RGB", (2, 2), (200, 100, 50))
    m = gltf_material(pbr(baseColorTexture=image, normalTexture=image), materials["a"])
    assert (m.diffuse_texture.wrap_u, m.diffuse_texture.wrap_v) == ("clamp", "mirror")
    assert (m.normal_texture.wrap_u, m.normal_texture.wrap_v) == ("repeat", "repeat")


def test_gltf_emissive_texture_multiplies_the_factor():
    from rtmesh.loaders.gltf_materials import OPTIONS_KEY, gltf_json_materials

    image = Image.new("RGB", (2, 1), (255, 0, 0))
    image.putpixel((1, 0), (0, 0, 0))
    doc = {"samplers": [{"wrapS": 33071, "wrapT": 33071}], "textures": [{"source": 0, "sampler": 0}],
           "materials": [{"name": "lamp", "emissiveFactor": [1.0, 0.5, 1.0], "emissiveTexture": {"index": 0}}]}
    json_material = gltf_json_materials(doc)["lamp"]
    assert json_material[OPTIONS_KEY]["emissiveTexture"]["wrap"] == ("clamp", "clamp")
    m = gltf_material(pbr(emissiveTexture=image), json_material)
    np.testing.assert_allclose(m.emission, [1.0, 0.5, 1.0])
    np.testing.assert_allclose(m.emission_texture.pixels[0], [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])  # sRGB decoded
    assert m.emission_texture.wrap_u == "clamp"
    # the spec's default factor is 0: the texture alone emits nothing
    assert gltf_material(pbr(emissiveTexture=image)).emission_texture is None


def test_an_emissive_texture_survives_a_glb_round_trip(tmp_path):
    mesh = trimesh.creation.box()
    uv = np.random.default_rng(0).random((len(mesh.vertices), 2))
    image = Image.new("RGB", (4, 4), (255, 255, 255))
    material = PBRMaterial(name="glow", emissiveFactor=[1.0, 1.0, 1.0], emissiveTexture=image)
    mesh.visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    path = tmp_path / "glow.glb"
    mesh.export(path)
    scene = load_mesh_scene(str(path))
    glowing = [m for m in scene.materials.materials if m.emission_texture is not None]
    assert len(glowing) == 1 and np.allclose(glowing[0].emission, 1.0)
