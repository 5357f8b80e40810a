"""Hostile USD files: one line naming the file, the prim and the attribute, no traceback, no
NumPy warning, no runaway memory (rtmesh/loaders/usd_*.py)."""

import logging
import os
import warnings

import numpy as np
import pytest

from rtmesh.api import load_scene
from rtmesh.cli import main
from rtmesh.core.errors import MeshError
from rtmesh.loaders.usd_files import read_usd

HEADER = '#usda 1.0\n(\n    upAxis = "Y"\n    metersPerUnit = 1\n)\n'
QUAD = '''
    def Mesh "Quad" (prepend apiSchemas = ["MaterialBindingAPI"])
    {{
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        {points}
        texCoord2f[] primvars:st = [(0,0),(1,0),(1,1),(0,1)] (interpolation = "faceVarying")
        {extra}
    }}
'''
POINTS = "point3f[] points = [(-1, 0, 1), (1, 0, 1), (1, 0, -1), (-1, 0, -1)]"


def _stage(tmp_path, body, header=HEADER):
    path = tmp_path / "m.usda"
    path.write_text(header + 'def Xform "World"\n{\n' + body + "\n}\n")
    return str(path)


def _block(prim):
    """``def X "N" { a \n b }`` written out as usda wants it, a line each."""
    return prim.replace("{ ", "\n{\n").replace(" }", "\n}\n")


def _quad(points=POINTS, extra=""):
    return QUAD.format(points=points, extra=extra)


