"""glTF's KHR layer extensions (specular, clearcoat, sheen, anisotropy, iridescence) from a
file: read into the layered model's parameters with their textures, bad values refused in
one line, ignored with one warning under Whitted, rendered under path."""

import base64
import io
import json
import logging

import numpy as np
import pytest
import trimesh
from PIL import Image
from trimesh.visual.material import PBRMaterial

from rtmesh.core.errors import MeshError
from rtmesh.loaders.importers import load_mesh_scene
from rtmesh.materials import gltf_layered, models

EXTENSIONS = {
    "KHR_materials_specular": {"specularFactor": 0.6, "specularColorFactor": [1.0, 0.5, 0.25],
                               "specularTexture": {"index": 0}},
    "KHR_materials_clearcoat": {"clearcoatFactor": 0.9, "clearcoatRoughnessFactor": 0.2,
                                "clearcoatNormalTexture": {"index": 0}},
    "KHR_materials_sheen": {"sheenColorFactor": [0.5, 0.25, 1.0], "sheenRoughnessFactor": 0.3,
                            "sheenColorTexture": {"index": 0}},
    "KHR_materials_anisotropy": {"anisotropyStrength": 0.7, "anisotropyRotation": 0.5},
    "KHR_materials_iridescence": {"iridescenceFactor": 0.8, "iridescenceIor": 1.4,
                                  "iridescenceThicknessMinimum": 150.0, "iridescenceThicknessMaximum": 500.0,
                                  "iridescenceThicknessTexture": {"index": 0}},
}


def _png_uri(pixels):
    buffer = io.BytesIO()
    Image.fromarray(np.asarray(pixels, dtype=np.uint8)).save(buffer, format="PNG")
    return "data:image/png;base64," + base64.b64encode(buffer.getvalue()).decode()


def write_layered_gltf(tmp_path, extensions, name="layered.gltf"):
    """A UV sphere with one glTF material using ``extensions``; texture 0 is a 2x2 PNG of
    (128, 64, 255, 200) texels (data URI)."""
    sphere = trimesh.creation.uv_sphere(radius=1.0, count=[16, 16])
    uv = np.stack([sphere.vertices[:, 0] * 0.5 + 0.5, sphere.vertices[:, 2] * 0.5 + 0.5], axis=1)
    sphere.visual = trimesh.visual.TextureVisuals(uv=uv, material=PBRMaterial(
        name="paint", baseColorFactor=[255, 255, 255, 255], metallicFactor=0.0, roughnessFactor=0.5))
    files = trimesh.Scene(sphere).export(file_type="gltf")
    doc = json.loads(files["model.gltf"])
    doc["materials"][0]["name"] = "paint"
    doc["materials"][0]["extensions"] = extensions
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [0.8, 0.2, 0.1, 1.0]
    doc["images"] = doc.get("images", []) + [{"uri": _png_uri(np.full((2, 2, 4), (128, 64, 255, 200)))}]
    doc["textures"] = doc.get("textures", []) + [{"source": len(doc["images"]) - 1}]
    index = len(doc["textures"]) - 1
    for table in extensions.values():
        for key, value in table.items():
            if key.endswith("Texture"):
                value["index"] = index
    doc.setdefault("extensionsUsed", []).extend(extensions)
    files["model.gltf"] = json.dumps(doc).encode()
    for file, data in files.items():
        (tmp_path / (name if file == "model.gltf" else file)).write_bytes(data)
    return tmp_path / name


def _material(scene):
    (material,) = [m for m in scene.materials.materials if m.name == "paint"]
    return material


