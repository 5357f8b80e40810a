"""Importing meshes and materials with trimesh: MTL mapping, real files, transforms."""

import os
import re
import shutil

import numpy as np
import pytest
import trimesh
import scenes

from rtmesh.core.errors import MeshError
from rtmesh.loaders.importers import load_mesh_scene, load_trimesh
from rtmesh.loaders.trimesh_materials import material_from_trimesh
from rtmesh.loaders.trimesh_parts import parts_from_trimesh

DATA = scenes.DATA
TRIANGLE_OBJ = "mtllib m.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def mtl_material(tmp_path, statements):
    (tmp_path / "m.mtl").write_text("newmtl m\n" + statements + "\n")
    (tmp_path / "t.obj").write_text(TRIANGLE_OBJ)
    scene = load_trimesh(tmp_path / "t.obj")
    mesh = next(iter(scene.geometry.values()))
    return material_from_trimesh(mesh.visual, "t")


def test_mtl_colours_keep_full_precision(tmp_path):
    m = mtl_material(tmp_path, "Kd 0.123 0.456 0.789\nKa 0.01 0.02 0.03\nKs 0.3 0.3 0.3\nNs 77\nKe 0.5 0 0\nillum 2")
    np.testing.assert_array_equal(m.diffuse, [0.123, 0.456, 0.789])
    np.testing.assert_array_equal(m.ambient, [0.01, 0.02, 0.03])
    np.testing.assert_array_equal(m.specular, [0.3, 0.3, 0.3])
    np.testing.assert_array_equal(m.emission, [0.5, 0, 0])
    assert m.shininess == 77
    assert not m.mirror.any() and not m.transmission.any()


@pytest.mark.parametrize(
    "illum, specular, mirror, transmission",
    [(0, False, False, False), (1, False, False, False), (2, True, False, False),
     (3, True, True, False), (5, True, True, False), (6, True, True, True), (7, True, True, True)],
)
def test_mtl_illum_models(tmp_path, illum, specular, mirror, transmission):
    m = mtl_material(tmp_path, f"Kd 0.5 0.5 0.5\nKs 0.4 0.4 0.4\nNi 1.33\nillum {illum}")
    assert m.specular.any() == specular
    assert m.mirror.any() == mirror
    assert m.transmission.any() == transmission
    if mirror:
        np.testing.assert_array_equal(m.mirror, [0.4] * 3)  # reflection weighted by Ks
    if transmission:
        assert m.ior == 1.33
    # illum 0 is "colour on, lighting off": Kd shown as is, and not an emitter that would
    # light the rest of the scene
    assert m.unlit == (illum == 0)
    np.testing.assert_array_equal(m.diffuse, [0.5] * 3)
    assert not m.emission.any()


@pytest.mark.parametrize(
    "statements, illum, transmission",
    [("d 1.0", 4, 0.0), ("d 0.25", 4, 0.75), ("Tr 0.25", 4, 0.25), ("Tr 1.0", 4, 0.0),
     ("d 1.0\nTr 0.5", 4, 0.0), ("Tf 0.2 0.4 0.6\nd 0.5", 4, [0.1, 0.2, 0.3]),
     ("Tf 0.2 0.4 0.6", 6, [0.2, 0.4, 0.6]), ("", 7, 1.0), ("d 0.5", 2, 0.0)],
)
def test_mtl_opacity_and_glass_transmission(tmp_path, statements, illum, transmission):
    # illum 4 lets 1 - opacity through (d wins over Tr; "Tr 1" alone reads as opaque because
    # exporters disagree on its meaning); illum 6/7 refract with weight Tf (default 1)
    m = mtl_material(tmp_path, f"{statements}\nillum {illum}")
    np.testing.assert_allclose(m.transmission, np.broadcast_to(transmission, 3))


