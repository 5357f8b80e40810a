"""Hostile textures, projector images, scene files and glTF lights through the command line:
each is one error line naming the file and the key, exit status 2, no image left behind and
no NumPy warning (pytest turns a RuntimeWarning into an error).  Nothing here renders: every
input is refused while the scene loads."""

import json
import logging
import math
import os

import hostile_files
import numpy as np
import OpenImageIO as oiio
import pytest

from rtmesh.cli import main
from rtmesh.core.errors import MeshError
from rtmesh.io.texture_images import load_texture
from rtmesh.loaders.gltf_nodes import _light_at, lights_from_gltf
from rtmesh.loaders.scene_file import MAX_SCENE_FILE_BYTES


def run(path, tmp_path, capsys, caplog):
    """Run the command line in-process: (status, stderr, warnings, output path)."""
    out = tmp_path / "out.png"
    with caplog.at_level(logging.WARNING):
        status = main(["render", str(path), "-o", str(out), "--width", "24", "--height", "18", "--spp", "1",
                       "--threads", "1", "-q"])
    err = capsys.readouterr().err
    warnings = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    return status, err, warnings, out


def refused(path, tmp_path, capsys, caplog):
    """The one error line of a refused input, after checking status 2, no warning, no output."""
    status, err, warnings, out = run(path, tmp_path, capsys, caplog)
    assert status == 2, err
    assert not warnings, warnings
    assert len(err.splitlines()) == 1 and err.startswith("rtmesh: error: "), err
    assert "Traceback" not in err and "internal error" not in err
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]
    return err.rstrip("\n").removeprefix("rtmesh: error: ")


def write_exr(path, pixels):
    pixels = np.asarray(pixels, dtype=np.float32)
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], "float")
    output = oiio.ImageOutput.create(str(path))
    assert output.open(str(path), spec)
    assert output.write_image(pixels)
    output.close()
    return path


def textured_obj(tmp_path, texels):
    """An OBJ cube whose MTL's map_Kd is an EXR of ``texels`` (h, w, 3): (obj, exr)."""
    exr = write_exr(tmp_path / "t.exr", texels)
    (tmp_path / "m.mtl").write_text("newmtl a\nmap_Kd t.exr\n")
    obj = tmp_path / "m.obj"
    obj.write_text("mtllib m.mtl\nusemtl a\nvt 0 0\n" + hostile_files.cube_obj())
    return obj, exr


# ---------------------------------------------------------------- 1. EXR textures


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_an_exr_texture_with_nan_or_inf_texels_is_refused(value, tmp_path, capsys, caplog):
    texels = np.full((4, 4, 3), 0.5)
    texels[1, 2, 0] = value
    obj, exr = textured_obj(tmp_path, texels)
    assert refused(obj, tmp_path, capsys, caplog) == (
        f"{exr}: texture holds NaN or infinite values (1 of its 48 values); a texture must be finite and >= 0")


def test_an_exr_texture_with_negative_texels_is_refused(tmp_path, capsys, caplog):
    obj, exr = textured_obj(tmp_path, np.full((4, 4, 3), -5.0))
    assert refused(obj, tmp_path, capsys, caplog) == (
        f"{exr}: texture holds negative values (the least -5); a texture must be finite and >= 0")


def test_an_exr_normal_map_may_hold_negative_values_and_not_nan(tmp_path, capsys, caplog):
    """A normal map (``norm``) is signed data, not a colour: its negative texels load; a
    non-finite one is refused as in any texture."""
    obj, exr = textured_obj(tmp_path, np.full((4, 4, 3), 0.5))
    normals = np.zeros((4, 4, 3))
    normals[..., 0], normals[..., 2] = -0.6, 0.8
    write_exr(tmp_path / "n.exr", normals)
    (tmp_path / "m.mtl").write_text("newmtl a\nmap_Kd t.exr\nnorm n.exr\n")
    status, err, warnings, out = run(obj, tmp_path, capsys, caplog)
    assert status == 0 and not warnings and out.exists(), err
    texture = load_texture(str(tmp_path / "n.exr"), srgb=False, signed=True)
    assert texture.pixels.min() == np.float32(-0.6)
    normals[0, 0, 1] = np.nan
    write_exr(tmp_path / "n2.exr", normals)
    with pytest.raises(MeshError, match="texture holds NaN or infinite values"):
        load_texture(str(tmp_path / "n2.exr"), srgb=False, signed=True)


def test_an_exr_texture_beyond_the_pixel_limit_is_refused(tmp_path, monkeypatch):
    from rtmesh.io import texture_images

    monkeypatch.setattr(texture_images, "MAX_TEXTURE_PIXELS", 15)
    exr = write_exr(tmp_path / "t.exr", np.full((4, 4, 3), 0.5))
    with pytest.raises(MeshError, match=r"t\.exr: texture of 4x4 pixels is larger than rtmesh reads \(15 pixels"):
        load_texture(str(exr))


