"""KHR_texture_transform: offset, rotation and scale of glTF textureInfos, against a scalar
reference of the extension's matrix and against the permutations of texels it implies.

glTF UVs have their origin at the top left of the image (v down); trimesh flips v on import
and :class:`Texture` reads v upward.  The reference below works in glTF's convention and
flips at both ends, so that it checks the conversion too.  Textures here are read at texel
centres (bilinear filtering reads a centre exactly) or compared with an untransformed lookup
at the reference's UVs.
"""

import json
import logging
import math

import numpy as np
import pytest
import trimesh
from PIL import Image
from scenes import render
from trimesh.visual.material import PBRMaterial

from rtmesh.io.texture_images import IDENTITY_UV_TRANSFORM, Texture
from rtmesh.loaders.importers import load_mesh_scene
from rtmesh.loaders.gltf_materials import (OPTIONS_KEY, TEXTURE_TRANSFORM, gltf_json_materials,
                                           gltf_material, khr_texture_transform, texture_options)
from rtmesh.rendering.surface_textures import face_tangents, transformed_tangents
from rtmesh.scene.camera import Camera

# a 4 x 4 single-channel image with a distinct value per texel, row 0 at the top
GRID = np.arange(16.0).reshape(4, 4)
# UVs (Texture's convention, v up) of the texel centres of a 4 x 4 image, row by row from the top
CENTRES = np.array([[(c + 0.5) / 4, 1.0 - (r + 0.5) / 4] for r in range(4) for c in range(4)])


def spec_uv(u, v, offset=(0.0, 0.0), rotation=0.0, scale=(1.0, 1.0)):
    """Scalar reference: the UV a lookup reads for the (trimesh / Texture) UV ``(u, v)``.

    glTF UV ``(u, 1 - v)``, then ``T * R * S`` with the spec's sample-code rotation
    ``[[c, s], [-s, c]]`` (the GLSL matrix as its text reads, row by row; the direction the
    spec's worked example needs, see :func:`test_the_specs_example_shows_the_lower_left_quadrant_turned_clockwise`),
    then back to v up.
    """
    gu, gv = u, 1.0 - v
    su, sv = scale[0] * gu, scale[1] * gv
    c, s = math.cos(rotation), math.sin(rotation)
    ru, rv = c * su + s * sv, -s * su + c * sv
    return ru + offset[0], 1.0 - (rv + offset[1])


def transformed(pixels, wrap="repeat", **extension):
    """A Texture with the UV transform of a KHR_texture_transform object."""
    return Texture(pixels, wrap=wrap, transform=khr_texture_transform(extension))


def same(actual, expected):
    """Equal up to rounding (cos(pi / 2) is 6e-17, which blends a neighbour in that much)."""
    np.testing.assert_allclose(actual, expected, rtol=0.0, atol=1e-9)


def read(texture, uv=CENTRES):
    return texture.sample(np.asarray(uv, dtype=np.float64))[:, 0].reshape(4, 4)


# ---------------------------------------------------------------- the matrix


def test_identity_is_no_transform_and_costs_nothing():
    assert khr_texture_transform({}) is None
    assert khr_texture_transform({"offset": [0, 0], "rotation": 0, "scale": [1, 1]}) is None
    for texture in (Texture(GRID), Texture(GRID, transform=IDENTITY_UV_TRANSFORM)):
        assert not texture.transformed
        same(read(texture), GRID)
    same(Texture(GRID).transform, IDENTITY_UV_TRANSFORM)


@pytest.mark.parametrize("extension", [
    {"offset": [0.3, -0.2]},
    {"rotation": 0.7},
    {"rotation": -2.5},
    {"scale": [2.0, 0.5]},
    {"scale": [-1.0, 1.0]},
    {"offset": [0.25, 0.6], "rotation": 1.1, "scale": [1.5, 3.0]},
    {"offset": [0, 1], "rotation": math.pi / 2, "scale": [0.5, 0.5]},
])
def test_lookups_match_the_scalar_reference(extension):
    uv = np.random.default_rng(1).uniform(-0.5, 1.5, (200, 2))
    reference = np.array([spec_uv(u, v, **extension) for u, v in uv])
    plain = Texture(GRID)
    np.testing.assert_allclose(transformed(GRID, **extension).sample(uv), plain.sample(reference), atol=1e-9)
    # the 2 x 3 matrix itself, column by column from the images of (0, 0), (1, 0), (0, 1)
    matrix = khr_texture_transform(extension)
    origin = np.array(spec_uv(0.0, 0.0, **extension))
    np.testing.assert_allclose(matrix[:, 2], origin, atol=1e-12)
    np.testing.assert_allclose(matrix[:, 0], np.array(spec_uv(1.0, 0.0, **extension)) - origin, atol=1e-12)
    np.testing.assert_allclose(matrix[:, 1], np.array(spec_uv(0.0, 1.0, **extension)) - origin, atol=1e-12)


