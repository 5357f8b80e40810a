"""Importing meshes and materials with trimesh: MTL mapping, real files, transforms."""

import os
import shutil

import numpy as np
import pytest
import trimesh

from rtmesh.core.errors import MeshError
from rtmesh.loaders.importers import load_mesh_scene, load_trimesh, material_from_trimesh, parts_from_trimesh

DATA = os.path.join(os.path.dirname(__file__), "data")
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
    source = os.path.join(os.path.dirname(__file__), "..", "assets", "meshes", "bunny.ply")
    broken = tmp_path / "broken.ply"
    shutil.copy(source, broken)
    with open(broken, "r+b") as f:
        f.truncate(2000)
    with pytest.raises(MeshError, match="broken.ply"):
        load_mesh_scene(broken)
