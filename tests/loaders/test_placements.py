"""Meshes the loaders place many times (rtmesh/loaders/placements.py): scene-file objects
that import one file, ``[[objects]] instances = "file.npy"``, USD point instancers and
instanceable prims are built once and placed by Embree instances from
``instances.MIN_TRIANGLES`` triangles, and render as their copies."""

import io

import numpy as np
import pytest
import trimesh

from rtmesh.api import load_scene
from rtmesh.cli import main
from rtmesh.rendering.integrator import Integrator
from rtmesh.scene import instances
from scenes import block_means, scattered_transforms

SIZE = dict(width=32, height=24, spp=4, integrator="path", caustics="off")
COUNT = 24


def _same_image(scene, settings, copies):
    """The instanced scene's image against the copies' (made by the loader): 8x8 block means
    within 1 % (of the block, or of a twentieth of the mean for dark blocks)."""
    it = Integrator(scene, settings)
    assert it.instances is not None  # traced through instances, not flattened
    a = block_means(it.render().image.astype(np.float64))
    b = block_means(Integrator(copies, settings).render().image.astype(np.float64))
    assert b.mean() > 0.02
    assert (np.abs(a - b) <= 0.01 * np.maximum(b, 0.05 * b.mean())).all(), np.abs(a - b).max()


def _ball_file(folder, subdivisions=2):
    """ball.glb: a smooth icosphere of radius 0.6 (320 triangles at 2 subdivisions)."""
    ball = trimesh.creation.icosphere(subdivisions, radius=0.6)
    ball.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(
        baseColorFactor=[0.8, 0.3, 0.2, 1.0], metallicFactor=0.0, roughnessFactor=0.5))
    (folder / "ball.glb").write_bytes(trimesh.exchange.gltf.export_glb(trimesh.Scene(ball), include_normals=True))
    return ball


def _scene_file(folder, objects, rows=None):
    """A floor, the objects (TOML) and a camera; ``rows`` saved as rows.npy beside it."""
    if rows is not None:
        np.save(folder / "rows.npy", rows)
    (folder / "scene.toml").write_text(
        '[camera]\nposition = [0, 9, 12]\nlook_at = [0, 0, 0]\nfov = 50\n'
        '[[lights]]\ntype = "directional"\ndirection = [-0.3, -1, -0.4]\nirradiance = 3\n'
        '[[objects]]\nprimitive = "box"\nextents = [12, 0.2, 12]\ntranslate = [0, -0.1, 0]\n' + objects)
    return folder / "scene.toml"


OBJECT = '[[objects]]\nname = "ball"\nmesh = "ball.glb"\ninstances = "rows.npy"\nscale = 0.8\ntranslate = [0.5, 0, -1]\n'


def test_an_instances_file_places_the_mesh_once_after_its_rows_then_the_object(tmp_path):
    ball = _ball_file(tmp_path)
    rows = scattered_transforms(COUNT)
    scene, _ = load_scene(str(_scene_file(tmp_path, OBJECT, rows)), **SIZE)
    inst = scene.instances
    assert len(inst) == COUNT and len(scene.faces) == 12 + 320  # the floor, the ball once
    assert scene.object_names[1:3] == ["ball[0]", "ball[1]"] and scene.object_categories[1] == "ball"
    # world = the object's transform (scale, then translate) after each row
    world = trimesh.transformations.translation_matrix([0.5, 0, -1]) @ np.diag([0.8, 0.8, 0.8, 1.0])
    np.testing.assert_allclose(inst.transforms, world @ rows, rtol=0, atol=1e-12)
    flat = instances.flattened(scene)
    copy = flat.vertices[flat.faces[flat.object_id == 3]].reshape(-1, 3)
    expected = trimesh.transform_points(ball.vertices, world @ rows[2])
    assert np.abs(copy[:, None] - expected[None]).sum(axis=2).min(axis=1).max() < 1e-6  # float32 in the GLB
    np.testing.assert_allclose(scene.bounds, flat.bounds, rtol=0, atol=1e-12)