def _refused(path, message):
    """read_usd refuses ``path`` with exactly ``path: message``, no NumPy warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(MeshError) as info:
            read_usd(path)
    assert str(info.value) == f"{path}: {message}"
    assert "\n" not in str(info.value)


def _material(surface="", texture=""):
    return _quad(extra="rel material:binding = </World/Looks/M>") + f'''
    def Scope "Looks"
    {{
        def Material "M"
        {{
            token outputs:surface.connect = </World/Looks/M/PBR.outputs:surface>
            def Shader "PBR"
            {{
                uniform token info:id = "UsdPreviewSurface"
                {surface}
                token outputs:surface
            }}
            def Shader "Tex"
            {{
                uniform token info:id = "UsdUVTexture"
                {texture}
                float3 outputs:rgb
            }}
        }}
    }}
'''


# ------------------------------------------------------------ 1. point instancer cycles

def _instancer(prototype, extra=""):
    return f'''
    def PointInstancer "PI"
    {{
        rel prototypes = [<{prototype}>]
        int[] protoIndices = [0, 0, 0]
        point3f[] positions = [(0,0,0), (1,0,0), (2,0,0)]
        {extra}
        def Scope "Protos"
        {{
            {_quad()}
        }}
    }}
'''


@pytest.mark.parametrize("prototype", ["/World/PI", "/World"])
def test_an_instancer_that_is_its_own_prototype_is_refused_at_once(tmp_path, prototype):
    # (before, the walk recursed into the prototype until memory ran out)
    path = _stage(tmp_path, _instancer(prototype))
    _refused(path, f"/World/PI.prototypes: prototype {prototype} holds the point instancer /World/PI "
                   "(a cycle of instancing)")


def test_the_cli_refuses_an_instancer_cycle_in_one_line(tmp_path, monkeypatch, capsys):
    _stage(tmp_path, _instancer("/World"))
    monkeypatch.chdir(tmp_path)
    code = main(["render", "m.usda", "-o", "o.exr", "-q", "--threads", "1", "--width", "16", "--height", "12",
                 "--spp", "1"])
    assert code == 2
    err = capsys.readouterr().err
    assert err == ("rtmesh: error: m.usda: /World/PI.prototypes: prototype /World holds the point instancer "
                   "/World/PI (a cycle of instancing)\n")
    assert not os.path.exists(tmp_path / "o.exr")


def test_invisible_instances_are_left_out_not_refused(tmp_path):
    path = _stage(tmp_path, _instancer("/World/PI/Protos/Quad", "int64[] invisibleIds = [1]"))
    content = read_usd(path)
    assert sum(len(p.vertices) for p in content.parts) == 2 * 4


def test_instancer_positions_shorter_than_proto_indices_are_refused(tmp_path, capfd):
    path = _stage(tmp_path, _instancer("/World/PI/Protos/Quad").replace(
        "[(0,0,0), (1,0,0), (2,0,0)]", "[(0,0,0)]"))
    _refused(path, "/World/PI.positions: 1 positions but 3 protoIndices")
    assert "Warning" not in capfd.readouterr().err


# ------------------------------------------------------------ 2. textures

def test_a_texture_linked_to_dev_zero_is_refused_without_reading_it(tmp_path):
    os.symlink("/dev/zero", tmp_path / "zero.png")
    path = _stage(tmp_path, _material('color3f inputs:diffuseColor.connect = </World/Looks/M/Tex.outputs:rgb>',
                                      "asset inputs:file = @zero.png@"))
    # (before, the texture was read until memory ran out)
    _refused(path, "/World/Looks/M/Tex.inputs:file: zero.png: not a regular file")


def test_a_texture_that_is_a_directory_is_refused(tmp_path):
    (tmp_path / "adir").mkdir()
    path = _stage(tmp_path, _material('color3f inputs:diffuseColor.connect = </World/Looks/M/Tex.outputs:rgb>',
                                      "asset inputs:file = @adir@"))
    _refused(path, "/World/Looks/M/Tex.inputs:file: adir: is a directory, not a texture")


# ------------------------------------------------------------ 3. material values

@pytest.mark.parametrize("surface, message", [
    ("color3f inputs:diffuseColor = (nan, 0.5, inf)",
     "/World/Looks/M/PBR.inputs:diffuseColor: 2 values that are NaN or infinite (of 3)"),
    ("color3f inputs:diffuseColor = (-1, 0.5, 0.5)",
     "/World/Looks/M/PBR.inputs:diffuseColor: a negative colour component (-1); colours are >= 0"),
    ("color3f inputs:emissiveColor = (1e30, 0, 0)",
     "/World/Looks/M/PBR.inputs:emissiveColor: values up to 1e+30 in magnitude, more than rtmesh takes (1e+18)"),
    ("float inputs:diffuseColor = 0.5", "/World/Looks/M/PBR.inputs:diffuseColor: expected 3 numbers (got 0.5)"),
    ("float inputs:roughness = nan",
     "/World/Looks/M/PBR.inputs:roughness: expected a finite number (0, or magnitude 1e-18 to 1e+18) (got nan)"),
    ("float inputs:opacity = -1", "/World/Looks/M/PBR.inputs:opacity: expected a number >= 0 (got -1.0)"),
])
def test_material_values_out_of_range_are_refused(tmp_path, surface, message):
    _refused(_stage(tmp_path, _material(surface)), message)


def test_a_texture_scale_that_is_not_finite_is_refused(tmp_path):
    from PIL import Image

    Image.new("RGB", (2, 2), (255, 255, 255)).save(tmp_path / "t.png")
    path = _stage(tmp_path, _material('color3f inputs:diffuseColor.connect = </World/Looks/M/Tex.outputs:rgb>',
                                      "asset inputs:file = @t.png@\n float4 inputs:scale = (nan, inf, -1, 1)"))
    _refused(path, "/World/Looks/M/Tex.inputs:scale: 2 values that are NaN or infinite (of 4)")


@pytest.mark.parametrize("colour, message", [
    ("color3f[] primvars:displayColor = [(-1, 0.5, 0.5)] (interpolation = \"constant\")",
     "/World/Quad.primvars:displayColor: a negative colour (-1); colours are >= 0"),
    ("color3f[] primvars:displayColor = [(nan, 0.5, 0.5)] (interpolation = \"constant\")",
     "/World/Quad.primvars:displayColor: 1 values that are NaN or infinite (of 3)"),
])
def test_display_colours_out_of_range_are_refused(tmp_path, colour, message):
    _refused(_stage(tmp_path, _quad(extra=colour)), message)


# ------------------------------------------------------------ 4. lights

@pytest.mark.parametrize("light, message", [
    ('def SphereLight "L" { float inputs:intensity = nan }',
     "/World/L.inputs:intensity: expected a finite number (0, or magnitude 1e-18 to 1e+18) (got nan)"),
    ('def SphereLight "L" { float inputs:intensity = -100 }',
     "/World/L.inputs:intensity: expected a number >= 0 (got -100.0)"),
    ('def DistantLight "L" { color3f inputs:color = (-1, -1, -1) }',
     "/World/L.inputs:color: colour components must be >= 0 (got [-1.0, -1.0, -1.0])"),
    ('def DomeLight "L" { float inputs:intensity = inf }',
     "/World/L.inputs:intensity: expected a finite number (0, or magnitude 1e-18 to 1e+18) (got inf)"),
    ('def DistantLight "L" { float inputs:intensity = 1000000 \n float inputs:exposure = 100 }',
     "/World/L.inputs:intensity: color x intensity x 2^exposure 1.26765e+36 is more than the largest "
     "intensity a scene file takes (1e+18)"),
    ('def RectLight "L" { float inputs:width = 0 }', "/World/L.inputs:width: expected a number > 0 (got 0.0)"),
])
def test_light_values_are_held_to_the_scene_files_limits(tmp_path, light, message):
    _refused(_stage(tmp_path, _quad() + _block(light)), message)


# ------------------------------------------------------------ 5. cameras

@pytest.mark.parametrize("camera, message", [
    ("float focalLength = 0", "/World/Cam.focalLength: expected a number > 0 (got 0.0)"),
    ("float focalLength = nan",
     "/World/Cam.focalLength: expected a finite number (0, or magnitude 1e-18 to 1e+18) (got nan)"),
    ("float verticalAperture = -20", "/World/Cam.verticalAperture: expected a number > 0 (got -20.0)"),
    ("float fStop = 2\n float focusDistance = inf",
     "/World/Cam.focusDistance: expected a finite number (0, or magnitude 1e-18 to 1e+18) (got inf)"),
    ('token projection = "orthographic"\n float verticalAperture = 0',
     "/World/Cam.verticalAperture: expected a number > 0 (got 0.0)"),
])
def test_camera_values_out_of_range_are_refused(tmp_path, camera, message):
    _refused(_stage(tmp_path, _quad() + _block(f'def Camera "Cam" {{ {camera} }}')), message)


# ------------------------------------------------------------ 6. transforms, units, shapes

@pytest.mark.parametrize("extra, message", [
    ('double3 xformOp:translate = (nan, 0, 0)\n uniform token[] xformOpOrder = ["xformOp:translate"]',
     "/World/Quad.xformOp:translate: a transform that is not finite or is more than 1e18 in magnitude"),
    ('double3 xformOp:scale = (1e300, 1, 1)\n uniform token[] xformOpOrder = ["xformOp:scale"]',
     "/World/Quad.xformOp:scale: a transform that is not finite or is more than 1e18 in magnitude"),
])
def test_transforms_that_are_not_finite_or_huge_are_refused(tmp_path, extra, message):
    _refused(_stage(tmp_path, _quad(extra=extra)), message)


@pytest.mark.parametrize("value", ["nan", "inf", "1e300"])
def test_meters_per_unit_out_of_range_is_refused(tmp_path, value):
    shown = {"nan": "nan", "inf": "inf", "1e300": "1e+300"}[value]
    path = _stage(tmp_path, _quad(), HEADER.replace("metersPerUnit = 1", f"metersPerUnit = {value}"))
    _refused(path, f"metersPerUnit: expected a finite number (0, or magnitude 1e-18 to 1e+18) (got {shown})")


@pytest.mark.parametrize("shape, message", [
    ('def Sphere "S" { double radius = 0 }', "/World/S.radius: expected a number > 0 (got 0.0)"),
    ('def Sphere "S" { double radius = inf }',
     "/World/S.radius: expected a finite number (0, or magnitude 1e-18 to 1e+18) (got inf)"),
    ('def Cube "C" { double size = 1e300 }',
     "/World/C.size: expected a finite number (0, or magnitude 1e-18 to 1e+18) (got 1e+300)"),
])
def test_implicit_shapes_out_of_range_are_refused(tmp_path, shape, message):
    _refused(_stage(tmp_path, _block(shape)), message)


# ------------------------------------------------------------ 7. message quality

@pytest.mark.parametrize("points, message", [
    ("int[] points = [1, 2, 3, 4]",
     "/World/Quad.points: expected an array of 3-vectors of numbers (got a value of type IntArray)"),
    ("float2[] points = [(0, 0), (1, 0), (1, 1), (0, 1)]",
     "/World/Quad.points: expected an array of 3-vectors of numbers (got 2 numbers an element)"),
])
def test_points_of_the_wrong_type_are_refused(tmp_path, points, message):
    _refused(_stage(tmp_path, _quad(points=points)), message)


def test_faces_on_points_that_are_not_finite_are_dropped_as_in_every_mesh_format(tmp_path, caplog):
    """As OBJ, PLY and glTF (docs/LIMITS.md): the faces that use a NaN point go, with a
    warning, and no NumPy warning; here both triangles of the quad use it, so nothing is left."""
    path = _stage(tmp_path, _quad(points="point3f[] points = [(nan, 0, 1), (1, 0, 1), (1, 0, -1), (-1, 0, -1)]"))
    with caplog.at_level(logging.WARNING), pytest.raises(MeshError, match="nothing to render"):
        load_scene(path)
    assert any("dropped 2 faces with NaN/Inf vertices" in r.getMessage() for r in caplog.records)


def test_negative_face_vertex_counts_are_named(tmp_path):
    path = _stage(tmp_path, _quad().replace("faceVertexCounts = [4]", "faceVertexCounts = [6, -2]"))
    _refused(path, "/World/Quad.faceVertexCounts: a negative count (-2)")


def test_primvar_indices_out_of_range_are_refused_without_usds_warning(tmp_path, capfd):
    extra = "int[] primvars:st:indices = [0, 1, 2, 9]"
    path = _stage(tmp_path, _quad(extra=extra))
    _refused(path, "/World/Quad.primvars:st: index 9 in its indices refers to a value it does not have (4 values)")
    assert "Warning" not in capfd.readouterr().err


# ------------------------------------------------------------ 2b. EXR textures

def _exr(path, pixels):
    from rtmesh.io.images import write_image

    write_image(str(path), np.asarray(pixels, dtype=np.float32))


def test_an_exr_texture_is_read_as_linear_floats(tmp_path):
    _exr(tmp_path / "t.exr", np.full((2, 2, 3), 2.5))
    path = _stage(tmp_path, _material('color3f inputs:diffuseColor.connect = </World/Looks/M/Tex.outputs:rgb>',
                                      "asset inputs:file = @t.exr@"))
    content = read_usd(path)
    texture = content.materials[0].diffuse_texture
    assert texture is not None and np.allclose(texture._pixels, 2.5)


@pytest.mark.parametrize("value, problem", [
    (np.nan, "texture holds NaN or infinite values (12 of its 12 values); a texture must be finite and >= 0"),
    (-5.0, "texture holds negative values (the least -5); a texture must be finite and >= 0"),
])
def test_an_exr_texture_that_is_not_finite_or_negative_is_refused(tmp_path, value, problem):
    _exr(tmp_path / "t.exr", np.full((2, 2, 3), value))
    path = _stage(tmp_path, _material('color3f inputs:diffuseColor.connect = </World/Looks/M/Tex.outputs:rgb>',
                                      "asset inputs:file = @t.exr@"))
    _refused(path, f"/World/Looks/M/Tex.inputs:file: t.exr: {problem}")