def test_an_offset_of_half_the_image_shifts_the_texels():
    # offset in glTF's UVs: +u reads further right, +v further down the image
    same(read(transformed(GRID, offset=[0.5, 0.0])), np.roll(GRID, -2, axis=1))
    same(read(transformed(GRID, offset=[0.0, 0.5])), np.roll(GRID, -2, axis=0))
    same(read(transformed(GRID, offset=[0.25, 0.0])), np.roll(GRID, -1, axis=1))


def test_a_quarter_turn_turns_the_image_clockwise():
    # "rotate the UVs counter-clockwise ... equivalent to a similar rotation of the image
    # clockwise": about the top-left corner with repeat, so the quadrants of the image
    # come back rotated clockwise as a whole
    quadrants = np.array([[1.0, 2.0], [3.0, 4.0]]).repeat(2, axis=0).repeat(2, axis=1)
    shown = read(transformed(quadrants, rotation=math.pi / 2))
    same(shown, np.rot90(quadrants, k=-1))
    same(shown[::2, ::2], [[3.0, 1.0], [4.0, 2.0]])
    same(read(transformed(quadrants, rotation=-math.pi / 2)), np.rot90(quadrants, k=1))
    same(read(transformed(GRID, rotation=math.pi / 2)), np.rot90(GRID, k=-1))


def test_scale_two_repeats_the_image_twice():
    quadrants = np.array([[1.0, 2.0], [3.0, 4.0]]).repeat(2, axis=0).repeat(2, axis=1)
    # a 2 x 2 image twice across and down: the 4 x 4 grid of its texels, tiled
    small = np.array([[1.0, 2.0], [3.0, 4.0]])
    same(read(transformed(small, scale=[2.0, 2.0])), np.tile(small, (2, 2)))
    same(read(transformed(quadrants, scale=[2.0, 1.0]))[0], [1.0, 2.0, 1.0, 2.0])


def test_the_specs_example_shows_the_lower_left_quadrant_turned_clockwise():
    # "This example utilizes only the lower left quadrant of the source image, rotated
    # clockwise 90 degrees": offset [0, 1], rotation pi / 2, scale [0.5, 0.5]
    texture = transformed(GRID, offset=[0, 1], rotation=1.57079632679, scale=[0.5, 0.5])
    half = np.array([[(c + 0.5) / 2, 1.0 - (r + 0.5) / 2] for r in range(2) for c in range(2)])
    shown = texture.sample(half)[:, 0].reshape(2, 2)
    np.testing.assert_allclose(shown, np.rot90(GRID[2:, :2], k=-1), atol=1e-9)
    # and "inverts the T axis, effectively defining a bottom-left origin"
    same(read(transformed(GRID, offset=[0, 1], scale=[1, -1])), GRID[::-1])


def test_wrap_modes_apply_to_the_transformed_uvs():
    # u scaled by 3 takes the texel centres of columns 0..3 to those of columns 1, 4, 7, 10,
    # beyond the image but for the first: each wrap mode folds them back its own way
    for wrap, columns in (("clamp", [1, 3, 3, 3]), ("repeat", [1, 0, 3, 2]), ("mirror", [1, 3, 0, 2])):
        same(read(transformed(GRID, wrap=wrap, scale=[3.0, 1.0])), GRID[:, columns])


