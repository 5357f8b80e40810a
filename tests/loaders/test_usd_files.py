"""USD files (rtmesh/loaders/usd_files.py), written here by usd-core.

The main test renders a stage (a cube, a textured quad, a point instancer of 100 balls, a
sphere light, a camera) and the same scene as a scene file of GLB meshes with the same
metallic-roughness materials, light and camera: 8x8 block means agree within 2 %.
"""

import builtins
import json
import logging
import math

import numpy as np
import pytest
import trimesh
from PIL import Image
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade

from rtmesh.api import load_scene
from rtmesh.batch.books import REPORT_NAME
from rtmesh.cli import main
from rtmesh.core.errors import MeshError, MissingExtraError, ResourceError
from rtmesh.loaders.usd_files import read_usd
from rtmesh.rendering import memory  # noqa: E402
from rtmesh.rendering.integrator import Integrator  # noqa: E402
from rtmesh.scene import instances  # noqa: E402

# the comparison is of what the loaders make: both scenes under one integrator
SIZE = dict(width=64, height=48, spp=8, integrator="whitted")
CUBE_AT, CUBE_TURN = np.array([-1.1, 0.5, 0.3]), 30.0
LIGHT_AT, LIGHT_RADIUS, LIGHT_NITS = np.array([0.5, 3.0, 2.0]), 0.1, 3000.0
CAMERA_AT, FOCAL, APERTURE = np.array([0.0, 2.6, 5.0]), 35.0, 20.955
BALL_RADIUS = 0.12


def _checker():
    cells = (np.indices((8, 8)).sum(axis=0) % 2).astype(np.uint8)
    return Image.fromarray(np.stack([40 + 180 * cells, 60 + 20 * cells, 200 - 150 * cells], axis=2))


def _grid():
    """Positions and scales of the 100 balls: a 10 x 10 grid over the quad."""
    i, j = np.meshgrid(np.arange(10), np.arange(10), indexing="ij")
    positions = np.stack([-1.8 + 0.4 * i.ravel(), np.full(100, BALL_RADIUS), -1.8 + 0.4 * j.ravel()], axis=1)
    scales = 0.6 + 0.4 * ((i + j).ravel() % 3) / 2.0
    positions[:, 1] *= scales
    return positions, scales


def _cube_mesh():
    """A unit cube as six quads (outward, right-handed)."""
    points = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    quads = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]])
    return points, quads


def _cube_world():
    return trimesh.transformations.translation_matrix(CUBE_AT) @ trimesh.transformations.rotation_matrix(
        math.radians(CUBE_TURN), [0, 1, 0])


def _preview(stage, path, colour, roughness, texture=None):
    material = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, f"{path}/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(roughness)
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    diffuse = shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f)
    if texture is None:
        diffuse.Set(Gf.Vec3f(*colour))
    else:
        reader = UsdShade.Shader.Define(stage, f"{path}/Reader")
        reader.CreateIdAttr("UsdPrimvarReader_float2")
        reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("st")
        image = UsdShade.Shader.Define(stage, f"{path}/Texture")
        image.CreateIdAttr("UsdUVTexture")
        image.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(texture)
        image.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
            reader.ConnectableAPI(), "result")
        image.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
        diffuse.ConnectToSource(image.ConnectableAPI(), "rgb")
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return material


def _bind(prim, material):
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(material)


