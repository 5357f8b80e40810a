"""Hostile mesh files (session 28's sweep): each is one error line naming the file and the key
with exit status 2 and no image, or loads with rtmesh's own warnings only; no NumPy warning
(pytest turns a RuntimeWarning into an error) and no traceback.  Nothing here renders more
than a 24 x 18 image of a cube."""

import copy
import json
import logging
import struct

import hostile_files
import numpy as np
import pytest
import trimesh

from rtmesh.core.errors import MeshError
from rtmesh.loaders.gltf_checks import check_document
from rtmesh.loaders.importers import load_mesh_scene, load_trimesh
from rtmesh.loaders.trimesh_parts import parts_from_trimesh

SIZE = ("--width", "24", "--height", "18", "--spp", "1", "--threads", "1", "-q")


def render(cli, path, tmp_path):
    """(status, stderr, output path) of ``rtmesh render path``."""
    out = tmp_path / "out.png"
    code, _, err = cli("render", path, "-o", out, *SIZE)
    assert "Traceback" not in err and "internal error" not in err, err
    return code, err, out


def refused(cli, path, tmp_path):
    """The error line of a refused file (status 2, one line, no image, no temporary left)."""
    code, err, out = render(cli, path, tmp_path)
    assert code == 2, err
    assert len(err.splitlines()) == 1 and err.startswith("rtmesh: error: "), err
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == [path.name]
    return err


def write_gltf(tmp_path, doc):
    path = tmp_path / "m.gltf"
    path.write_text(json.dumps(doc))
    return path


def cube_doc():
    return hostile_files.gltf_cube([{"name": "c", "mesh": 0}], [0])


# ------------------------------------------------------------ glTF accessors and indices

def _textured(doc):
    doc["meshes"][0]["primitives"][0]["material"] = 0
    doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    doc["textures"] = [{"source": 0}]
    doc["images"] = [{"bufferView": 9, "mimeType": "image/png"}]