def test_normal_map_frames_follow_the_transform():
    # the tangent frame of transformed UVs is the frame of the UVs taken through the transform
    rng = np.random.default_rng(2)
    vertices, uv = rng.normal(size=(3, 3)), rng.uniform(size=(3, 2))
    faces = np.array([[0, 1, 2]])
    for extension in ({"rotation": math.pi / 2}, {"offset": [0.2, 0.1], "rotation": 0.4, "scale": [2.0, -0.5]}):
        matrix = khr_texture_transform(extension)
        moved = uv @ matrix[:, :2].T + matrix[:, 2]
        np.testing.assert_allclose(transformed_tangents(face_tangents(vertices, faces, uv), matrix),
                                   face_tangents(vertices, faces, moved), rtol=1e-9, atol=1e-12)
    # a quad in the xy plane with uv = xy: a quarter turn puts the image's +u along -y
    flat = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    tb = face_tangents(flat, faces, flat[:, :2])
    turned = transformed_tangents(tb, khr_texture_transform({"rotation": math.pi / 2}))
    np.testing.assert_allclose(turned, [[0, -1, 0, 1, 0, 0]], atol=1e-12)


def test_malformed_transforms_are_value_errors():
    for extension in ({"offset": [1]}, {"rotation": "x"}, {"scale": [1, float("nan")]}, {"offset": [True, 0]}, []):
        with pytest.raises(ValueError):
            khr_texture_transform(extension)
    with pytest.raises(ValueError, match="UV transform"):
        Texture(GRID, transform=np.eye(2))


# ---------------------------------------------------------------- the file's JSON


def _doc(*materials):
    return {"samplers": [{"wrapS": 33071, "wrapT": 10497}], "textures": [{"source": 0, "sampler": 0}],
            "images": [{"uri": "checker.png"}], "materials": list(materials)}


def _info(**extension):
    return {"index": 0, "extensions": {TEXTURE_TRANSFORM: extension}}


def test_options_carry_wrap_and_transform_to_every_texture_role():
    roles = {"normalTexture": _info(rotation=1.0), "occlusionTexture": _info(scale=[2, 2]),
             "emissiveTexture": _info(offset=[0.5, 0]),
             "pbrMetallicRoughness": {"baseColorTexture": _info(scale=[3, 1]),
                                      "metallicRoughnessTexture": {"index": 0}}}
    material = gltf_json_materials(_doc({"name": "a", **roles}))["a"]
    assert set(material[OPTIONS_KEY]) == {"baseColorTexture", "metallicRoughnessTexture", "normalTexture",
                                          "occlusionTexture", "emissiveTexture"}
    for role, options in material[OPTIONS_KEY].items():
        assert options["wrap"] == ("clamp", "repeat")
    np.testing.assert_allclose(texture_options(material, "baseColorTexture")["transform"],
                               khr_texture_transform({"scale": [3, 1]}))
    assert texture_options(material, "metallicRoughnessTexture") == {"wrap": ("clamp", "repeat"), "transform": None}
    # no JSON, or no such texture: glTF's defaults
    assert texture_options(None, "baseColorTexture") == {"wrap": "repeat", "transform": None}
    assert texture_options({}, "normalTexture") == {"wrap": "repeat", "transform": None}
    # a fresh dict each time: a caller may add to it
    texture_options(material, "normalTexture")["name"] = "x"
    assert "name" not in texture_options(material, "normalTexture")


def test_gltf_material_textures_carry_the_transform():
    material = gltf_json_materials(_doc({"name": "a", "normalTexture": _info(rotation=1.0),
                                         "emissiveFactor": [1, 1, 1], "emissiveTexture": _info(offset=[0.5, 0]),
                                         "pbrMetallicRoughness": {"baseColorTexture": _info(scale=[3, 1])}}))["a"]
    image = Image.new("RGB", (2, 2), (200, 100, 50))
    m = gltf_material(PBRMaterial(name="a", baseColorTexture=image, normalTexture=image, emissiveTexture=image),
                      material)
    for texture, extension in ((m.diffuse_texture, {"scale": [3, 1]}), (m.normal_texture, {"rotation": 1.0}),
                               (m.emission_texture, {"offset": [0.5, 0]})):
        assert texture.transformed and (texture.wrap_u, texture.wrap_v) == ("clamp", "repeat")
        np.testing.assert_allclose(texture.transform, khr_texture_transform(extension))
    plain = gltf_material(PBRMaterial(name="b", baseColorTexture=image))
    assert not plain.diffuse_texture.transformed