def test_every_layer_extension_is_read_with_its_textures(tmp_path):
    material = _material(load_mesh_scene(write_layered_gltf(tmp_path, json.loads(json.dumps(EXTENSIONS))),
                                         physical=True))
    assert material.model == "gltf_layered"
    layers = material.layers
    assert layers.extensions == tuple(EXTENSIONS)
    assert layers.specular == 0.6 and np.array_equal(layers.specular_colour, [1.0, 0.5, 0.25])
    assert (layers.clearcoat, layers.clearcoat_roughness) == (0.9, 0.2)
    assert np.array_equal(layers.sheen_colour, [0.5, 0.25, 1.0]) and layers.sheen_roughness == 0.3
    assert (layers.anisotropy, layers.anisotropy_rotation) == (0.7, 0.5)
    assert (layers.iridescence, layers.iridescence_ior, layers.thickness_min, layers.thickness_max) == (
        0.8, 1.4, 150.0, 500.0)
    assert set(layers.textures) == {"specularTexture", "clearcoatNormalTexture", "sheenColorTexture",
                                    "iridescenceThicknessTexture"}
    # linear data stays linear, colours are decoded from sRGB
    np.testing.assert_allclose(layers.textures["specularTexture"].pixels[0, 0, 3], 200 / 255, atol=1e-6)
    assert layers.textures["sheenColorTexture"].pixels[0, 0, 0] < 128 / 255
    # the row the path integrator reads
    tags, params, _ = models.material_rows([material])
    assert tags[0] == models.GLTF_LAYERED
    row = params[0]
    np.testing.assert_allclose(row[gltf_layered.BASE_AT:gltf_layered.BASE_AT + 3], [0.8, 0.2, 0.1])
    assert row[gltf_layered.CLEARCOAT_AT] == 0.9 and row[gltf_layered.THICKNESS_AT] == 500.0
    assert row[gltf_layered.THICKNESS_MIN_AT] == 150.0


def test_materials_without_layers_keep_the_metallic_roughness_model(tmp_path):
    material = _material(load_mesh_scene(write_layered_gltf(tmp_path, {"KHR_materials_ior": {"ior": 1.4}}),
                                         physical=True))
    assert material.model == "metallic_roughness" and material.layers is None


@pytest.mark.parametrize("extension,key,value,message", [
    ("KHR_materials_clearcoat", "clearcoatFactor", 2.0, r"clearcoatFactor 2\.0 is out of range \(expected \[0"),
    ("KHR_materials_sheen", "sheenColorFactor", "red", r"sheenColorFactor 'red' \(expected 3 numbers\)"),
    ("KHR_materials_specular", "specularColorFactor", [1.0, -1.0, 1.0], r"specularColorFactor .* out of range"),
    ("KHR_materials_iridescence", "iridescenceIor", 0.5, r"iridescenceIor 0\.5 is out of range"),
    ("KHR_materials_anisotropy", "anisotropyStrength", None, r"anisotropyStrength None \(expected a number\)"),
])
def test_bad_layer_values_are_one_line_errors_naming_them(tmp_path, extension, key, value, message):
    path = write_layered_gltf(tmp_path, {extension: {key: value}})
    with pytest.raises(MeshError, match=message) as error:
        load_mesh_scene(path, physical=True)
    text = str(error.value)
    assert "\n" not in text and "layered.gltf" in text and "paint" in text and extension in text


def test_a_missing_layer_image_is_a_one_line_error(tmp_path):
    path = write_layered_gltf(tmp_path, {"KHR_materials_clearcoat": {"clearcoatTexture": {"index": 0}}})
    doc = json.loads(path.read_text())
    doc["images"][-1] = {"uri": "data:image/png;base64,AAAA"}  # (a missing file is refused before: gltf_nodes)
    path.write_text(json.dumps(doc))
    with pytest.raises(MeshError, match=r"clearcoatTexture: image \d+ is missing or unreadable"):
        load_mesh_scene(path, physical=True)


def test_whitted_ignores_the_layers_with_one_warning_naming_them(tmp_path, caplog):
    path = write_layered_gltf(tmp_path, {"KHR_materials_clearcoat": {"clearcoatFactor": 1.0},
                                         "KHR_materials_sheen": {"sheenColorFactor": [1, 1, 1]}})
    with caplog.at_level(logging.WARNING):
        scene = load_mesh_scene(path, physical=False)
    lines = [r.getMessage() for r in caplog.records if "KHR_materials_clearcoat" in r.getMessage()]
    assert len(lines) == 1
    assert "KHR_materials_sheen" in lines[0] and "'path' only" in lines[0]
    # Whitted shades it with the metallic-roughness BRDF
    assert scene.materials.physical.all()