def test_an_instances_file_renders_as_the_copies_under_path(tmp_path, monkeypatch):
    _ball_file(tmp_path)
    path = _scene_file(tmp_path, OBJECT, scattered_transforms(COUNT))
    scene, settings = load_scene(str(path), **SIZE)
    monkeypatch.setattr(instances, "MIN_TRIANGLES", 10 ** 9)  # the loader copies instead
    copies, _ = load_scene(str(path), **SIZE)
    assert copies.instances is None and len(copies.faces) == 12 + COUNT * 320
    _same_image(scene, settings, copies)


def test_objects_importing_one_file_share_it(tmp_path, monkeypatch):
    _ball_file(tmp_path)
    rows = scattered_transforms(6)
    objects = "".join(f'[[objects]]\nmesh = "ball.glb"\ntranslate = {rows[j, :3, 3].tolist()}\nscale = 0.5\n'
                      for j in range(6))
    objects += '[[objects]]\nmesh = "ball.glb"\nsmooth = false\ntranslate = [0, 3, 0]\n'  # shaded otherwise: its own
    path = _scene_file(tmp_path, objects)
    scene, settings = load_scene(str(path), **SIZE)
    assert len(scene.instances) == 6 and len(scene.faces) == 12 + 320 + 320
    # the default, the shared file's material (read once) and the flat object's own reading
    assert len(scene.materials.materials) == 3
    monkeypatch.setattr(instances, "MIN_TRIANGLES", 10 ** 9)
    copies, _ = load_scene(str(path), **SIZE)
    assert copies.instances is None and len(copies.faces) == 12 + 7 * 320
    _same_image(scene, settings, copies)


def test_a_files_own_node_reuse_is_kept_through_the_objects_placements(tmp_path):
    ball = trimesh.creation.icosphere(2, radius=0.6)
    graph = trimesh.Scene()
    moves = [trimesh.transformations.translation_matrix([x, 0.6, 0]) for x in (-2.0, 0.0, 2.0)]
    graph.add_geometry(ball, node_name="b0", geom_name="ball", transform=moves[0])
    for j in (1, 2):
        graph.graph.update(frame_to=f"b{j}", frame_from=graph.graph.base_frame, geometry="ball", matrix=moves[j])
    (tmp_path / "three.glb").write_bytes(trimesh.exchange.gltf.export_glb(graph))
    rows = np.stack([trimesh.transformations.translation_matrix([0, 0, z]) for z in (-2.0, 2.0)])
    once = '[[objects]]\nname = "row"\nmesh = "three.glb"\n'
    scene, _ = load_scene(str(_scene_file(tmp_path, once)), **SIZE)
    assert len(scene.instances) == 3 and len(scene.faces) == 12 + 320
    twice = '[[objects]]\nname = "row"\nmesh = "three.glb"\ninstances = "rows.npy"\n'
    scene, _ = load_scene(str(_scene_file(tmp_path, twice, rows)), **SIZE)
    inst = scene.instances
    assert len(inst) == 6 and len(scene.faces) == 12 + 320
    assert sorted(scene.object_names[1:]) == [f"row/b{i}[{j}]" for i in range(3) for j in range(2)]
    # one level: each row after the file's node
    expected = {(x, 0.6, z) for x in (-2.0, 0.0, 2.0) for z in (-2.0, 2.0)}
    assert {tuple(np.round(t[:3, 3], 9) + 0.0) for t in inst.transforms} == expected


def test_a_small_mesh_is_copied_and_a_primitive_can_be_placed(tmp_path):
    rows = scattered_transforms(5)
    objects = ('[[objects]]\nprimitive = "box"\nname = "crate"\ninstances = "rows.npy"\n'
               '[[objects]]\nprimitive = "icosphere"\nsubdivisions = 1\ninstances = "rows.npy"\ntranslate = [0, 2, 0]\n')
    scene, _ = load_scene(str(_scene_file(tmp_path, objects, rows)), **SIZE)
    # the boxes (12 triangles) copied into one object; the 80-triangle spheres instanced
    assert "crate (5 copies)" in scene.object_names and len(scene.instances) == 5
    assert len(scene.faces) == 12 + 5 * 12 + 80


def _bad(rows):
    out = io.BytesIO()
    np.save(out, rows)
    return out.getvalue()


