"""Writers of malformed, hostile or unusual input files for the tests.

``python tests/hostile_files.py`` regenerates the small corpus in ``tests/data/bad/``
(:func:`write_corpus`); large files (a 20000 x 20000 PNG) are written at test time by
:func:`write_big_png`, which streams the image so that nothing of its size is held in
memory.
"""

import copy
import io
import json
import os
import struct
import zlib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
BAD = os.path.join(HERE, "data", "bad")

# a unit cube: 8 corners, 12 outward triangles (1-based for OBJ)
CUBE_VERTICES = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
CUBE_FACES = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                       [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])


def obj_text(vertices, faces, header=""):
    """OBJ text of a triangle mesh (0-based faces), with ``repr`` precision."""
    lines = [header] if header else []
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(vertices, dtype=float).tolist()]
    lines += ["f " + " ".join(str(i + 1) for i in face) for face in faces]
    return "\n".join(lines) + "\n"


def cube_obj(scale=1.0, offset=0.0):
    return obj_text(CUBE_VERTICES * scale + offset, CUBE_FACES)


# a wall 3 wide and 3 high with a door 1 wide and 2 high, as one face of 8 corners
WALL_CORNERS = [(0, 0), (1, 0), (1, 2), (2, 2), (2, 0), (3, 0), (3, 3), (0, 3)]


def wall_with_door_obj():
    lines = [f"v {x} {y} 0" for x, y in WALL_CORNERS] + [f"vt {x / 3} {y / 3}" for x, y in WALL_CORNERS]
    lines.append("f " + " ".join(f"{i + 1}/{i + 1}" for i in range(len(WALL_CORNERS))))
    return "\n".join(lines) + "\n"


def gltf_cube(nodes, scene_nodes, faces=CUBE_FACES):
    """A .gltf document (embedded buffer) of the cube, with the given nodes; mesh 0 is it
    (``faces``: its triangles, any indices)."""
    positions = CUBE_VERTICES.astype("<f4").tobytes()
    indices = np.asarray(faces).astype("<u2").tobytes()
    data = positions + indices
    uri = "data:application/octet-stream;base64," + __import__("base64").b64encode(data).decode()
    return {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": scene_nodes}],
        "nodes": nodes,
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": len(data), "uri": uri}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(positions)},
                        {"buffer": 0, "byteOffset": len(positions), "byteLength": len(indices)}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3",
             "min": [-1, -1, -1], "max": [1, 1, 1]},
            {"bufferView": 1, "componentType": 5123, "count": 36, "type": "SCALAR"},
        ],
    }


def glb_bytes(doc, binary=b""):
    """A GLB container of a JSON document and a binary chunk."""
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    if binary:
        chunks += struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(chunks)) + chunks


def _png_chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_bytes(width, height, rows=None):
    """A grey 8-bit PNG; ``rows`` yields its filtered rows in blocks (default black)."""
    z = zlib.compressobj(9)
    body = []
    row = b"\0" * (width + 1)
    for start in range(0, height, 256):
        body.append(z.compress(row * min(256, height - start)))
    body.append(z.flush())
    return (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
            + _png_chunk(b"IDAT", b"".join(body)) + _png_chunk(b"IEND", b""))


def write_big_png(path, width=20000, height=20000):
    """A valid black PNG of ``width x height`` pixels (a few hundred KB on disk)."""
    with open(path, "wb") as f:
        f.write(png_bytes(width, height))


def textured_square_glb(image):
    """A GLB of one textured square whose base-colour texture is the PNG bytes ``image``."""
    positions = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype="<f4").tobytes()
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype="<f4").tobytes()
    indices = np.array([0, 1, 2, 0, 2, 3], dtype="<u2").tobytes()
    image = image + b"\0" * (-len(image) % 4)
    binary = positions + uvs + indices + b"\0\0" + image
    views = [(0, len(positions)), (len(positions), len(uvs)), (len(positions) + len(uvs), len(indices)),
             (len(positions) + len(uvs) + len(indices) + 2, len(image))]
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "square"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2,
                                    "material": 0}]}],
        "materials": [{"name": "painted", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        "textures": [{"source": 0}],
        "images": [{"name": "paint.png", "bufferView": 3, "mimeType": "image/png"}],
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": [{"buffer": 0, "byteOffset": o, "byteLength": n} for o, n in views],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [-1, -1, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"},
        ],
    }
    return glb_bytes(doc, binary)


def corrupt_png():
    """A PNG whose signature and header are intact and whose pixel data is garbage."""
    good = png_bytes(16, 16)
    return good[:33] + _png_chunk(b"IDAT", bytes(range(7, 250, 3))) + _png_chunk(b"IEND", b"")


def _rng_bytes(n, seed):
    return np.random.default_rng(seed).integers(0, 256, n, dtype=np.uint8).tobytes()