def _render(path, **settings):
    from rtmesh.api import load_scene, render
    scene, loaded = load_scene(path, width=32, height=32, spp=8, **settings)
    return render(scene, loaded).image


def test_layered_materials_render_under_path_with_their_textures(tmp_path):
    """Every extension at once, with textures (the clear coat's normal map, the film's
    thickness, ...): finite, and the layers change the image."""
    layered = _render(write_layered_gltf(tmp_path, json.loads(json.dumps(EXTENSIONS))))
    plain = _render(write_layered_gltf(tmp_path, {}, name="plain.gltf"))
    assert np.isfinite(layered).all() and layered.min() >= 0
    assert np.abs(layered - plain).mean() > 0.01 * plain.mean()


def test_a_clear_coat_over_a_black_base_reflects_its_fresnel_of_the_light_around(tmp_path):
    """A smooth clear coat (ior 1.5: F0 = ((1.5 - 1) / (1.5 + 1))^2 = 0.04) over a black base
    with no specular layer, under a uniform white background and nothing else: seen head on
    (the sphere's centre, within about 20 degrees of the normal, where Schlick's F stays
    within 0.0400-0.0406) the coat reflects 0.04 of the background; without the coat the
    sphere is black."""
    def black(extensions, name):
        path = write_layered_gltf(tmp_path, extensions, name)
        doc = json.loads(path.read_text())
        doc["materials"][0]["pbrMetallicRoughness"].update(baseColorFactor=[0, 0, 0, 1], metallicFactor=0.0)
        path.write_text(json.dumps(doc))
        from rtmesh.api import load_scene, render
        from rtmesh.scene.background import SolidBackground
        scene, loaded = load_scene(path, width=32, height=32, spp=256, integrator="path", seed=1)
        scene.background = SolidBackground(np.ones(3))  # as rtmesh render --background 1
        return render(scene, loaded).image
    coated = black({"KHR_materials_clearcoat": {"clearcoatFactor": 1.0}, "KHR_materials_specular": {
        "specularFactor": 0.0}}, "coated.gltf")
    bare = black({"KHR_materials_specular": {"specularFactor": 0.0}}, "bare.gltf")
    centre = (slice(12, 20), slice(12, 20))
    assert bare[centre].max() == 0.0
    assert abs(coated[centre].mean() - 0.0401) < 0.003, coated[centre].mean()


def _sphere_render(**layers):
    """One anisotropic metal sphere of the docs' sweep (UV tangents along its parallels)."""
    from benchmarks.make_khr_sweeps import sphere

    from rtmesh.materials.table import Material
    from rtmesh.rendering.integrator import Integrator
    from rtmesh.rendering.settings import RenderSettings
    from rtmesh.scene.camera import Camera
    from rtmesh.scene.model import MeshPart, Scene
    vertices, faces, normals, uv = sphere(np.zeros(3), radius=1.0, rings=24, segments=48)
    material = Material(name="metal", model="gltf_layered", base_color=(0.9, 0.9, 0.9), metallic=1.0,
                        perceptual_roughness=0.35, layers=gltf_layered.Layers(**layers))
    scene = Scene.from_parts([MeshPart(name="s", vertices=vertices, faces=faces, material=0, vertex_normals=normals,
                                       uv=uv)], [material], physical=True,
                             camera=Camera(position=(0.0, 0.0, 4.0), look_at=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0),
                                           fov=35.0))
    return Integrator(scene, RenderSettings(width=40, height=40, spp=16, integrator="path", seed=3)).render().image


def test_anisotropy_follows_its_rotation_from_the_uv_tangents():
    """Strength 0 is the isotropic metal (bit for bit whatever the rotation); a strong
    anisotropy along the parallels and one turned a quarter turn differ."""
    iso = _sphere_render()
    np.testing.assert_array_equal(iso, _sphere_render(anisotropy_rotation=1.0))
    along = _sphere_render(anisotropy=0.9)
    across = _sphere_render(anisotropy=0.9, anisotropy_rotation=np.pi / 2)
    assert np.isfinite(along).all() and np.isfinite(across).all()
    assert np.abs(along - iso).mean() > 0.02 * iso.mean()
    assert np.abs(along - across).mean() > 0.02 * iso.mean()
