"""Writers of compressed and quantised GLB files, made from a plain GLB as the web pipelines
make them (gltf-transform, gltfpack): every primitive Draco-encoded by DracoPy, every
buffer view meshopt-encoded by meshoptimizer's codecs (the ``meshopt`` package), or every
vertex attribute quantised to normalised integers with a dequantising node transform
(KHR_mesh_quantization).  The tests render each against the plain file.
"""

import json
import struct

import numpy as np

DTYPES = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def split_glb(data):
    """(JSON document, binary chunk) of a GLB file's bytes."""
    length = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + length])
    at = 20 + length
    binary = b""
    if at + 8 <= len(data):
        size = struct.unpack_from("<I", data, at)[0]
        binary = data[at + 8:at + 8 + size]
    return doc, binary


def join_glb(doc, binary):
    """A GLB file's bytes of a JSON document and its binary chunk."""
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(chunks)) + chunks


def read_accessor(doc, binary, index):
    """An accessor's values as (count, width) (tightly packed views, as trimesh writes them)."""
    accessor = doc["accessors"][index]
    view = doc["bufferViews"][accessor["bufferView"]]
    start = view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
    width = WIDTH[accessor["type"]]
    values = np.frombuffer(binary, DTYPES[accessor["componentType"]], accessor["count"] * width, start)
    return values.reshape(accessor["count"], width)