def test_a_finite_exr_texture_loads_as_stored(tmp_path):
    texels = np.linspace(0.0, 1e30, 48).reshape(4, 4, 3)  # large but finite: kept
    texture = load_texture(str(write_exr(tmp_path / "t.exr", texels)))
    assert np.array_equal(texture.pixels, texels.astype(np.float32))


# ---------------------------------------------------------------- 2, 3. projector images

PROJECTOR_SCENE = """
[[objects]]
primitive = "plane"
size = [10.0, 10.0]

[[lights]]
type = "point"
position = [2.0, -2.0, 5.0]
intensity = 30.0

[[lights]]
type = "projector"
position = [0, 0, 5]
look_at = [0, 0, 0]
image = "{image}"
intensity = 10
"""


def projector_scene(tmp_path, image):
    path = tmp_path / "s.toml"
    path.write_text(PROJECTOR_SCENE.format(image=image))
    return path


def test_a_projector_exr_with_nan_is_refused_naming_the_scene_key(tmp_path, capsys, caplog):
    texels = np.ones((4, 4, 3))
    texels[0, 0] = [np.nan, np.inf, 1.0]
    exr = write_exr(tmp_path / "n.exr", texels)
    scene = projector_scene(tmp_path, "n.exr")
    assert refused(scene, tmp_path, capsys, caplog) == (
        f"{scene}: lights[1].image: {exr}: texture holds NaN or infinite values (2 of its 48 values); "
        "a texture must be finite and >= 0")


def test_a_projector_exr_with_negative_texels_is_refused(tmp_path, capsys, caplog):
    exr = write_exr(tmp_path / "t.exr", np.full((2, 2, 3), -5.0))
    scene = projector_scene(tmp_path, "t.exr")
    assert refused(scene, tmp_path, capsys, caplog) == (
        f"{scene}: lights[1].image: {exr}: texture holds negative values (the least -5); "
        "a texture must be finite and >= 0")


@pytest.mark.parametrize("name, content", [
    ("bad.png", hostile_files.corrupt_png()),
    ("text.png", b"this is not an image\n"),
    ("empty.exr", b""),
], ids=["corrupt", "text", "empty"])
def test_a_corrupt_projector_image_names_the_scene_file_and_key(name, content, tmp_path, capsys, caplog):
    (tmp_path / name).write_bytes(content)
    scene = projector_scene(tmp_path, name)
    line = refused(scene, tmp_path, capsys, caplog)
    assert line.startswith(f"{scene}: lights[1].image: {tmp_path / name}: corrupt or unreadable texture ("), line


# ---------------------------------------------------------------- 4. the scene file itself


def test_a_scene_file_linked_to_dev_zero_is_refused_at_once(tmp_path, capsys, caplog):
    link = tmp_path / "z.toml"
    os.symlink("/dev/zero", link)
    assert refused(link, tmp_path, capsys, caplog) == f"{link}: not a regular file"


def test_a_scene_file_that_is_a_fifo_is_refused_without_blocking(tmp_path, capsys, caplog):
    fifo = tmp_path / "f.toml"
    os.mkfifo(fifo)
    assert refused(fifo, tmp_path, capsys, caplog) == f"{fifo}: not a regular file"


@pytest.mark.parametrize("make, problem", [
    (lambda p: p.mkdir(), "is a directory, not a scene file"),
    (lambda p: None, "no such scene file"),
    (lambda p: os.symlink(p, p), "symbolic link loop, not a scene file"),
])
def test_a_scene_file_that_is_not_a_file_says_what_it_is(make, problem, tmp_path, capsys, caplog):
    path = tmp_path / "s.toml"
    make(path)
    assert refused(path, tmp_path, capsys, caplog) == f"{path}: {problem}"


def test_a_scene_file_beyond_the_limit_is_refused(tmp_path, capsys, caplog):
    path = tmp_path / "big.toml"
    with open(path, "wb") as f:
        f.truncate(MAX_SCENE_FILE_BYTES + 1)  # sparse: nothing of its size is written
    assert MAX_SCENE_FILE_BYTES == 16 * 1024 * 1024
    assert refused(path, tmp_path, capsys, caplog) == (
        f"{path}: scene file larger than rtmesh reads (16 MiB; scene files are small text: keep meshes "
        "and instances in files of their own)")


# ---------------------------------------------------------------- 5. glTF KHR_lights_punctual


def gltf_with_light(tmp_path, light, light_index=0):
    doc = hostile_files.gltf_cube(
        [{"name": "c", "mesh": 0},
         {"name": "lamp", "translation": [0, 3, 3], "extensions": {"KHR_lights_punctual": {"light": light_index}}}],
        [0, 1])
    doc["extensionsUsed"] = ["KHR_lights_punctual"]
    doc["extensions"] = {"KHR_lights_punctual": {"lights": [light]}}
    path = tmp_path / "m.gltf"
    path.write_text(json.dumps(doc))  # NaN as JSON's usual extension, as the files found were
    return path