def corpus():
    """``{file name: bytes}`` of the corpus in tests/data/bad/ (see tests/test_bad_inputs.py)."""
    files = {}
    nan_cube = cube_obj().splitlines()
    nan_cube[0], nan_cube[3] = "v nan -1 -1", "v -1 1 inf"
    files["nan_vertices.obj"] = "\n".join(nan_cube) + "\n"
    files["huge_cube.obj"] = cube_obj(1e11)
    files["tiny_cube.obj"] = cube_obj(1e-9)
    files["offset_cube.obj"] = cube_obj(1.0, 1e7)
    files["far_outlier.obj"] = obj_text(
        np.vstack([CUBE_VERTICES, CUBE_VERTICES * 1e29 + 1e30]), np.vstack([CUBE_FACES, CUBE_FACES + 8]))
    files["wall_with_door.obj"] = wall_with_door_obj()
    files["index_out_of_range.obj"] = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 99\n"
    files["short_faces.obj"] = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n"
    files["garbage.obj"] = _rng_bytes(3000, 1)
    files["garbage.stl"] = _rng_bytes(3000, 2)
    files["garbage.glb"] = _rng_bytes(3000, 3)
    files["garbage.ply"] = _rng_bytes(3000, 4)
    files["latin1_garbage.off"] = bytes(range(128, 256)) * 8
    files["only_comments.obj"] = "# nothing here\n"
    files["lying_count.stl"] = b"binary stl" + b" " * 70 + struct.pack("<I", 1000) + b"\0" * 500
    files["truncated_ascii.stl"] = "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"
    files["lying_header.ply"] = ("ply\nformat ascii 1.0\nelement vertex 1000\nproperty float x\n"
                                 "property float y\nproperty float z\nelement face 1\n"
                                 "property list uchar int vertex_indices\nend_header\n0 0 0\n")
    files["truncated_faces.ply"] = ("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n"
                                    "property float y\nproperty float z\nelement face 3\n"
                                    "property list uchar int vertex_indices\nend_header\n"
                                    "0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n")
    files["index_out_of_range.ply"] = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                       "property float y\nproperty float z\nelement face 2\n"
                                       "property list uchar int vertex_indices\nend_header\n"
                                       "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 7\n")
    files["garbage.mtl"] = "newmtl m\nKd abc 1 zz\nNs -inf\nillum 99\nKe nan 1 1\n"
    files["garbage_mtl.obj"] = "mtllib garbage.mtl\nusemtl m\n" + cube_obj()
    cycle = gltf_cube([{"name": "a", "mesh": 0, "children": [1]},
                       {"name": "b", "mesh": 0, "children": [0], "translation": [3, 0, 0]}], [0])
    files["node_cycle.gltf"] = json.dumps(cycle)
    zero = gltf_cube([{"name": "hidden", "mesh": 0, "scale": [0, 0, 0]},
                      {"name": "shown", "mesh": 0, "translation": [3, 0, 0]}], [0, 1])
    files["zero_scale.gltf"] = json.dumps(zero)
    missing = copy.deepcopy(zero)
    missing["buffers"][0]["uri"] = "gone.bin"
    files["missing_buffer.gltf"] = json.dumps(missing)
    # physically based materials with unusable extension values: a warning naming the file,
    # material and key, the default used
    bad_glass = gltf_cube([{"name": "glass", "mesh": 0}], [0])
    bad_glass["meshes"][0]["primitives"][0]["material"] = 0
    bad_glass["materials"] = [{"name": "glass", "emissiveFactor": [1, 1, 1], "extensions": {
        "KHR_materials_transmission": {"transmissionFactor": "lots"},
        "KHR_materials_ior": {"ior": -3},
        "KHR_materials_emissive_strength": {"emissiveStrength": 1e308},
        "KHR_materials_volume": {"attenuationDistance": -1, "attenuationColor": [2, -1, "x"]}}}]
    files["bad_pbr_extensions.gltf"] = json.dumps(bad_glass)
    # a KHR layer extension's value out of its specification's range: one error line
    bad_coat = copy.deepcopy(bad_glass)
    bad_coat["materials"] = [{"name": "paint", "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 2}}}]
    files["bad_layer_extension.gltf"] = json.dumps(bad_coat)
    good = glb_bytes(zero)
    files["truncated.glb"] = good[: len(good) // 2]
    files["corrupt_texture.glb"] = textured_square_glb(corrupt_png())
    files["bad_types.toml"] = '[render]\nwidth = "wide"\n[[objects]]\nprimitive = "box"\n'
    files["fov_270.toml"] = ('[camera]\nposition = [0, -5, 0]\nlook_at = [0, 0, 0]\nfov = 270\n'
                             '[[objects]]\nprimitive = "box"\n')
    files["huge_spp.toml"] = '[render]\nspp = 100000000000\n[[objects]]\nprimitive = "box"\n'
    files["not_utf8.toml"] = b"[render]\nwidth = 4\n# \xff\xfe\n"
    # a box placed by three transforms, the second singular (a zero scale along y)
    rows = np.tile(np.eye(4), (3, 1, 1))
    rows[:, 0, 3] = [-2.0, 0.0, 2.0]
    rows[1, 1, 1] = 0.0
    npy = io.BytesIO()
    np.save(npy, rows)
    files["singular_instances.npy"] = npy.getvalue()
    files["singular_instances.toml"] = '[[objects]]\nprimitive = "box"\ninstances = "singular_instances.npy"\n'
    return files


def write_corpus(folder=BAD):
    os.makedirs(folder, exist_ok=True)
    for name, content in corpus().items():
        with open(os.path.join(folder, name), "wb") as f:
            f.write(content if isinstance(content, bytes) else content.encode())


if __name__ == "__main__":
    write_corpus()