def test_other_texture_coordinate_sets_are_one_warning_and_set_0(caplog):
    doc = _doc({"name": "a", "pbrMetallicRoughness": {"baseColorTexture": _info(texCoord=1, scale=[2, 2])},
                "normalTexture": {"index": 0, "texCoord": 2}},
               {"name": "b", "emissiveTexture": _info(texCoord=1)},
               # the extension's texCoord overrides the textureInfo's: set 0, no warning
               {"name": "c", "emissiveTexture": {"index": 0, "texCoord": 1, "extensions": {
                   TEXTURE_TRANSFORM: {"texCoord": 0}}}})
    with caplog.at_level(logging.WARNING, logger="rtmesh"):
        materials = gltf_json_materials(doc, "model.gltf")
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    text = warnings[0].getMessage()
    assert text.startswith("model.gltf: texture coordinate sets other than 0 are not read")
    assert "material 'a' baseColorTexture (set 1)" in text and "material 'a' normalTexture (set 2)" in text
    assert "material 'b' emissiveTexture (set 1)" in text and "'c'" not in text
    # the transform still applies, to set 0
    np.testing.assert_allclose(texture_options(materials["a"], "baseColorTexture")["transform"],
                               khr_texture_transform({"scale": [2, 2]}))


def test_a_malformed_transform_is_one_warning_and_ignored(caplog):
    doc = _doc({"name": "a", "pbrMetallicRoughness": {"baseColorTexture": _info(offset=[1, "x"])}},
               {"name": "b", "pbrMetallicRoughness": {"baseColorTexture": _info(rotation=None)}})
    with caplog.at_level(logging.WARNING, logger="rtmesh"):
        materials = gltf_json_materials(doc, "model.gltf")
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    assert "model.gltf: malformed KHR_texture_transform ignored" in warnings[0].getMessage()
    assert "material 'a' baseColorTexture: offset [1, 'x']" in warnings[0].getMessage()
    assert texture_options(materials["a"], "baseColorTexture")["transform"] is None


# ---------------------------------------------------------------- a file, rendered


def _write_checker_gltf(tmp_path, extension, required=False):
    """A unit quad in the xy plane (uv = xy), base colour a 4 x 4 image of four coloured
    2 x 2 blocks, written by trimesh and given ``extension`` in its JSON."""
    blocks = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [255, 255, 255]]], np.uint8)
    image = Image.fromarray(blocks.repeat(2, axis=0).repeat(2, axis=1))
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    quad = trimesh.Trimesh(vertices, [[0, 1, 2], [0, 2, 3]], process=False)
    quad.visual = trimesh.visual.TextureVisuals(uv=vertices[:, :2], material=PBRMaterial(
        name="checker", baseColorTexture=image, baseColorFactor=[1.0, 1.0, 1.0, 1.0], metallicFactor=0.0))
    files = trimesh.Scene(quad).export(file_type="gltf")
    doc = json.loads(files["model.gltf"])
    info = doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]
    info["extensions"] = {TEXTURE_TRANSFORM: extension}
    doc["extensionsUsed"] = sorted(set(doc.get("extensionsUsed", [])) | {TEXTURE_TRANSFORM})
    if required:
        doc["extensionsRequired"] = [TEXTURE_TRANSFORM]
    files["model.gltf"] = json.dumps(doc).encode()
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    return tmp_path / "model.gltf", np.asarray(image, np.float64) / 255.0  # pure colours: linear = sRGB


def _albedo(path):
    """The 4 x 4 albedo pass of the quad seen straight on: one pixel per texel centre."""
    camera = Camera(position=[0.5, 0.5, 2.0], look_at=[0.5, 0.5, 0.0], up=[0.0, 1.0, 0.0],
                    projection="orthographic", ortho_height=1.0)
    scene = load_mesh_scene(path, camera=camera)
    return render(scene, width=4, height=4, passes=("albedo",)).passes["albedo"].reshape(4, 4, 3)


@pytest.mark.parametrize("required", [False, True])
def test_a_rotated_texture_renders_turned_clockwise(tmp_path, required):
    path, image = _write_checker_gltf(tmp_path, {"rotation": math.pi / 2}, required=required)
    np.testing.assert_allclose(_albedo(path), np.rot90(image, k=-1), atol=1e-4)


def test_an_identity_transform_renders_the_image_as_is(tmp_path):
    path, image = _write_checker_gltf(tmp_path, {"offset": [0, 0]})
    np.testing.assert_allclose(_albedo(path), image, atol=1e-4)