def write_stage(path, texture):
    """The test stage (module docstring); ``texture`` is the quad's PNG, beside it."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.Xform.Define(stage, "/World")
    # the cube: six quads, no normals (flat by the crease angle), turned and moved
    points, quads = _cube_mesh()
    cube = UsdGeom.Mesh.Define(stage, "/World/Cube")
    cube.CreatePointsAttr([Gf.Vec3f(*p) for p in points])
    cube.CreateFaceVertexCountsAttr([4] * 6)
    cube.CreateFaceVertexIndicesAttr(quads.ravel().tolist())
    cube.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    xform = UsdGeom.Xformable(cube)
    xform.AddTranslateOp().Set(Gf.Vec3d(*CUBE_AT))
    xform.AddRotateYOp().Set(CUBE_TURN)
    _bind(cube.GetPrim(), _preview(stage, "/World/Looks/Red", (0.8, 0.1, 0.1), 0.6))
    # the textured quad: the floor, st faceVarying and indexed
    quad = UsdGeom.Mesh.Define(stage, "/World/Quad")
    quad.CreatePointsAttr([(-2.2, 0, 2.2), (2.2, 0, 2.2), (2.2, 0, -2.2), (-2.2, 0, -2.2)])
    quad.CreateFaceVertexCountsAttr([4])
    quad.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    quad.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    st = UsdGeom.PrimvarsAPI(quad).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                 UsdGeom.Tokens.faceVarying)
    st.Set([(0, 0), (1, 0), (1, 1), (0, 1)])
    st.SetIndices([0, 1, 2, 3])
    _bind(quad.GetPrim(), _preview(stage, "/World/Looks/Checker", None, 0.8, texture=texture))
    # 100 balls by a point instancer, with the prototype under it
    instancer = UsdGeom.PointInstancer.Define(stage, "/World/Balls")
    ball_mesh = trimesh.creation.icosphere(subdivisions=1, radius=BALL_RADIUS)
    ball = UsdGeom.Mesh.Define(stage, "/World/Balls/Prototypes/Ball")
    ball.CreatePointsAttr([Gf.Vec3f(*p) for p in ball_mesh.vertices])
    ball.CreateFaceVertexCountsAttr([3] * len(ball_mesh.faces))
    ball.CreateFaceVertexIndicesAttr(ball_mesh.faces.ravel().tolist())
    ball.CreateNormalsAttr([Gf.Vec3f(*n) for n in ball_mesh.vertex_normals])
    ball.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    ball.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    _bind(ball.GetPrim(), _preview(stage, "/World/Looks/Blue", (0.1, 0.3, 0.9), 0.4))
    instancer.CreatePrototypesRel().SetTargets([ball.GetPath()])
    positions, scales = _grid()
    instancer.CreateProtoIndicesAttr([0] * 100)
    instancer.CreatePositionsAttr([Gf.Vec3f(*p) for p in positions])
    instancer.CreateScalesAttr([Gf.Vec3f(s, s, s) for s in scales])
    # the sphere light and the camera
    light = UsdLux.SphereLight.Define(stage, "/World/Light")
    light.CreateRadiusAttr(LIGHT_RADIUS)
    light.CreateIntensityAttr(LIGHT_NITS)
    UsdGeom.Xformable(light).AddTranslateOp().Set(Gf.Vec3d(*LIGHT_AT))
    camera = UsdGeom.Camera.Define(stage, "/World/Camera")
    camera.CreateFocalLengthAttr(FOCAL)
    camera.CreateVerticalApertureAttr(APERTURE)
    camera.CreateHorizontalApertureAttr(APERTURE * 4 / 3)
    look = Gf.Matrix4d().SetLookAt(Gf.Vec3d(*CAMERA_AT), Gf.Vec3d(0, 0, 0), Gf.Vec3d(0, 1, 0)).GetInverse()
    UsdGeom.Xformable(camera).AddTransformOp().Set(look)
    stage.GetRootLayer().Save()
    return path


def _glb(path, mesh, colour, roughness, image=None):
    material = trimesh.visual.material.PBRMaterial(
        name=path.stem, baseColorFactor=[*colour, 1.0] if image is None else None, baseColorTexture=image,
        metallicFactor=0.0, roughnessFactor=roughness, doubleSided=True)
    uv = mesh.visual.uv if getattr(mesh.visual, "uv", None) is not None else None
    mesh.visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    path.write_bytes(trimesh.exchange.gltf.export_glb(trimesh.Scene(mesh), include_normals=image is None
                                                      and "ball" in path.stem))
    return path.name


def write_scene_file(folder):
    """The same scene as a scene file of GLB meshes."""
    points, quads = _cube_mesh()
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    cube = trimesh.Trimesh(trimesh.transform_points(points, _cube_world()), triangles, process=False)
    quad = trimesh.Trimesh([(-2.2, 0, 2.2), (2.2, 0, 2.2), (2.2, 0, -2.2), (-2.2, 0, -2.2)],
                           [[0, 1, 2], [0, 2, 3]], process=False)
    quad.visual = trimesh.visual.TextureVisuals(uv=[(0, 0), (1, 0), (1, 1), (0, 1)])
    ball = trimesh.creation.icosphere(subdivisions=1, radius=BALL_RADIUS)
    lines = [f'[[objects]]\nmesh = "{_glb(folder / "cube.glb", cube, (0.8, 0.1, 0.1), 0.6)}"\n',
             f'[[objects]]\nmesh = "{_glb(folder / "quad.glb", quad, None, 0.8, _checker())}"\n']
    ball_file = _glb(folder / "ball.glb", ball, (0.1, 0.3, 0.9), 0.4)
    for position, scale in zip(*_grid()):
        lines.append(f'[[objects]]\nmesh = "{ball_file}"\nscale = {float(scale)!r}\n'
                     f'translate = {[float(x) for x in position]}\n')
    fov = math.degrees(2 * math.atan(0.5 * APERTURE / FOCAL))
    lines.append(f"[camera]\nposition = {CAMERA_AT.tolist()}\nlook_at = [0, 0, 0]\nfov = {fov!r}\n")
    # radiance x pi r^2 (W/sr), in the Whitted integrator's units (divided by pi, as glTF's lights)
    intensity = LIGHT_NITS * LIGHT_RADIUS ** 2
    lines.append(f'[[lights]]\ntype = "point"\nposition = {LIGHT_AT.tolist()}\nintensity = {intensity!r}\n')
    path = folder / "scene.toml"
    path.write_text("\n".join(lines))
    return path


@pytest.fixture(scope="module")
def usd_file(tmp_path_factory):
    folder = tmp_path_factory.mktemp("usd")
    _checker().save(folder / "checker.png")
    return write_stage(folder / "scene.usda", "checker.png")


def _blocks(image):
    h, w = image.shape[0] // 8 * 8, image.shape[1] // 8 * 8
    return image[:h, :w].reshape(h // 8, 8, w // 8, 8, 3).mean(axis=(1, 3))


def test_a_usd_stage_renders_as_the_same_scene_file(usd_file, tmp_path):
    scene, settings = load_scene(str(usd_file), **SIZE)
    reference, ref_settings = load_scene(str(write_scene_file(tmp_path)), **SIZE)
    # the instancer's ball (80 triangles) and the scene file's 100 objects naming one ball
    # file: built once, placed 100 times (Whitted renders the copies)
    assert len(scene.faces) == len(reference.faces) == 12 + 2 + 80
    assert len(scene.instances) == len(reference.instances) == 100
    assert len(instances.flattened(scene).faces) == len(instances.flattened(reference).faces) == 12 + 2 + 100 * 80
    assert len(scene.lights) == 1 and np.allclose(scene.lights[0].intensity, reference.lights[0].intensity)
    image = Integrator(scene, settings).render().image.astype(np.float64)
    expected = Integrator(reference, ref_settings).render().image.astype(np.float64)
    assert expected.mean() > 0.02
    a, b = _blocks(image), _blocks(expected)
    floor = 0.05 * b.mean()  # the dark blocks: within 2 % of a twentieth of the mean
    assert (np.abs(a - b) <= 0.02 * np.maximum(b, floor)).all(), np.abs(a - b).max()


def test_usd_content_is_mapped_in_rtmesh_units(usd_file):
    content = read_usd(usd_file)
    names = [p.name for p in content.parts]
    assert names == ["/World/Cube", "/World/Quad"]
    (balls,) = content.placements
    assert balls.part.name == "/World/Balls/Prototypes/Ball" and len(balls.part.faces) == 80
    assert balls.transforms.shape == (100, 4, 4) and balls.names[:2] == ["/World/Balls/Prototypes/Ball[0]",
                                                                         "/World/Balls/Prototypes/Ball[1]"]
    quad = content.parts[1]
    assert quad.uv is not None and len(quad.vertices) == 4
    materials = {m.name: m for m in content.materials}
    np.testing.assert_array_equal(materials["Checker"].diffuse_texture.bytes[..., :3], np.asarray(_checker()))
    assert materials["Red"].model == "metallic_roughness" and np.allclose(materials["Red"].base_color, [0.8, 0.1, 0.1])
    camera = content.camera
    assert np.allclose(camera.position, CAMERA_AT)
    assert math.isclose(camera.fov, math.degrees(2 * math.atan(0.5 * APERTURE / FOCAL)), rel_tol=1e-6)
    (light,) = content.lights
    assert np.allclose(light.position, LIGHT_AT)


def _stage(path, up="Y", meters=1.0):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, up)
    UsdGeom.SetStageMetersPerUnit(stage, meters)
    return stage


def test_primvars_of_every_interpolation_reach_each_corner(tmp_path):
    # two quads sharing an edge: displayColor per face (uniform), st per corner (faceVarying),
    # normals per point (vertex), displayOpacity constant
    stage = _stage(tmp_path / "primvars.usda")
    mesh = UsdGeom.Mesh.Define(stage, "/M")
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0)])
    mesh.CreateFaceVertexCountsAttr([4, 4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 4, 3, 1, 2, 5, 4])
    api = UsdGeom.PrimvarsAPI(mesh)
    api.CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.uniform).Set(
        [(1, 0, 0), (0, 0, 1)])
    api.CreatePrimvar("displayOpacity", Sdf.ValueTypeNames.FloatArray, UsdGeom.Tokens.constant).Set([0.5])
    api.CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying).Set(
        [(0, 0), (1, 0), (1, 1), (0, 1)] * 2)
    api.CreatePrimvar("normals", Sdf.ValueTypeNames.Normal3fArray, UsdGeom.Tokens.vertex).Set([(0, 0, 1)] * 6)
    stage.GetRootLayer().Save()
    (part,) = read_usd(tmp_path / "primvars.usda").parts
    # the shared edge splits: its points have another st (and colour) in each quad
    assert len(part.vertices) == 8 and len(part.faces) == 4
    corners = part.vertices[part.faces]  # (4, 3, 3)
    colours = part.vertex_colors[part.faces]
    left = corners[:, :, 0].mean(axis=1) < 1.0
    assert np.allclose(colours[left][..., :3], [1, 0, 0]) and np.allclose(colours[~left][..., :3], [0, 0, 1])
    assert np.allclose(colours[..., 3], 0.5)
    uv = part.uv[part.faces]
    local_x = corners[..., 0] - np.where(left, 0.0, 1.0)[:, None]
    assert np.allclose(uv[..., 0], local_x) and np.allclose(uv[..., 1], corners[..., 1])
    assert np.allclose(part.vertex_normals, [0, 0, 1])
    (material,) = read_usd(tmp_path / "primvars.usda").materials
    assert np.allclose(material.base_color, 1.0)  # the colours are the vertices'


def test_z_up_centimetre_stages_are_turned_to_y_up_metres(tmp_path):
    stage = _stage(tmp_path / "z_up.usda", up="Z", meters=0.01)
    mesh = UsdGeom.Mesh.Define(stage, "/T")
    mesh.CreatePointsAttr([(0, 0, 0), (100, 0, 0), (0, 0, 200)])
    mesh.CreateFaceVertexCountsAttr([3])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2])
    stage.GetRootLayer().Save()
    (part,) = read_usd(tmp_path / "z_up.usda").parts
    assert np.allclose(np.sort(part.vertices, axis=0), np.sort(np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0]]), axis=0))


def _cli(path, tmp_path, capsys, *extra):
    out = tmp_path / "out.png"
    status = main(["render", str(path), "-o", str(out), "--width", "24", "--height", "18", "-q", *extra])
    return status, capsys.readouterr().err, out


def test_a_cycle_of_references_is_one_line_and_nothing_written(tmp_path, capsys):
    (tmp_path / "a.usda").write_text('#usda 1.0\ndef Xform "A" (prepend references = @b.usda@</B>) {}\n')
    (tmp_path / "b.usda").write_text('#usda 1.0\ndef Xform "B" (prepend references = @a.usda@</A>) {}\n')
    status, err, out = _cli(tmp_path / "a.usda", tmp_path, capsys)
    assert status == 2 and not out.exists()
    assert err == (f"rtmesh: error: {tmp_path / 'a.usda'}: a cycle of references: a.usda</A> -> b.usda</B> -> "
                   "a.usda</A> (USD cannot compose it)\n")


def test_a_malformed_usd_file_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.usda"
    bad.write_text('#usda 1.0\ndef Mesh "M" { int[] faceVertexCounts = [3 }\n')
    status, err, out = _cli(bad, tmp_path, capsys)
    assert status == 2 and not out.exists() and len(err.splitlines()) == 1
    assert err.startswith(f"rtmesh: error: {bad}: cannot read USD: ") and "parse error" in err
    indices = tmp_path / "indices.usda"
    stage = _stage(indices)
    mesh = UsdGeom.Mesh.Define(stage, "/M")
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    mesh.CreateFaceVertexCountsAttr([3])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 7])
    stage.GetRootLayer().Save()
    status, err, out = _cli(indices, tmp_path, capsys)
    assert status == 2 and not out.exists()
    assert err == (f"rtmesh: error: {indices}: /M: faceVertexIndices refer to points the mesh does not have "
                   "(3 points)\n")


def test_a_usd_file_renders_on_the_command_line(usd_file, tmp_path, capsys):
    status, err, out = _cli(usd_file, tmp_path, capsys)
    assert status == 0 and out.exists() and "error" not in err


def test_flattening_instances_beyond_the_memory_limit_stops_before_taking_it(usd_file, tmp_path, capsys,
                                                                            monkeypatch):
    # 100 balls of 80 triangles, instanced: the ball counted once (and a record a placement)
    with memory.loading_limit(1_000_000):
        assert len(read_usd(usd_file).placements) == 1
    # copied (as balls below the instancing size are): about 3.5 MB, refused under 1 MB
    monkeypatch.setattr(instances, "MIN_TRIANGLES", 10 ** 9)
    with memory.loading_limit(1_000_000), pytest.raises(ResourceError) as caught:
        read_usd(usd_file)
    assert str(caught.value).startswith(f"{usd_file}: /World/Balls/Prototypes/Ball and the prims before it, "
                                        "flattened (100 copies of 80 triangles here) would need about ")
    status, err, out = _cli(usd_file, tmp_path, capsys, "--memory-limit", "1M")
    assert status == 2 and not out.exists() and len(err.splitlines()) == 1
    assert "--memory-limit is 1 MiB" in err


def test_without_usd_core_the_error_names_the_extra(usd_file, monkeypatch):
    real_import = builtins.__import__

    def without(name, *args, **kwargs):
        if name == "pxr" or name.startswith("pxr."):
            raise ImportError("No module named 'pxr'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", without)
    with pytest.raises(MissingExtraError, match=r"USD files need usd-core: pip install 'rtmesh\[usd\]'"):
        read_usd(usd_file)


def test_a_missing_texture_is_a_warning_and_the_rest_renders(tmp_path, caplog):
    path = write_stage(tmp_path / "lost.usda", "gone.png")
    with caplog.at_level(logging.WARNING):
        content = read_usd(path)
    assert any("texture gone.png cannot be read" in r.getMessage() for r in caplog.records)
    assert len(content.parts) + len(content.placements) == 3
    with pytest.raises(MeshError, match="nothing to render"):
        (tmp_path / "empty.usda").write_text("#usda 1.0\n")
        load_scene(str(tmp_path / "empty.usda"))


def _layered_stage(folder):
    """A stage whose geometry lives in other layers: a sublayer, a reference and a payload
    (in a layer of its own folder, referencing a fourth layer), and a texture beside them."""
    def triangle_layer(name, offset):
        stage = _stage(folder / name)
        mesh = UsdGeom.Mesh.Define(stage, "/Tri")
        mesh.CreatePointsAttr([(offset, 0, 0), (offset + 1, 0, 0), (offset, 1, 0)])
        mesh.CreateFaceVertexCountsAttr([3])
        mesh.CreateFaceVertexIndicesAttr([0, 1, 2])
        stage.SetDefaultPrim(mesh.GetPrim())
        stage.GetRootLayer().Save()

    (folder / "parts").mkdir()
    _checker().save(folder / "parts" / "checker.png")
    triangle_layer("sub.usda", 0.0)
    triangle_layer("ref.usda", 2.0)
    triangle_layer("parts/deep.usda", 4.0)  # its prim, placed by the payload, is textured
    payload = _stage(folder / "parts" / "payload.usda")
    holder = UsdGeom.Xform.Define(payload, "/Holder")
    payload.DefinePrim("/Holder/Deep").GetReferences().AddReference("./deep.usda")
    payload.SetDefaultPrim(holder.GetPrim())
    _bind(payload.GetPrimAtPath("/Holder/Deep"), _preview(payload, "/Holder/Look", None, 0.5, "./checker.png"))
    payload.GetRootLayer().Save()
    stage = _stage(folder / "root.usda")
    stage.GetRootLayer().subLayerPaths.append("./sub.usda")
    stage.DefinePrim("/Referenced").GetReferences().AddReference("./ref.usda")
    stage.DefinePrim("/Loaded").GetPayloads().AddPayload("./parts/payload.usda")
    stage.GetRootLayer().Save()
    return folder / "root.usda"


def test_the_layers_a_stage_composes_are_inputs_of_its_load(tmp_path):
    from rtmesh.batch.identity import OpenedFiles

    root = _layered_stage(tmp_path)
    with OpenedFiles() as opened:
        parts = read_usd(root).parts
    assert len(parts) == 3
    names = sorted(entry[0] for entry in opened.entries(root))
    assert names == ["", "parts/checker.png", "parts/deep.usda", "parts/payload.usda", "ref.usda", "sub.usda"]


@pytest.mark.usefixtures("in_process_jobs")  # a batch's USD inputs, not its worker processes
def test_a_folder_of_usd_files_renders_in_batch(usd_file, tmp_path, capsys):
    import shutil

    source = tmp_path / "src"
    source.mkdir()
    shutil.copy(usd_file, source / "scene.usda")
    shutil.copy(usd_file.parent / "checker.png", source / "checker.png")
    # and a stage made of layers in a folder of its own, the batch given its root file
    (tmp_path / "layered").mkdir()
    root = _layered_stage(tmp_path / "layered")
    out = tmp_path / "out"
    args = ["batch", str(source), str(root), "-o", str(out), "--width", "16", "--height", "16", "--spp", "1",
            "--workers", "1", "-q"]
    code = main(args)
    assert code == 0, capsys.readouterr().err
    assert (out / "scene.usda.png").exists() and (out / "root.usda.png").exists()
    # a layer the stage references changed: only that asset's image is redone
    deep = root.parent / "parts" / "deep.usda"
    deep.write_text(deep.read_text().replace("(4, 1, 0)", "(4, 2, 0)"))
    assert main(args) == 0
    lines = [json.loads(line) for line in (out / REPORT_NAME).read_text().splitlines()]
    assert [line["asset"] for line in lines if line["status"] == "done"] == ["root.usda"]


def test_instanceable_prims_are_placed_as_their_references(tmp_path):
    stage = _stage(tmp_path / "instanced.usda")
    UsdGeom.Xform.Define(stage, "/Library")
    stage.GetPrimAtPath("/Library").SetSpecifier(Sdf.SpecifierClass)
    tri = UsdGeom.Mesh.Define(stage, "/Library/Tri")
    tri.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    tri.CreateFaceVertexCountsAttr([3])
    tri.CreateFaceVertexIndicesAttr([0, 1, 2])
    for i in range(3):
        holder = UsdGeom.Xform.Define(stage, f"/Copy{i}")
        holder.AddTranslateOp().Set(Gf.Vec3d(10.0 * i, 0, 0))
        holder.GetPrim().GetReferences().AddInternalReference("/Library")
        holder.GetPrim().SetInstanceable(True)
    stage.GetRootLayer().Save()
    parts = read_usd(tmp_path / "instanced.usda").parts
    assert len(parts) == 3
    assert sorted(float(p.vertices[:, 0].min()) for p in parts) == [0.0, 10.0, 20.0]


def test_a_usdz_package_reads_its_textures_from_the_package(usd_file, tmp_path):
    from pxr import UsdUtils

    package = tmp_path / "scene.usdz"
    assert UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(usd_file)), str(package))
    content = read_usd(package)
    texture = {m.name: m for m in content.materials}["Checker"].diffuse_texture
    np.testing.assert_array_equal(texture.bytes[..., :3], np.asarray(_checker()))
    assert len(content.parts) + len(content.placements) == 3


def test_usds_own_diagnostics_stay_off_the_terminal(tmp_path):
    # USD prints composition warnings from C++ on file descriptor 2; a user sees one line
    import subprocess
    import sys

    (tmp_path / "a.usda").write_text('#usda 1.0\ndef Xform "A" (prepend references = @b.usda@</B>) {}\n')
    (tmp_path / "b.usda").write_text('#usda 1.0\ndef Xform "B" (prepend references = @a.usda@</A>) {}\n')
    proc = subprocess.run([sys.executable, "-m", "rtmesh.cli", "render", str(tmp_path / "a.usda"), "-o",
                           str(tmp_path / "out.png"), "--width", "24", "--height", "18", "-q"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and not (tmp_path / "out.png").exists()
    assert proc.stderr.splitlines() == [f"rtmesh: error: {tmp_path / 'a.usda'}: a cycle of references: "
                                        "a.usda</A> -> b.usda</B> -> a.usda</A> (USD cannot compose it)"]


def test_a_scene_file_object_places_a_usd_file_with_its_materials(usd_file, tmp_path):
    scene_file = tmp_path / "with_usd.toml"
    scene_file.write_text(f'[[objects]]\nmesh = "{usd_file}"\ntranslate = [0, 5, 0]\nscale = 2\n'
                          '[[lights]]\ntype = "directional"\ndirection = [0, -1, 0]\nirradiance = 1\n')
    scene, _ = load_scene(str(scene_file), width=16, height=12, spp=1)
    direct = read_usd(usd_file)
    points = np.concatenate([p.vertices for p in direct.parts])
    # the balls placed by instances, the object's transform after the instancer's
    assert len(scene.instances) == 100
    assert np.allclose(scene.bounds[0], 2 * points.min(axis=0) + [0, 5, 0], atol=1e-6)
    flat = instances.flattened(scene)
    assert np.allclose(flat.vertices.min(axis=0), 2 * points.min(axis=0) + [0, 5, 0], atol=1e-6)
    assert {"Red", "Checker", "Blue"} <= {m.name for m in scene.materials.materials}