class _Builder:
    def __init__(self, doc, binary):
        self.doc, self.binary = doc, bytearray(binary)

    def view(self, payload, **extra):
        self.binary += b"\0" * (-len(self.binary) % 4)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.binary), "byteLength": len(payload),
                                        **extra})
        self.binary += payload
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, values, component, normalized=False, stride=None):
        values = np.ascontiguousarray(values)
        width = values.shape[1]
        if stride is not None and stride != values.itemsize * width:  # rows padded to 4 bytes
            padded = np.zeros((len(values), stride // values.itemsize), values.dtype)
            padded[:, :width] = values
            payload, extra = padded.tobytes(), {"byteStride": stride}
        else:
            payload, extra = values.tobytes(), {}
        accessor = {"bufferView": self.view(payload, **extra), "componentType": component, "count": len(values),
                    "type": {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}[width]}
        if normalized:
            accessor["normalized"] = True
        if width == 3 and not normalized:
            accessor["min"], accessor["max"] = values.min(axis=0).tolist(), values.max(axis=0).tolist()
        self.doc["accessors"].append(accessor)
        return len(self.doc["accessors"]) - 1

    def glb(self):
        self.doc["buffers"] = [{"byteLength": len(self.binary)}]
        return join_glb(self.doc, bytes(self.binary))


def _used(doc, name):
    doc.setdefault("extensionsUsed", []).append(name)
    doc.setdefault("extensionsRequired", []).append(name)


def draco_glb(plain, quantization_bits=16):
    """The plain GLB with every primitive's positions, normals, texture coordinates and
    indices in one DracoPy blob (the accessors left without data, as the extension has it)."""
    import DracoPy

    doc, binary = split_glb(plain)
    out = _Builder(doc, binary)
    for mesh in doc["meshes"]:
        for primitive in mesh["primitives"]:
            attributes = primitive["attributes"]
            arrays = {name: read_accessor(doc, binary, attributes[name]).astype(np.float64)
                      for name in ("NORMAL", "TEXCOORD_0") if name in attributes}
            faces = read_accessor(doc, binary, primitive["indices"]).reshape(-1, 3)
            blob = DracoPy.encode(read_accessor(doc, binary, attributes["POSITION"]), faces=faces,
                                  quantization_bits=quantization_bits, preserve_order=True,
                                  normals=arrays.get("NORMAL"), tex_coord=arrays.get("TEXCOORD_0"))
            ids = {a["attribute_type"]: a["unique_id"] for a in DracoPy.decode(blob).attributes}
            kinds = {"POSITION": DracoPy.AttributeType.POSITION, "NORMAL": DracoPy.AttributeType.NORMAL,
                     "TEXCOORD_0": DracoPy.AttributeType.TEX_COORD}
            primitive.setdefault("extensions", {})["KHR_draco_mesh_compression"] = {
                "bufferView": out.view(blob),
                "attributes": {name: ids[kinds[name]] for name in kinds if name in attributes}}
            for index in [*attributes.values(), primitive["indices"]]:
                doc["accessors"][index].pop("bufferView", None)
    _used(doc, "KHR_draco_mesh_compression")
    return out.glb()


def meshopt_glb(plain):
    """The plain GLB with every vertex and index view meshopt-encoded (EXT_meshopt_compression),
    the uncompressed data left to a fallback buffer without bytes."""
    import meshopt

    doc, binary = split_glb(plain)
    compressed = bytearray()
    index_views = {doc["accessors"][p["indices"]]["bufferView"] for m in doc["meshes"] for p in m["primitives"]}
    for accessor in doc["accessors"]:
        view = doc["bufferViews"][accessor["bufferView"]]
        values = read_accessor(doc, binary, doc["accessors"].index(accessor))
        if accessor["bufferView"] in index_views:
            mode, stride = "TRIANGLES", values.itemsize
            encoded = meshopt.encode_gltf_buffer(values.reshape(-1).astype(np.uint32), mode)
        else:
            mode, stride = "ATTRIBUTES", values.itemsize * values.shape[1]
            encoded = meshopt.encode_gltf_buffer(values, mode)
        compressed += b"\0" * (-len(compressed) % 4)
        view["buffer"] = 1
        view["extensions"] = {"EXT_meshopt_compression": {
            "buffer": 0, "byteOffset": len(compressed), "byteLength": len(encoded), "byteStride": stride,
            "count": accessor["count"] * (values.shape[1] if mode == "TRIANGLES" else 1), "mode": mode}}
        compressed += encoded
    # images keep their views in buffer 0: copied after the compressed data
    for image in doc.get("images", []):
        view = doc["bufferViews"][image["bufferView"]]
        start = view.get("byteOffset", 0)
        compressed += b"\0" * (-len(compressed) % 4)
        payload = binary[start:start + view["byteLength"]]
        view.update(buffer=0, byteOffset=len(compressed))
        compressed += payload
    doc["buffers"] = [{"byteLength": len(compressed)},
                      {"byteLength": len(binary), "extensions": {"EXT_meshopt_compression": {"fallback": True}}}]
    _used(doc, "EXT_meshopt_compression")
    return join_glb(doc, bytes(compressed))


def quantised_glb(plain):
    """The plain GLB with positions as normalised int16 (a uniform dequantising scale and
    offset on each mesh's node), normals as normalised int8 and texture coordinates as
    normalised uint16 (KHR_mesh_quantization), rows padded to four bytes."""
    doc, binary = split_glb(plain)
    out = _Builder(doc, binary)
    for m, mesh in enumerate(doc["meshes"]):
        nodes = [n for n in doc["nodes"] if n.get("mesh") == m]
        assert len(nodes) == 1 and not nodes[0].get("children"), "one leaf node a mesh"
        positions = np.concatenate([read_accessor(doc, binary, p["attributes"]["POSITION"])
                                    for p in mesh["primitives"]])
        offset = (positions.min(axis=0) + positions.max(axis=0)) / 2.0
        scale = float(np.abs(positions - offset).max())
        for primitive in mesh["primitives"]:
            attributes = primitive["attributes"]
            p = read_accessor(doc, binary, attributes["POSITION"])
            attributes["POSITION"] = out.accessor(np.round((p - offset) / scale * 32767).astype("<i2"), 5122,
                                                  normalized=True, stride=8)
            if "NORMAL" in attributes:
                n = read_accessor(doc, binary, attributes["NORMAL"])
                attributes["NORMAL"] = out.accessor(np.round(n * 127).astype("<i1"), 5120, normalized=True,
                                                    stride=4)
            if "TEXCOORD_0" in attributes:
                uv = read_accessor(doc, binary, attributes["TEXCOORD_0"])
                assert uv.min() >= 0.0 and uv.max() <= 1.0
                attributes["TEXCOORD_0"] = out.accessor(np.round(uv * 65535).astype("<u2"), 5123, normalized=True)
        local = np.asarray(nodes[0].pop("matrix", np.eye(4).ravel()), float).reshape(4, 4).T
        for key in ("translation", "rotation", "scale"):
            assert key not in nodes[0], "trimesh writes node matrices"
        dequantise = np.diag([scale, scale, scale, 1.0])
        dequantise[:3, 3] = offset
        nodes[0]["matrix"] = (local @ dequantise).T.ravel().tolist()
    _used(doc, "KHR_mesh_quantization")
    return out.glb()


def gpu_instanced_glb(plain, node, translations, rotations, scales):
    """The plain GLB with node ``node`` drawing its mesh once per instance
    (EXT_mesh_gpu_instancing): translations and scales as floats, rotations (x, y, z, w)
    as normalised int16."""
    doc, binary = split_glb(plain)
    out = _Builder(doc, binary)
    doc["nodes"][node].setdefault("extensions", {})["EXT_mesh_gpu_instancing"] = {"attributes": {
        "TRANSLATION": out.accessor(np.asarray(translations, "<f4"), 5126),
        "ROTATION": out.accessor(np.round(np.asarray(rotations) * 32767).astype("<i2"), 5122, normalized=True),
        "SCALE": out.accessor(np.asarray(scales, "<f4"), 5126)}}
    doc.setdefault("extensionsUsed", []).append("EXT_mesh_gpu_instancing")
    return out.glb()