GOOD = scattered_transforms(4)
SINGULAR, NAN, INF, PROJECTIVE, HUGE = (GOOD.copy() for _ in range(5))
SINGULAR[2, :3, 1] = 0.0
NAN[1, 0, 3] = np.nan
INF[3, 2, 2] = np.inf
PROJECTIVE[0, 3, 0] = 0.5
HUGE[1, 0, 3] = 1e30


BAD_FILES = {
    "missing": (None, "cannot read"),
    "not_npy": (b"not an array at all", "not a NumPy .npy file"),
    "truncated": (_bad(GOOD)[:150], "truncated or corrupt"),
    "wrong_shape": (_bad(GOOD[:, :3]), "shape (4, 3, 4), expected (k, 4, 4)"),
    "empty": (_bad(np.zeros((0, 4, 4))), "shape (0, 4, 4)"),
    "complex": (_bad(GOOD.astype(np.complex128)), "complex128 values, not numbers"),
    "singular": (_bad(SINGULAR), "instance 2 has a singular transform"),
    "nan": (_bad(NAN), "instance 1 has a non-finite transform"),
    "inf": (_bad(INF), "instance 3 has a non-finite transform"),
    "projective": (_bad(PROJECTIVE), "instance 0 has a transform that is not affine"),
    "huge": (_bad(HUGE), "instance 1 has a number beyond 1e+18"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_a_bad_instances_file_is_one_line_and_nothing_written(tmp_path, capsys, case):
    content, why = BAD_FILES[case]
    _ball_file(tmp_path)
    path = _scene_file(tmp_path, OBJECT)
    if content is not None:
        (tmp_path / "rows.npy").write_bytes(content)
    out = tmp_path / "out.png"
    status = main(["render", str(path), "-o", str(out), "--width", "16", "--height", "12", "-q"])
    err = capsys.readouterr().err
    assert status == 2 and not out.exists() and "Traceback" not in err
    assert err.count("\n") == 1, err
    assert f"{path}: objects[1].instances: " in err and "rows.npy" in err and why in err, err


def test_copies_beyond_the_memory_limit_stop_before_they_are_made(tmp_path, capsys):
    rows = np.tile(np.eye(4), (20_000, 1, 1))
    rows[:, 0, 3] = np.arange(20_000)
    objects = ('[[objects]]\nprimitive = "box"\ninstances = "rows.npy"\n'
               '[[objects]]\nprimitive = "icosphere"\ninstances = "rows.npy"\n')
    path = _scene_file(tmp_path, objects, rows)
    out = tmp_path / "out.png"
    # 20,000 boxes copied: ~180 MB; 20,000 instances of one sphere: ~25 MB, its records
    status = main(["render", str(path), "-o", str(out), "--width", "16", "--height", "12", "-q",
                   "--memory-limit", "100M"])
    err = capsys.readouterr().err
    assert status == 2 and not out.exists() and err.count("\n") == 1
    assert "objects[1]: 20000 copies of 12 triangles would need about" in err and "--memory-limit is 100 MiB" in err


def _placed_spheres(tmp_path, capsys, material, limit):
    """Render 20,000 placements of a 1280-triangle sphere of ``material`` (a scene-file
    table) under ``--memory-limit limit``: (exit status, error text, output path)."""
    rows = np.tile(np.eye(4), (20_000, 1, 1))
    rows[:, 0, 3] = np.arange(20_000)
    path = _scene_file(tmp_path, f'[materials.m]\n{material}\n[[objects]]\nprimitive = "icosphere"\n'
                                 'material = "m"\ninstances = "rows.npy"\n', rows)
    out = tmp_path / "out.png"
    status = main(["render", str(path), "-o", str(out), "--width", "16", "--height", "12", "-q",
                   "--memory-limit", limit, "--integrator", "path"])
    return status, capsys.readouterr().err, out


def test_too_many_instance_rows_are_refused_naming_the_scene_file_and_the_key(tmp_path, capsys):
    # 200,000 placements' records (~230 MiB) before the rows are read
    rows = np.tile(np.eye(4), (200_000, 1, 1))
    path = _scene_file(tmp_path, '[[objects]]\nprimitive = "icosphere"\ninstances = "rows.npy"\n', rows)
    out = tmp_path / "out.png"
    status = main(["render", str(path), "-o", str(out), "--width", "16", "--height", "12", "-q",
                   "--memory-limit", "100M"])
    err = capsys.readouterr().err
    assert status == 2 and not out.exists() and err.count("\n") == 1, err
    assert f"{path}: objects[1].instances: {tmp_path / 'rows.npy'}: 200000 instance transforms would need about" in err


def test_placed_emitters_beyond_the_memory_limit_stop_before_them(tmp_path, capsys):
    # loaded once (~25 MB); every placed face is a light of its own (~5 GB of light rows):
    # refused, one line, before the render takes them
    status, err, out = _placed_spheres(tmp_path, capsys, "emission = [1, 1, 1]", "100M")
    assert status == 2 and not out.exists() and err.count("\n") == 1, err
    assert "the scene: 25600000 placed emissive triangles as lights would need about" in err


def test_placed_glass_stays_placed_within_the_memory_limit(tmp_path, capsys):
    # loaded once (~25 MB) and traced as instances, media included (copies: ~15 GB)
    status, err, out = _placed_spheres(tmp_path, capsys, "transmission = [1, 1, 1]", "200M")
    assert status == 0 and out.exists(), err


# ---------------------------------------------------------------- USD


@pytest.fixture
def pxr():
    import pxr

    return pxr


def _usd_stage(path, pxr, instanceable):
    """A floor, a light, a camera and 12 balls of 80 triangles: placed by a point instancer,
    or as instanceable prims referencing one ball."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    floor = UsdGeom.Mesh.Define(stage, "/World/Floor")
    floor.CreatePointsAttr([(-6, 0, 6), (6, 0, 6), (6, 0, -6), (-6, 0, -6)])
    floor.CreateFaceVertexCountsAttr([4])
    floor.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    ball = trimesh.creation.icosphere(subdivisions=1, radius=0.5)
    root = "/Library/Ball" if instanceable else "/World/Balls/Prototypes/Ball"
    if instanceable:
        stage.DefinePrim("/Library", "Xform").SetSpecifier(Sdf.SpecifierClass)
    mesh = UsdGeom.Mesh.Define(stage, root)
    mesh.CreatePointsAttr([Gf.Vec3f(*p) for p in ball.vertices])
    mesh.CreateFaceVertexCountsAttr([3] * len(ball.faces))
    mesh.CreateFaceVertexIndicesAttr(ball.faces.ravel().tolist())
    mesh.CreateNormalsAttr([Gf.Vec3f(*n) for n in ball.vertex_normals])
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    mesh.CreateDisplayColorAttr([(0.8, 0.3, 0.2)])
    rows = scattered_transforms(12)
    if instanceable:
        for j, row in enumerate(rows):
            holder = UsdGeom.Xform.Define(stage, f"/World/Ball{j}")
            holder.AddTransformOp().Set(Gf.Matrix4d(row.T.tolist()))
            holder.GetPrim().GetReferences().AddInternalReference("/Library")
            holder.GetPrim().SetInstanceable(True)
    else:
        instancer = UsdGeom.PointInstancer.Define(stage, "/World/Balls")
        instancer.CreatePrototypesRel().SetTargets([mesh.GetPath()])
        instancer.CreateProtoIndicesAttr([0] * 12)
        instancer.CreatePositionsAttr([Gf.Vec3f(*row[:3, 3]) for row in rows])
        instancer.CreateScalesAttr([Gf.Vec3f(*np.linalg.norm(row[:3, :3], axis=0)) for row in rows])
    light = UsdLux.DistantLight.Define(stage, "/World/Sun")
    light.CreateIntensityAttr(3.0)
    UsdGeom.Xformable(light).AddRotateXOp().Set(-60.0)
    camera = UsdGeom.Camera.Define(stage, "/World/Camera")
    look = Gf.Matrix4d().SetLookAt(Gf.Vec3d(0, 9, 12), Gf.Vec3d(0, 0, 0), Gf.Vec3d(0, 1, 0)).GetInverse()
    UsdGeom.Xformable(camera).AddTransformOp().Set(look)
    stage.GetRootLayer().Save()
    return path


@pytest.mark.parametrize("instanceable", [False, True])
def test_usd_instancers_and_instanceable_prims_place_one_mesh(tmp_path, monkeypatch, pxr, instanceable):
    path = _usd_stage(tmp_path / "balls.usda", pxr, instanceable)
    scene, settings = load_scene(str(path), **SIZE)
    assert len(scene.instances) == 12 and len(scene.faces) == 2 + 80
    names = scene.object_names[1:]
    assert names[0] == ("/World/Ball0/Ball" if instanceable else "/World/Balls/Prototypes/Ball[0]")
    monkeypatch.setattr(instances, "MIN_TRIANGLES", 10 ** 9)  # copied, as before instancing
    copies, _ = load_scene(str(path), **SIZE)
    assert copies.instances is None and len(copies.faces) == 2 + 12 * 80
    np.testing.assert_allclose(scene.bounds, copies.bounds, rtol=0, atol=1e-9)
    _same_image(scene, settings, copies)


def test_nested_usd_instancing_is_multiplied_out_to_one_level(tmp_path, monkeypatch, pxr):
    from pxr import Gf, Sdf, Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(tmp_path / "nested.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    ball = trimesh.creation.icosphere(1, radius=0.3)  # 80 triangles

    def ball_at(path):
        mesh = UsdGeom.Mesh.Define(stage, path)
        mesh.CreatePointsAttr([Gf.Vec3f(*p) for p in ball.vertices])
        mesh.CreateFaceVertexCountsAttr([3] * len(ball.faces))
        mesh.CreateFaceVertexIndicesAttr(ball.faces.ravel().tolist())

    # three instanceable rows, each a point instancer of five balls
    stage.DefinePrim("/Rows", "Xform").SetSpecifier(Sdf.SpecifierClass)
    row = UsdGeom.PointInstancer.Define(stage, "/Rows/Row")
    ball_at("/Rows/Row/Prototypes/Ball")
    row.CreatePrototypesRel().SetTargets(["/Rows/Row/Prototypes/Ball"])
    row.CreateProtoIndicesAttr([0] * 5)
    row.CreatePositionsAttr([Gf.Vec3f(i, 0, 0) for i in range(5)])
    for j in range(3):
        holder = UsdGeom.Xform.Define(stage, f"/World/Row{j}")
        holder.AddTranslateOp().Set(Gf.Vec3d(0, 0, 2 * j))
        holder.GetPrim().GetReferences().AddInternalReference("/Rows")
        holder.GetPrim().SetInstanceable(True)
    # a point instancer of four instanceable prims
    stage.DefinePrim("/Balls", "Xform").SetSpecifier(Sdf.SpecifierClass)
    ball_at("/Balls/Ball")
    instancer = UsdGeom.PointInstancer.Define(stage, "/World/Instancer")
    prototype = UsdGeom.Xform.Define(stage, "/World/Instancer/Prototypes/Holder")
    prototype.GetPrim().GetReferences().AddInternalReference("/Balls")
    prototype.GetPrim().SetInstanceable(True)
    instancer.CreatePrototypesRel().SetTargets([prototype.GetPath()])
    instancer.CreateProtoIndicesAttr([0] * 4)
    instancer.CreatePositionsAttr([Gf.Vec3f(i, 3, 0) for i in range(4)])
    stage.GetRootLayer().Save()
    scene, _ = load_scene(str(tmp_path / "nested.usda"), width=16, height=12)
    assert len(scene.instances) == 3 * 5 + 4 and len(scene.faces) == 2 * 80
    monkeypatch.setattr(instances, "MIN_TRIANGLES", 10 ** 9)
    copies, _ = load_scene(str(tmp_path / "nested.usda"), width=16, height=12)
    assert len(copies.faces) == 19 * 80
    np.testing.assert_allclose(scene.bounds, copies.bounds, rtol=0, atol=1e-9)
    np.testing.assert_allclose(scene.bounds, [[-0.3, -0.3, -0.3], [4.3, 3.3, 4.3]], atol=1e-6)