def _camera(doc):
    doc["nodes"].append({"camera": 5, "translation": [0, 0, 5]})
    doc["scenes"][0]["nodes"].append(1)
    doc["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.8}}]


def _set(key, value):
    """A mutation setting ``doc[a][i][b]... = value`` for ``key`` "a.i.b"."""
    *parents, last = key.split(".")

    def mutate(doc):
        target = doc
        for part in parents:
            target = target[int(part)] if part.isdigit() else target[part]
        target[int(last) if last.isdigit() else last] = value
    return mutate


# (mutation of the cube, the error after "FILE: ")
MALFORMED = {
    "position_vec2": (_set("accessors.0.type", "VEC2"),
                      "meshes[0].primitives[0].attributes.POSITION: accessors[0] is VEC2; positions must be 3D (VEC3)"),
    "normal_vec2": (lambda d: (d["accessors"].append({"bufferView": 0, "componentType": 5126, "count": 8,
                                                        "type": "VEC2"}),
                               d["meshes"][0]["primitives"][0]["attributes"].update(NORMAL=2)),
                    "meshes[0].primitives[0].attributes.NORMAL: accessors[2] is VEC2; normals must be 3D (VEC3)"),
    "indices_float": (_set("accessors.1.componentType", 5126),
                      "meshes[0].primitives[0].indices: accessors[1] holds SCALAR FLOAT values; indices must be "
                      "SCALAR UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT"),
    "component_type": (_set("accessors.0.componentType", 9999),
                       "accessors[0].componentType: 9999 is not a glTF component type (5120, 5121, 5122, 5123, "
                       "5125 or 5126)"),
    "accessor_type": (_set("accessors.0.type", "MAT9"),
                      'accessors[0].type: "MAT9" is not a glTF accessor type (SCALAR, VEC2, VEC3, VEC4, MAT2, '
                      "MAT3 or MAT4)"),
    "byte_offset_huge": (_set("bufferViews.0.byteOffset", 10**9),
                         "bufferViews[0]: bytes 1000000000 to 1000000096 lie beyond the end of buffers[0] (168 "
                         "bytes): a truncated file or a wrong byteOffset?"),
    "byte_offset_negative": (_set("bufferViews.0.byteOffset", -8),
                             "bufferViews[0].byteOffset: -8 is not an integer >= 0"),
    "byte_stride_huge": (_set("bufferViews.0.byteStride", 100000),
                         "bufferViews[0].byteStride: 100000 is not a glTF byte stride (a multiple of 4 from 4 to 252)"),
    "byte_stride_small": (_set("bufferViews.0.byteStride", 4),
                          "accessors[0]: VEC3 FLOAT elements of 12 bytes do not fit in the byteStride 4 of "
                          "bufferViews[0]"),
    "count_overflow": (_set("accessors.0.count", 800),
                       "accessors[0]: 800 VEC3 elements of 12 bytes from byte 0 need 9600 bytes; bufferViews[0] "
                       "holds 96"),
    "indices_not_triangles": (_set("accessors.1.count", 35),
                              "meshes[0].primitives[0].indices: 35 indices do not make whole triangles (not a "
                              "multiple of 3)"),
    "scene": (_set("scene", 4), "scene: 4 refers to no scene (the file has 1 scene)"),
    "scene_node": (_set("scenes.0.nodes.0", 5), "scenes[0].nodes[0]: 5 refers to no node (the file has 1 node)"),
    "node_mesh": (_set("nodes.0.mesh", 3), "nodes[0].mesh: 3 refers to no mesh (the file has 1 mesh)"),
    "camera": (_camera, "nodes[1].camera: 5 refers to no camera (the file has 1 camera)"),
    "material": (_set("meshes.0.primitives.0.material", 3),
                 "meshes[0].primitives[0].material: 3 refers to no material (the file has 0 materials)"),
    "buffer_view": (_set("accessors.0.bufferView", 7),
                    "accessors[0].bufferView: 7 refers to no buffer view (the file has 2 buffer views)"),
    "image_buffer_view": (_textured, "images[0].bufferView: 9 refers to no buffer view (the file has 2 buffer views)"),
    "texture": (lambda d: (_textured(d), d.pop("textures")),
                "materials[0].pbrMetallicRoughness.baseColorTexture.index: 0 refers to no texture (the file has 0 "
                "textures)"),
    "matrix_15": (_set("nodes.0.matrix", [1.0] * 15), "nodes[0].matrix: expected 16 numbers (got 15 values)"),
    "translation_string": (_set("nodes.0.translation", "abc"), 'nodes[0].translation: expected 3 numbers (got "abc")'),
    "mode": (_set("meshes.0.primitives.0.mode", 99),
             "meshes[0].primitives[0].mode: 99 is not a glTF primitive mode (0 to 6)"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_a_malformed_gltf_is_refused_naming_the_key(case, tmp_path):
    mutate, message = MALFORMED[case]
    doc = cube_doc()
    mutate(doc)
    path = write_gltf(tmp_path, doc)
    with pytest.raises(MeshError) as caught:
        load_trimesh(path)
    assert str(caught.value) == f"{path}: {message}"


@pytest.mark.parametrize("case", ["position_vec2", "component_type", "camera"])
def test_a_malformed_gltf_on_the_command_line_is_one_line(case, cli, tmp_path):
    mutate, message = MALFORMED[case]
    doc = cube_doc()
    mutate(doc)
    path = write_gltf(tmp_path, doc)
    assert refused(cli, path, tmp_path) == f"rtmesh: error: {path}: {message}\n"


def test_a_truncated_glb_names_its_buffer_view(tmp_path):
    doc = cube_doc()
    binary = hostile_files.CUBE_VERTICES.astype("<f4").tobytes() + hostile_files.CUBE_FACES.astype("<u2").tobytes()
    del doc["buffers"][0]["uri"]
    data = hostile_files.glb_bytes(doc, binary)
    # the binary chunk says 168 bytes; the file ends 40 bytes into the indices
    path = tmp_path / "m.glb"
    path.write_bytes(data[:len(data) - len(binary) + 136])
    with pytest.raises(MeshError, match=r"m\.glb: bufferViews\[1\]: bytes 96 to 168 lie beyond the end of "
                                        r"buffers\[0\] \(136 bytes\)"):
        load_trimesh(path)


def test_well_formed_gltf_files_pass_the_check_unchanged(tmp_path):
    # the cube, a textured GLB, and a file of 10000 nodes (one pass over the JSON)
    doc = cube_doc()
    before = copy.deepcopy(doc)
    check_document("cube.gltf", doc)
    assert doc == before
    path = tmp_path / "square.glb"
    path.write_bytes(hostile_files.textured_square_glb(hostile_files.png_bytes(4, 4)))
    assert len(load_trimesh(path).geometry) == 1
    many = hostile_files.gltf_cube([{"name": f"n{i}", "mesh": 0, "translation": [3.0 * i, 0, 0]}
                                    for i in range(10000)], list(range(10000)))
    check_document("many.gltf", many)


def test_a_2d_mesh_given_to_parts_from_trimesh_is_a_mesh_error():
    mesh = trimesh.Trimesh(vertices=[[0, 0], [1, 0], [0, 1]], faces=[[0, 1, 2]], process=False)
    with pytest.raises(MeshError, match=r"^flat: node 'flat': vertices of 2 coordinates; positions must be 3D$"):
        parts_from_trimesh(mesh, "flat")


# ------------------------------------------------------------ PLY with NaN

PLY_UV_NAN = """ply
format ascii 1.0
element vertex 3
property float x
property float y
property float z
property float s
property float t
element face 1
property list uchar int vertex_indices
end_header
0 0 0 nan inf
1 0 0 1 0
0 1 0 0 1
3 0 1 2
"""


def all_nan_ply():
    header = ("ply\nformat binary_little_endian 1.0\nelement vertex 8\nproperty float x\nproperty float y\n"
              "property float z\nelement face 12\nproperty list uchar int vertex_indices\nend_header\n").encode()
    faces = b"".join(struct.pack("<B3i", 3, *f) for f in hostile_files.CUBE_FACES.tolist())
    return header + np.full((8, 3), np.nan, "<f4").tobytes() + faces


def test_nan_texture_coordinates_in_a_ply_are_one_warning_and_no_numpy_warning(cli, tmp_path):
    path = tmp_path / "m.ply"
    path.write_text(PLY_UV_NAN)
    code, err, out = render(cli, path, tmp_path)
    assert code == 0 and out.exists()
    assert err == f"rtmesh: warning: {path}: object 'm.ply': 1 non-finite texture coordinates replaced by 0\n"


def test_the_numpy_error_state_is_restored_after_a_load(tmp_path):
    path = tmp_path / "m.ply"
    path.write_text(PLY_UV_NAN)
    before = np.geterr()
    load_trimesh(path)
    assert np.geterr() == before


def test_a_ply_of_nan_vertices_only_is_one_line(cli, tmp_path):
    path = tmp_path / "m.ply"
    path.write_bytes(all_nan_ply())
    assert refused(cli, path, tmp_path) == (
        f"rtmesh: error: {path}: nothing to render (no triangles); while loading: dropped 12 of 12 faces that "
        "use vertices with NaN or infinite coordinates (8 such vertices)\n")


# ------------------------------------------------------------ OBJ with a byte order mark, OFF

def test_an_obj_with_a_utf8_byte_order_mark_loads(cli, tmp_path):
    path = tmp_path / "m.obj"
    path.write_bytes(b"\xef\xbb\xbf" + hostile_files.cube_obj().replace("\n", "\r\n").encode())
    (geometry,) = load_trimesh(path).geometry.values()
    assert geometry.vertices.shape == (8, 3) and len(geometry.faces) == 12
    code, err, out = render(cli, path, tmp_path)
    assert code == 0 and err == "" and out.exists()


def test_an_off_face_index_out_of_range_is_refused_as_the_docs_say(cli, tmp_path):
    # docs/LIMITS.md: trimesh refuses such an OBJ or OFF file (PLY and glTF drop the faces)
    path = tmp_path / "m.off"
    path.write_text("OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 9\n")
    assert refused(cli, path, tmp_path) == (
        f"rtmesh: error: {path}: cannot read mesh: OFF file has a face index outside the range of its vertices\n")


# ------------------------------------------------------------ warnings of a load that fails

def test_a_load_that_fails_shows_one_line_with_its_first_warning(cli, tmp_path):
    path = tmp_path / "m.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 0 0\nf 1 2 3\nf 1 4 2\nf 1 1 1\n")
    assert refused(cli, path, tmp_path) == (
        f"rtmesh: error: {path}: nothing to render (no non-degenerate triangles with finite vertices); while "
        "loading: object 'm.obj': dropped 3 zero-area faces (and 1 more warning)\n")


def test_a_load_that_succeeds_shows_its_warnings(cli, tmp_path):
    path = tmp_path / "m.obj"
    vertices = hostile_files.CUBE_VERTICES.copy()
    vertices[0] = np.nan
    path.write_text(hostile_files.obj_text(vertices, hostile_files.CUBE_FACES))
    code, err, out = render(cli, path, tmp_path)
    assert code == 0 and out.exists()
    assert err == ("rtmesh: warning: m.obj: dropped 6 of 12 faces that use vertices with NaN or infinite "
                   "coordinates (1 such vertices)\n")


def test_holding_the_warnings_leaves_the_logging_configuration_as_it_was(cli, tmp_path):
    """rtmesh render holds its load's warnings (rtmesh.cli._load_warnings_held) and puts the
    logging set-up back, after a load that succeeds and one that fails; the Python API logs
    as it goes."""
    root = logging.getLogger()
    before = list(root.handlers)
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    good, bad = tmp_path / "a" / "good.obj", tmp_path / "b" / "bad.obj"
    vertices = hostile_files.CUBE_VERTICES.copy()
    vertices[0] = np.nan
    good.write_text(hostile_files.obj_text(vertices, hostile_files.CUBE_FACES))
    bad.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    assert render(cli, good, tmp_path / "a")[0] == 0
    assert list(root.handlers) == before
    assert refused(cli, bad, tmp_path / "b").startswith(f"rtmesh: error: {bad}: nothing to render")
    assert list(root.handlers) == before
    with pytest.raises(MeshError, match="nothing to render"):
        load_mesh_scene(bad)