def test_glb_scene_graph_keeps_node_transforms():
    box = trimesh.creation.box(extents=[1, 1, 1])
    scene = trimesh.Scene()
    scene.add_geometry(box, node_name="a", transform=trimesh.transformations.translation_matrix([5, 0, 0]))
    nested = trimesh.transformations.translation_matrix([0, 3, 0]) @ trimesh.transformations.scale_matrix(2.0)
    scene.add_geometry(box, node_name="b", transform=nested)
    parts, materials = parts_from_trimesh(scene)
    bounds = {p.name: (p.vertices.min(axis=0), p.vertices.max(axis=0)) for p in parts}
    np.testing.assert_allclose(bounds["a"][0], [4.5, -0.5, -0.5])
    np.testing.assert_allclose(bounds["b"][0], [-1, 2, -1])
    np.testing.assert_allclose(bounds["b"][1], [1, 4, 1])


def test_mirroring_transform_keeps_faces_outward():
    box = trimesh.creation.box(extents=[1, 1, 1])
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    (p,), _ = parts_from_trimesh(box, transform=mirror, smooth=False)
    tri = p.vertices[p.faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    outward = (normals * (tri.mean(axis=1) - p.vertices.mean(axis=0))).sum(axis=1)
    assert (outward > 0).all()


@pytest.mark.parametrize("name, message", [("empty.obj", "nothing to render")])
def test_broken_files_fail_with_a_clear_error(name, message):
    with pytest.raises(MeshError, match=message):
        load_mesh_scene(os.path.join(DATA, name))


def test_nan_vertex_faces_are_dropped_with_a_warning(caplog):
    # nancolor.obj has a NaN colour but finite vertices; put a NaN into a copy's vertices
    mesh = trimesh.creation.box()
    vertices = mesh.vertices.copy()
    vertices[0] = np.nan
    broken = trimesh.Trimesh(vertices, mesh.faces, process=False)
    with caplog.at_level("WARNING"):
        from rtmesh.loaders.importers import scene_from_trimesh
        scene = scene_from_trimesh(broken)
    assert "NaN/Inf" in caplog.text
    assert np.isfinite(scene.vertices).all()
    assert len(scene.faces) == 12 - (mesh.faces == 0).any(axis=1).sum()


def test_truncated_glb_is_a_one_line_error(tmp_path):
    source = os.path.join(scenes.ASSETS, "meshes", "bunny.ply")
    broken = tmp_path / "broken.ply"
    shutil.copy(source, broken)
    with open(broken, "r+b") as f:
        f.truncate(2000)
    with pytest.raises(MeshError, match="broken.ply"):
        load_mesh_scene(broken)


# ---------------------------------------------------------------- hostile and unusual files

import json  # noqa: E402
import logging  # noqa: E402

import hostile_files  # noqa: E402

from rtmesh.api import load_scene  # noqa: E402
from rtmesh.rendering.integrator import Integrator


def _write(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    return path


def test_nan_and_inf_vertices_drop_only_their_faces_and_say_how_many(tmp_path, caplog):
    path = _write(tmp_path, "nan.obj", hostile_files.corpus()["nan_vertices.obj"])
    with caplog.at_level(logging.WARNING):
        parts, _ = parts_from_trimesh(load_trimesh(path))
    # corners 0 (NaN) and 3 (inf) of the cube: the faces using either go, the rest stay
    bad = np.isin(hostile_files.CUBE_FACES, [0, 3]).any(axis=1)
    assert sum(len(p.faces) for p in parts) == 12 - bad.sum() == 4
    assert f"dropped {bad.sum()} of 12 faces that use vertices with NaN or infinite coordinates (2 such vertices)" \
        in caplog.text
    assert "vertex colours" not in caplog.text


def test_nan_vertex_colours_are_reported_as_colours(caplog):
    with caplog.at_level(logging.WARNING):
        parts, _ = parts_from_trimesh(load_trimesh(os.path.join(DATA, "nancolor.obj")))
    assert "vertex colours hold NaN values" in caplog.text and "faces" not in caplog.text
    assert parts[0].vertex_colors is None


@pytest.mark.parametrize("scale, offset", [(1e11, 0.0), (1e-9, 0.0), (1e-9, 1e-3), (1.0, 1e7)])
def test_a_cube_at_any_scale_keeps_its_triangles_and_renders(tmp_path, scale, offset):
    path = _write(tmp_path, "cube.obj", hostile_files.cube_obj(scale, offset))
    mesh = next(iter(load_trimesh(path).geometry.values()))
    assert len(mesh.faces) == 12 and len(mesh.vertices) == 8
    scene, settings = load_scene(path, width=24, height=18, spp=1, threads=1)
    assert len(scene.faces) == 12
    image = Integrator(scene, settings).render().image
    # framed and lit like the unit cube: the same image whatever the scale
    unit, unit_settings = load_scene(_write(tmp_path, "unit.obj", hostile_files.cube_obj()),
                                     width=24, height=18, spp=1, threads=1)
    np.testing.assert_allclose(image, Integrator(unit, unit_settings).render().image, atol=1e-3)


@pytest.mark.parametrize("name", ["fuze.obj", "rabbit.obj", "fandisk.obj", "quadknot.obj", "textured_tetrahedron.obj"])
def test_vertex_merge_equals_trimeshs_on_ordinary_files(name):
    # rtmesh's merge (relative to scale, without trimesh's int64 conversion) keeps what
    # trimesh keeps at ordinary scales: same vertices, same faces
    ours = [g for g in load_trimesh(os.path.join(DATA, name)).geometry.values()]
    theirs = [g for g in trimesh.load(os.path.join(DATA, name), force="scene").geometry.values()]
    assert len(ours) == len(theirs)
    for a, b in zip(ours, theirs):
        np.testing.assert_array_equal(a.vertices, b.vertices)
        np.testing.assert_array_equal(a.faces, b.faces)


def test_a_concave_polygon_is_ear_clipped_not_fanned(tmp_path):
    path = _write(tmp_path, "wall.obj", hostile_files.wall_with_door_obj())
    parts, _ = parts_from_trimesh(load_trimesh(path), smooth=False)
    v, f = parts[0].vertices, parts[0].faces
    assert len(f) == len(hostile_files.WALL_CORNERS) - 2
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    # the wall's area without the door (9 - 2), every triangle wound like the face (+z)
    assert 0.5 * np.linalg.norm(cross, axis=1).sum() == pytest.approx(7.0)
    assert (cross[:, 2] > 0).all()
    # no triangle covers the middle of the door opening
    p = np.array([1.5, 1.0])
    a, b, c = (v[f[:, k], :2] for k in range(3))

    def side(p0, p1):
        return np.sign((p1[:, 0] - p0[:, 0]) * (p[1] - p0[:, 1]) - (p1[:, 1] - p0[:, 1]) * (p[0] - p0[:, 0]))
    inside = (side(a, b) == side(b, c)) & (side(b, c) == side(c, a))
    assert not inside.any()
    # texture coordinates follow their corners
    np.testing.assert_allclose(parts[0].uv, v[:, :2] / 3.0)


def test_negative_polygon_indices_refer_back_from_the_statement(tmp_path):
    text = "v 9 9 9\n" + "".join(f"v {x} {y} 0\n" for x, y in hostile_files.WALL_CORNERS)
    text += "f " + " ".join(str(-8 + i) for i in range(8)) + "\n"
    parts, _ = parts_from_trimesh(load_trimesh(_write(tmp_path, "w.obj", text)), smooth=False)
    v, f = parts[0].vertices, parts[0].faces
    assert len(f) == 6 and not (v[np.unique(f)] == 9).any()


def test_a_gltf_node_cycle_is_one_error_naming_the_nodes(tmp_path, caplog):
    path = _write(tmp_path, "node_cycle.gltf", hostile_files.corpus()["node_cycle.gltf"])
    with caplog.at_level(logging.WARNING), pytest.raises(MeshError) as caught:
        load_scene(path, width=16, height=12, spp=1)
    assert str(caught.value) == (f"{path}: 2 nodes form a cycle: 'a' -> 'b' -> 'a' (glTF forbids cycles in "
                                 "the node graph)")
    assert not caplog.records
    # a longer cycle below a root, and nodes without names
    nodes = [{"name": "root", "children": [1]}, {"mesh": 0, "children": [2]}, {"name": "c", "children": [3]},
             {"name": "d", "children": [1]}]
    path = _write(tmp_path, "long_cycle.gltf", json.dumps(hostile_files.gltf_cube(nodes, [0])))
    with pytest.raises(MeshError, match=re.escape("3 nodes form a cycle: nodes[1] -> 'c' -> 'd' -> nodes[1]")):
        load_mesh_scene(path)


def test_hidden_nodes_are_one_warning_for_the_file_and_the_rest_renders(tmp_path, caplog):
    path = _write(tmp_path, "zero_scale.gltf", hostile_files.corpus()["zero_scale.gltf"])
    with caplog.at_level(logging.WARNING):
        scene, settings = load_scene(path, width=16, height=12, spp=1)
    assert [r.getMessage() for r in caplog.records] == [
        f"{path}: node 'hidden' has a zero scale (a singular transform, which hides it) or a non-finite one; "
        "not rendered"]
    assert len(scene.faces) == 12  # the other node's cube
    assert Integrator(scene, settings).render().image.max() > 0
    caplog.clear()
    nodes = [{"name": f"n{i}", "mesh": 0, "scale": [0, 0, 0]} for i in range(9)] + [{"name": "shown", "mesh": 0}]
    path = _write(tmp_path, "nine_hidden.gltf", json.dumps(hostile_files.gltf_cube(nodes, list(range(10)))))
    with caplog.at_level(logging.WARNING):
        scene, _ = load_scene(path, width=16, height=12, spp=1)
    assert [r.getMessage() for r in caplog.records] == [
        f"{path}: 9 nodes ('n0', 'n1', 'n2', 'n3', 'n4' and 4 more) have a zero scale (a singular transform, "
        "which hides it) or a non-finite one; not rendered"]
    assert len(scene.faces) == 12


@pytest.mark.parametrize("name, message", [
    ("garbage.obj", "not a valid OBJ file (binary data, not text)"),
    ("garbage.glb", "not a valid GLB file (no glTF header)"),
    ("garbage.ply", "not a valid PLY file (no 'ply' header)"),
    ("garbage.stl", "not a valid STL file (not ASCII, and its binary header announces"),
    ("lying_count.stl", "announces 1000 triangles (50084 bytes) in a file of 584 bytes"),
    ("missing_buffer.gltf", "buffer file gone.bin not found"),
    ("index_out_of_range.obj", "a face refers to a vertex the file does not have"),
    ("corrupt_texture.glb", "square baseColorTexture: corrupt or unreadable texture"),
])
def test_malformed_files_are_one_clear_error(tmp_path, name, message):
    path = _write(tmp_path, name, hostile_files.corpus()[name])
    with pytest.raises(MeshError, match=re.escape(message)):
        load_mesh_scene(path)


def test_directories_symlink_loops_and_broken_links_are_named_as_such(tmp_path):
    (tmp_path / "folder.obj").mkdir()
    os.symlink(tmp_path / "loop.obj", tmp_path / "loop.obj")
    os.symlink(tmp_path / "gone.obj", tmp_path / "dangling.obj")
    for name, message in (("folder.obj", "is a directory, not a mesh file"),
                          ("loop.obj", "symbolic link loop"),
                          ("dangling.obj", "broken symbolic link"),
                          ("absent.obj", "no such mesh file")):
        with pytest.raises(MeshError, match=message):
            load_trimesh(tmp_path / name)


def test_garbage_mtl_values_are_warned_once_per_file_with_key_and_line(tmp_path, caplog):
    corpus = hostile_files.corpus()
    _write(tmp_path, "garbage.mtl", corpus["garbage.mtl"])
    path = _write(tmp_path, "m.obj", corpus["garbage_mtl.obj"])
    with caplog.at_level(logging.WARNING):
        _, materials = parts_from_trimesh(load_trimesh(path))
    records = [r.getMessage() for r in caplog.records if "garbage.mtl" in r.getMessage()]
    assert len(records) == 1
    for fragment in ("line 2: kd 'abc 1 zz'", "line 3: ns '-inf'", "line 4: illum '99'", "line 5: ke 'nan 1 1'"):
        assert fragment in records[0]
    # the defaults: grey diffuse, Blinn-Phong, no emission
    np.testing.assert_array_equal(materials[0].diffuse, np.full(3, 0.7))
    assert not materials[0].emission.any() and not materials[0].unlit


@pytest.fixture(scope="module")
def big_png(tmp_path_factory):
    path = tmp_path_factory.mktemp("big") / "big.png"
    hostile_files.write_big_png(path)  # 20000 x 20000, a few hundred KB
    return path


def test_a_texture_too_large_is_one_line_naming_it(tmp_path, big_png):
    import shutil as _shutil

    _shutil.copy(big_png, tmp_path / "big.png")
    (tmp_path / "m.mtl").write_text("newmtl m\nmap_Kd big.png\n")
    (tmp_path / "t.obj").write_text(TRIANGLE_OBJ.replace("f 1 2 3", "vt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3"))
    with pytest.raises(MeshError, match=r"big.png: texture of 400000000 pixels is larger than rtmesh reads "
                                        r"\(67108864 pixels, e.g. 8192x8192\): downsample it"):
        load_mesh_scene(tmp_path / "t.obj")
    glb = _write(tmp_path, "big.glb", hostile_files.textured_square_glb(big_png.read_bytes()))
    with pytest.raises(MeshError, match="paint.png: corrupt or unreadable texture, or one of more than 89478485 pixels"):
        load_mesh_scene(glb)


def test_a_texture_below_pils_limit_but_above_rtmeshs_is_refused_before_decoding(tmp_path):
    from rtmesh.io.texture_images import load_texture

    path = tmp_path / "wide.png"
    path.write_bytes(hostile_files.png_bytes(70000, 1000))  # 70 M pixels
    with pytest.raises(MeshError, match=r"wide.png: texture of 70000x1000 pixels is larger than rtmesh reads"):
        load_texture(str(path))


def test_faces_far_from_the_rest_are_dropped_with_a_warning_not_a_black_image(tmp_path, caplog):
    path = _write(tmp_path, "far.obj", hostile_files.corpus()["far_outlier.obj"])
    with caplog.at_level(logging.WARNING):
        scene, settings = load_scene(path, width=24, height=18, spp=1, threads=1)
    assert "dropped 12 of 24 faces that lie far from the rest (the scene spans 1.1e+30, the rest 2)" in caplog.text
    assert len(scene.faces) == 12
    unit, unit_settings = load_scene(_write(tmp_path, "unit.obj", hostile_files.cube_obj()),
                                     width=24, height=18, spp=1, threads=1)
    np.testing.assert_array_equal(Integrator(scene, settings).render().image,
                                  Integrator(unit, unit_settings).render().image)


def test_ordinary_scenes_are_framed_whole():
    from rtmesh.scene.camera import framing_bounds

    cube_v, cube_f = hostile_files.CUBE_VERTICES, hostile_files.CUBE_FACES
    dome = trimesh.creation.icosphere(subdivisions=2, radius=1e4)
    scenes = {
        "a row of cubes": [cube_v + [10.0 * i, 0, 0] for i in range(5)],
        "a figure in a sky dome": [cube_v, dome.vertices],
        "a model and a far one of its size": [cube_v, cube_v + [1e5, 0, 0]],
        "a flat card above a flat floor": [cube_v * [3, 3, 0], cube_v * [1, 1, 0] + [0, 0, 1]],
    }
    for name, pieces in scenes.items():
        faces = [cube_f if len(p) == 8 else dome.faces for p in pieces]
        offsets = np.cumsum([0] + [len(p) for p in pieces[:-1]])
        vertices = np.vstack(pieces)
        all_faces = np.vstack([f + o for f, o in zip(faces, offsets)])
        bounds, keep = framing_bounds(vertices, all_faces)
        assert keep is None, name
        np.testing.assert_array_equal(bounds, [vertices.min(axis=0), vertices.max(axis=0)])


def test_a_malformed_bump_strength_is_warned_and_reads_as_one(tmp_path, caplog):
    shutil.copy(os.path.join(DATA, "fuze uv.jpg"), tmp_path / "h.jpg")
    (tmp_path / "m.mtl").write_text("newmtl m\nbump -bm abc h.jpg\n")
    (tmp_path / "t.obj").write_text(TRIANGLE_OBJ.replace("f 1 2 3", "vt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3"))
    with caplog.at_level(logging.WARNING):
        _, materials = parts_from_trimesh(load_trimesh(tmp_path / "t.obj"))
    assert "m.mtl: malformed values ignored, defaults used: line 2: bump -bm 'abc' (expected a number)" in caplog.text
    (tmp_path / "m.mtl").write_text("newmtl m\nbump -bm 1 h.jpg\n")
    _, same = parts_from_trimesh(load_trimesh(tmp_path / "t.obj"))
    np.testing.assert_array_equal(materials[0].normal_texture.pixels, same[0].normal_texture.pixels)


def test_coordinates_beyond_float32_drop_their_faces_with_a_count(tmp_path, caplog):
    text = hostile_files.cube_obj().replace("v -1.0 -1.0 -1.0", "v -1e50 -1.0 -1.0", 1)
    with caplog.at_level(logging.WARNING):
        scene, settings = load_scene(_write(tmp_path, "c.obj", text), width=16, height=12, spp=1)
    dropped = int(np.isin(hostile_files.CUBE_FACES, [0]).any(axis=1).sum())
    assert f"dropped {dropped} faces with coordinates beyond float32's range" in caplog.text
    assert len(scene.faces) == 12 - dropped
    assert np.isfinite(Integrator(scene, settings).render().image).all()


def test_a_truncated_vertex_statement_is_one_clear_error(tmp_path):
    text = hostile_files.cube_obj() + "v 0.5 0.25\n"
    with pytest.raises(MeshError, match=r"vertices of 2 coordinates, not 3 \(a vertex statement with too few"):
        load_mesh_scene(_write(tmp_path, "c.obj", text))


def test_gltf_faces_with_indices_beyond_the_vertices_are_dropped_with_a_count(tmp_path, caplog):
    import json

    faces = hostile_files.CUBE_FACES.copy()
    faces[0, 1] = 99
    doc = hostile_files.gltf_cube([{"name": "cube", "mesh": 0}], [0], faces)
    path = _write(tmp_path, "c.gltf", json.dumps(doc))
    with caplog.at_level(logging.WARNING):
        scene, settings = load_scene(path, width=16, height=12, spp=1)
    assert "dropped 1 of 12 faces that refer to vertices the file does not have" in caplog.text
    assert len(scene.faces) == 11
    assert np.isfinite(Integrator(scene, settings).render().image).all()


def test_faces_dropped_in_many_objects_are_one_warning_a_kind(caplog):
    from rtmesh.scene.model import MeshPart, Scene

    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    degenerate = np.array([[0, 1, 2], [0, 2, 3], [0, 0, 1]])  # one zero-area face
    parts = [MeshPart(f"o{i}", square + [2 * i, 0, 0], degenerate) for i in range(7)]
    parts.append(MeshPart("flat", np.zeros((3, 3)), np.array([[0, 1, 2]])))
    with caplog.at_level(logging.WARNING):
        Scene.from_parts(parts, source="many.glb")
    assert [r.getMessage() for r in caplog.records] == [
        "many.glb: dropped 8 zero-area faces in 8 objects: 'o0' (1), 'o1' (1), 'o2' (1), 'o3' (1), 'o4' (1) "
        "and 3 more",
        "many.glb: object 'flat' has no renderable triangles; skipped"]