BAD_LIGHTS = [
    ({"type": "point", "color": [math.nan, 1, 1]}, "color",
     "expected a list of 3 numbers (finite; 0, or magnitude 1e-18 to 1e+18) (got [nan, 1, 1])"),
    ({"type": "point", "color": [1, -1, 1]}, "color", "colour components must be >= 0 (got [1, -1, 1])"),
    ({"type": "point", "color": 1}, "color", "expected a list of 3 numbers (got 1)"),
    ({"type": "point", "intensity": 1e300}, "intensity",
     "expected a finite number (0, or magnitude 1e-18 to 1e+18) (got 1e+300)"),
    ({"type": "point", "intensity": -5}, "intensity", "expected a number >= 0 (got -5)"),
    ({"type": "point", "intensity": "bright"}, "intensity",
     "expected a finite number (0, or magnitude 1e-18 to 1e+18) (got 'bright')"),
    ({"type": "point", "color": [1e10, 1, 1], "intensity": 1e10}, "intensity",
     "color x intensity 1e+20 is more than the largest intensity a scene file takes (1e+18)"),
    ({"type": "laser"}, "type", "expected 'point', 'spot' or 'directional' (got 'laser')"),
    ({"color": [1, 1, 1]}, "type", "expected 'point', 'spot' or 'directional' (got None)"),
    ({"type": "spot", "intensity": 5, "spot": {"innerConeAngle": 2, "outerConeAngle": 0.1}}, "spot.innerConeAngle",
     "2 is more than spot.outerConeAngle 0.1 (the cone's full-intensity part must lie inside it)"),
    ({"type": "spot", "spot": {"outerConeAngle": 4}}, "spot.outerConeAngle", "expected radians from 0 to pi (got 4)"),
    ({"type": "spot", "spot": {"outerConeAngle": math.nan}}, "spot.outerConeAngle",
     "expected a finite number (0, or magnitude 1e-18 to 1e+18) (got nan)"),
]
BAD_LIGHT_IDS = ["nan-color", "negative-color", "number-color", "huge-intensity", "negative-intensity",
                 "string-intensity", "huge-product", "bogus-type", "no-type", "inner-beyond-outer",
                 "outer-beyond-pi", "nan-cone"]


@pytest.mark.parametrize("light, key, problem", BAD_LIGHTS, ids=BAD_LIGHT_IDS)
def test_a_bad_gltf_light_is_one_line_naming_the_file_and_key(light, key, problem, tmp_path, capsys, caplog):
    path = gltf_with_light(tmp_path, light)
    line = refused(path, tmp_path, capsys, caplog)
    assert line.startswith(f"{path}: ") and "KHR_lights_punctual" in line, line
    assert line.endswith(f"{key}: {problem}"), line


def test_a_bad_gltf_light_in_a_scene_file_names_the_object_too(tmp_path, capsys, caplog):
    path = gltf_with_light(tmp_path, {"type": "point", "intensity": -5})
    scene = tmp_path / "s.toml"
    scene.write_text('[[objects]]\nmesh = "m.gltf"\n')
    line = refused(scene, tmp_path, capsys, caplog)
    assert line.startswith(f"{scene}: objects[0].mesh: {path}: ") and line.endswith(
        "intensity: expected a number >= 0 (got -5)"), line


@pytest.mark.parametrize("light, key, problem", BAD_LIGHTS, ids=BAD_LIGHT_IDS)
def test_a_bad_light_entry_given_its_key_and_file_is_the_documented_line(light, key, problem):
    frame = (np.zeros(3), np.array([0.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]))
    with pytest.raises(MeshError) as caught:
        _light_at(light, frame, False, where="KHR_lights_punctual.lights[0]", source="m.gltf")
    assert str(caught.value) == f"m.gltf: KHR_lights_punctual.lights[0].{key}: {problem}"


def test_good_gltf_lights_keep_their_values(tmp_path):
    lights = [{"type": "point", "color": [1, 0.5, 0], "intensity": 2},
              {"type": "spot", "intensity": 3, "spot": {"innerConeAngle": 0.1, "outerConeAngle": 0.1}},
              {"type": "directional", "intensity": 0}]
    doc = hostile_files.gltf_cube([{"extensions": {"KHR_lights_punctual": {"light": i}}} for i in range(3)],
                                  [0, 1, 2])
    doc["extensions"] = {"KHR_lights_punctual": {"lights": lights}}
    point, spot, directional = lights_from_gltf(doc, source="m.gltf")
    assert np.allclose(point.intensity, np.array([2.0, 1.0, 0.0]) / math.pi)
    assert spot.inner_angle == spot.outer_angle == pytest.approx(math.degrees(0.1))
    assert np.allclose(spot.intensity, 3.0 / math.pi)
    assert not directional.irradiance.any()
    point, _, _ = lights_from_gltf(doc, source="m.gltf", physical=True)
    assert np.allclose(point.intensity, [2.0, 1.0, 0.0])


def test_a_light_index_beyond_the_files_lights_is_refused(tmp_path):
    doc = json.loads(gltf_with_light(tmp_path, {"type": "point"}, light_index=4).read_text())
    with pytest.raises(MeshError, match=r"m\.gltf: .*KHR_lights_punctual.*4"):
        lights_from_gltf(doc, source="m.gltf")
