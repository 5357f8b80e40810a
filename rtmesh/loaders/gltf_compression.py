"""Compressed and quantised glTF geometry, decoded before trimesh reads the file.

Web pipelines (gltf-transform, gltfpack, Blender's exporter) store geometry with
``KHR_draco_mesh_compression`` (a Draco blob per primitive), ``EXT_meshopt_compression``
(meshoptimizer-encoded buffer views) and ``KHR_mesh_quantization`` (normalised or plain
integer positions, normals, tangents and texture coordinates, with node transforms that
scale them back).  trimesh reads none of these correctly by itself, so a file that uses
any of them is rewritten here, in memory, into a plain GLB of the same scene: every
buffer of the file joined into one binary chunk, meshopt views decoded in place, Draco
primitives decoded into float32 attributes and uint32 indices, integer vertex attributes
converted to float32 as the glTF specification defines (``c / (2^(b-1) - 1)`` clamped to
-1 for signed normalised types, ``c / (2^b - 1)`` for unsigned ones, the integer itself
when not normalised).  Node transforms are left as they are: the dequantising transforms
a quantiser writes on the nodes then place the float attributes as they placed the
integers.  ``EXT_mesh_gpu_instancing`` nodes become a child node per instance (its
translation, rotation and scale); the loader then builds a mesh that several nodes place
once and places it by Embree instances (:mod:`rtmesh.scene.instances`).  An instance whose
values are not finite or make its transform singular is refused in one line.  Files that
use none of these extensions are read by trimesh as before.

Draco needs ``DracoPy`` and meshopt the ``meshopt`` package (meshoptimizer's codecs), both
in the ``rtmesh[compressed]`` extra; a file that needs a missing one is refused in one
line naming the extension and the extra.  A buffer that does not decode (truncated, or
its count wrong) is one line naming the file and the glTF key.
"""

import base64
import io
import json
import os
import struct
import urllib.parse

import numpy as np

from rtmesh.core.errors import MeshError, MissingExtraError

DRACO = "KHR_draco_mesh_compression"
MESHOPT = "EXT_meshopt_compression"
QUANTIZATION = "KHR_mesh_quantization"
GPU_INSTANCING = "EXT_mesh_gpu_instancing"
# the extensions this module decodes; a file that uses one is rewritten
DECODED = (DRACO, MESHOPT, QUANTIZATION, GPU_INSTANCING)
# the meshopt extension under its vendor-neutral name (gltfpack writes either)
_MESHOPT_NAMES = (MESHOPT, "KHR_meshopt_compression")

# glTF componentType -> NumPy dtype (little-endian)
COMPONENT_TYPES = {5120: np.dtype("<i1"), 5121: np.dtype("<u1"), 5122: np.dtype("<i2"),
                   5123: np.dtype("<u2"), 5125: np.dtype("<u4"), 5126: np.dtype("<f4")}
COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_FLOAT, _UINT32 = 5126, 5125
# vertex attributes that KHR_mesh_quantization lets be integers (prefixes of their names)
_QUANTISABLE = ("POSITION", "NORMAL", "TANGENT", "TEXCOORD_", "COLOR_")
_GLB_MAGIC, _JSON_CHUNK, _BIN_CHUNK = 0x46546C67, 0x4E4F534A, 0x004E4942
EXTRA = "rtmesh[compressed]"


def uses_decoded_extensions(doc):
    """True when a glTF document uses Draco, meshopt or quantised geometry.

    Parameters
    ----------
    doc : dict
        The file's JSON.
    """
    used = set(doc.get("extensionsUsed") or []) | set(doc.get("extensionsRequired") or [])
    return bool(used & set(DECODED + _MESHOPT_NAMES))


def plain_glb(path, doc):
    """The file as a plain GLB: compressed and quantised geometry decoded (module docstring).

    Parameters
    ----------
    path : str
        A ``.gltf`` or ``.glb`` file (its external buffers are read relative to its folder).
    doc : dict
        Its JSON (:func:`rtmesh.loaders.gltf_nodes.read_gltf_json`).

    Returns
    -------
    bytes
        A GLB file holding one buffer; images named by URI stay external.

    Raises
    ------
    MeshError
        A codec the file needs is not installed, a buffer or accessor lies outside its
        data, or a compressed buffer does not decode.
    """
    doc = json.loads(json.dumps(doc))  # rewritten below; the caller's stays as read
    writer = _Writer(path, _file_buffers(path, doc))
    views = doc.get("bufferViews") or []
    for i, view in enumerate(views):
        extensions = view.get("extensions") or {}
        name = next((n for n in _MESHOPT_NAMES if n in extensions), None)
        if name is not None:
            views[i] = writer.meshopt_view(view, extensions[name], f"bufferViews[{i}].extensions.{name}")
        else:
            views[i] = writer.moved_view(view, f"bufferViews[{i}]")
    for m, mesh in enumerate(doc.get("meshes") or []):
        for p, primitive in enumerate(mesh.get("primitives") or []):
            where = f"meshes[{m}].primitives[{p}]"
            draco = (primitive.get("extensions") or {}).pop(DRACO, None)
            if draco is not None:
                writer.draco_primitive(doc, primitive, draco, f"{where}.extensions.{DRACO}")
            for name, index in list((primitive.get("attributes") or {}).items()):
                if name.startswith(_QUANTISABLE):
                    primitive["attributes"][name] = writer.float_accessor(doc, index, f"{where}.attributes.{name}")
    nodes = doc.get("nodes") or []
    for i in range(len(nodes)):
        spec = (nodes[i].get("extensions") or {}).pop(GPU_INSTANCING, None) if isinstance(nodes[i], dict) else None
        if spec is not None:
            writer.instance_nodes(doc, i, spec, f"nodes[{i}].extensions.{GPU_INSTANCING}")
    for key in ("extensionsUsed", "extensionsRequired"):
        if key in doc:
            doc[key] = [e for e in doc[key] if e not in DECODED + _MESHOPT_NAMES]
    doc["buffers"] = [{"byteLength": len(writer.data)}]
    return _glb(doc, bytes(writer.data))


def _file_buffers(path, doc):
    """The bytes of every buffer of the file, in order (None for a meshopt fallback buffer,
    which has no data)."""
    glb_bin = None
    if path.lower().endswith(".glb"):
        glb_bin = _glb_binary_chunk(path)
    folder = os.path.dirname(os.path.abspath(path))
    out = []
    for i, buffer in enumerate(doc.get("buffers") or []):
        uri = buffer.get("uri")
        try:
            if uri is None:
                fallback = any((buffer.get("extensions") or {}).get(n, {}).get("fallback")
                               for n in _MESHOPT_NAMES)
                if not fallback and glb_bin is None:
                    raise ValueError("no URI, and no GLB binary chunk holds it")
                out.append(None if fallback else glb_bin)
            elif uri.startswith("data:"):
                out.append(base64.b64decode(uri.split(",", 1)[1]))
            else:
                with open(os.path.join(folder, urllib.parse.unquote(uri)), "rb") as f:
                    out.append(f.read())
        except (OSError, ValueError, IndexError) as exc:
            raise MeshError(f"{path}: buffers[{i}]: cannot read ({exc})") from None
    return out


def _glb_binary_chunk(path):
    """The BIN chunk of a GLB file, or None."""
    with open(path, "rb") as f:
        data = f.read()
    try:
        json_length = struct.unpack_from("<I", data, 12)[0]
        at = 20 + json_length
        if at + 8 > len(data):
            return None
        length, kind = struct.unpack_from("<II", data, at)
    except struct.error:
        return None
    if kind != _BIN_CHUNK or at + 8 + length > len(data):
        raise MeshError(f"{path}: the GLB binary chunk is truncated or missing")
    return data[at + 8:at + 8 + length]


def _glb(doc, binary):
    """A GLB file of a JSON document and its one binary buffer."""
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    out = io.BytesIO()
    out.write(struct.pack("<III", _GLB_MAGIC, 2, 12 + 8 + len(text) + 8 + len(binary)))
    out.write(struct.pack("<II", len(text), _JSON_CHUNK) + text)
    out.write(struct.pack("<II", len(binary), _BIN_CHUNK) + binary)
    return out.getvalue()


class _Writer:
    """The one buffer of the rewritten file, grown view by view."""

    def __init__(self, path, buffers):
        self.path, self.buffers, self.data = path, buffers, bytearray()

    def error(self, where, message):
        return MeshError(f"{self.path}: {where}: {message}")

    def append(self, payload):
        """A new bufferView of ``payload`` (4-byte aligned); returns the view (a dict)."""
        self.data += b"\0" * (-len(self.data) % 4)
        view = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(payload)}
        self.data += payload
        return view

    def source(self, spec, where):
        """The bytes a view (or a meshopt extension) names in its source buffer."""
        index, offset, length = spec.get("buffer"), spec.get("byteOffset", 0), spec.get("byteLength")
        if not (isinstance(index, int) and 0 <= index < len(self.buffers)):
            raise self.error(where, f"buffer {index!r} does not exist")
        data = self.buffers[index]
        if data is None:
            return None
        if not (isinstance(offset, int) and isinstance(length, int) and 0 <= offset
                and offset + length <= len(data) and length >= 0):
            raise self.error(where, f"bytes {offset!r} to {offset!r} + {length!r} lie outside buffer "
                                    f"{index} ({len(data)} bytes): a truncated file?")
        return data[offset:offset + length]

    def moved_view(self, view, where):
        """A plain view, its bytes copied into the new buffer."""
        payload = self.source(view, where)
        moved = {k: v for k, v in view.items() if k not in ("buffer", "byteOffset", "byteLength")}
        if payload is None:  # a view of a fallback buffer that no meshopt view decodes: empty
            payload = b"\0" * int(view.get("byteLength", 0))
        moved.update(self.append(payload))
        return moved

    def meshopt_view(self, view, spec, where):
        """A meshopt-compressed view (``view`` with its extension ``spec``) decoded
        (``meshopt.decode_gltf_buffer``)."""
        try:
            import meshopt
        except ImportError:
            raise MissingExtraError(f"{self.path}: uses {MESHOPT}, which needs the meshopt package: "
                            f"pip install '{EXTRA}'") from None
        payload = self.source(spec, where)
        count, stride = spec.get("count"), spec.get("byteStride")
        mode, filter_ = spec.get("mode", "ATTRIBUTES"), spec.get("filter", "NONE")
        if not (isinstance(count, int) and count > 0 and isinstance(stride, int) and stride > 0):
            raise self.error(where, f"count {count!r} and byteStride {stride!r} must be positive integers")
        if count * stride != view.get("byteLength"):
            # the codecs decode a wrong count without a word where its blocks allow
            raise self.error(where, f"the compressed data does not decode to {count} elements of {stride} "
                                    f"bytes: the bufferView holds {view.get('byteLength')!r} bytes")
        try:
            decoded = meshopt.decode_gltf_buffer(payload, count, stride, mode, filter_)
        except (ValueError, RuntimeError, TypeError) as exc:
            raise self.error(where, f"the compressed data does not decode to {count} elements of "
                                    f"{stride} bytes ({exc})") from None
        view = self.append(np.ascontiguousarray(decoded).tobytes())
        if mode == "ATTRIBUTES":
            view["byteStride"] = stride
        return view

    def draco_primitive(self, doc, primitive, spec, where):
        """A Draco primitive's attributes and indices as new float32 / uint32 accessors."""
        try:
            import DracoPy
        except ImportError:
            raise MissingExtraError(f"{self.path}: uses {DRACO}, which needs DracoPy: pip install '{EXTRA}'") from None
        views = doc.get("bufferViews") or []
        index = spec.get("bufferView")
        if not (isinstance(index, int) and 0 <= index < len(views)):
            raise self.error(where, f"bufferView {index!r} does not exist")
        view = views[index]  # already moved into the new buffer
        blob = bytes(self.data[view["byteOffset"]:view["byteOffset"] + view["byteLength"]])
        try:
            decoded = DracoPy.decode(blob)
        except Exception as exc:  # DracoPy raises its own types for every malformed blob
            raise self.error(where, f"the Draco data does not decode ({exc}): a truncated or "
                                    "corrupt buffer?") from None
        by_id = {a["unique_id"]: np.asarray(a["data"]) for a in decoded.attributes}
        attributes = primitive.setdefault("attributes", {})
        for name, ident in (spec.get("attributes") or {}).items():
            if ident not in by_id:
                raise self.error(f"{where}.attributes.{name}", f"Draco attribute {ident!r} is not in the data")
            values = by_id[ident].reshape(len(by_id[ident]), -1)
            if values.dtype.kind in "iu":
                target = _accessor(doc, attributes.get(name), self, f"{where}.attributes.{name}", spec_only=True)
                values = _dequantised(values, target.get("normalized", False) if target else True)
            attributes[name] = self.new_accessor(doc, values.astype(np.float32))
        faces = getattr(decoded, "faces", None)
        if faces is None:
            raise self.error(where, "the Draco data holds points, not triangles")
        primitive["indices"] = self.new_accessor(doc, np.asarray(faces, dtype=np.uint32).reshape(-1, 1),
                                                 component=_UINT32)
        primitive.pop("mode", None)  # Draco meshes are triangles
        if primitive.get("extensions") == {}:
            del primitive["extensions"]

    def instance_nodes(self, doc, index, spec, where):
        """An EXT_mesh_gpu_instancing node's instances as its children, its mesh on each."""
        node = doc["nodes"][index]
        attributes = spec.get("attributes") or {}
        values, count = {}, None
        for name, width in (("TRANSLATION", 3), ("ROTATION", 4), ("SCALE", 3)):
            if name not in attributes:
                continue
            accessor = _accessor(doc, attributes[name], self, f"{where}.attributes.{name}")
            read = _dequantised(_read_accessor(doc, accessor, self, f"{where}.attributes.{name}"),
                                accessor.get("normalized", False))
            if read.shape[1] != width or (count is not None and len(read) != count):
                raise self.error(f"{where}.attributes.{name}", f"{len(read)} values of {read.shape[1]} "
                                 f"components; expected {count if count is not None else 'n'} of {width}")
            if not np.isfinite(read).all():
                raise self.error(f"{where}.attributes.{name}", "values that are not finite")
            # a zero scale or quaternion makes the instance's transform singular
            singular = (read == 0.0).any(axis=1) if name == "SCALE" else \
                (read == 0.0).all(axis=1) if name == "ROTATION" else np.zeros(len(read), bool)
            if singular.any():
                raise self.error(f"{where}.attributes.{name}", f"instance {int(np.flatnonzero(singular)[0])} has a "
                                 f"singular transform (a zero {name.lower()})")
            values[name.lower()], count = read, len(read)
        if count is None or "mesh" not in node:
            return
        mesh, name = node.pop("mesh"), node.get("name", f"node {index}")
        first = len(doc["nodes"])
        columns = {key: array.tolist() for key, array in values.items()}
        doc["nodes"].extend({"name": f"{name}[{k}]", "mesh": mesh, **{key: rows[k] for key, rows in columns.items()}}
                            for k in range(count))
        node["children"] = list(node.get("children") or []) + list(range(first, first + count))

    def new_accessor(self, doc, values, component=_FLOAT):
        """Index of a new accessor of ``values``, (n, k) float32 or (n, 1) uint32."""
        view = self.append(np.ascontiguousarray(values).tobytes())
        doc.setdefault("bufferViews", []).append(view)
        kind = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}[values.shape[1]]
        accessor = {"bufferView": len(doc["bufferViews"]) - 1, "componentType": component,
                    "count": len(values), "type": kind}
        if component == _FLOAT and kind == "VEC3" and len(values):
            accessor["min"], accessor["max"] = values.min(axis=0).tolist(), values.max(axis=0).tolist()
        doc.setdefault("accessors", []).append(accessor)
        return len(doc["accessors"]) - 1

    def float_accessor(self, doc, index, where):
        """An integer vertex attribute as a new float32 accessor (floats are kept)."""
        accessor = _accessor(doc, index, self, where, spec_only=True)
        if accessor.get("componentType") == _FLOAT or "bufferView" not in accessor:
            return index
        values = _read_accessor(doc, accessor, self, where)
        return self.new_accessor(doc, _dequantised(values, accessor.get("normalized", False)).astype(np.float32))


def _accessor(doc, index, writer, where, spec_only=False):
    accessors = doc.get("accessors") or []
    if index is None and spec_only:
        return None
    if not (isinstance(index, int) and 0 <= index < len(accessors)):
        raise writer.error(where, f"accessor {index!r} does not exist")
    return accessors[index]


def _read_accessor(doc, accessor, writer, where):
    """An accessor's values, (count, components), from the new buffer (views moved)."""
    dtype = COMPONENT_TYPES.get(accessor.get("componentType"))
    width = COMPONENTS.get(accessor.get("type"))
    count = accessor.get("count")
    if dtype is None or width is None or not (isinstance(count, int) and count >= 0):
        raise writer.error(where, "componentType, type or count is not one glTF defines")
    if "sparse" in accessor:
        raise writer.error(where, "a sparse quantised accessor (not supported)")
    view = (doc.get("bufferViews") or [None])[accessor["bufferView"]] \
        if 0 <= accessor["bufferView"] < len(doc.get("bufferViews") or []) else None
    if view is None:
        raise writer.error(where, f"bufferView {accessor['bufferView']!r} does not exist")
    element = dtype.itemsize * width
    stride = view.get("byteStride", element)
    start = view["byteOffset"] + accessor.get("byteOffset", 0)
    end = start + (stride * (count - 1) + element if count else 0)
    if end > view["byteOffset"] + view["byteLength"]:
        raise writer.error(where, f"{count} elements of {stride} bytes run past the end of their "
                                  f"bufferView ({view['byteLength']} bytes)")
    return np.ndarray((count, width), dtype=dtype, buffer=writer.data, offset=start,
                      strides=(stride, dtype.itemsize)).copy()


def _dequantised(values, normalized):
    """Integer attribute values as float64, as glTF 2.0 defines normalised integers
    ("Accessor data types"; KHR_mesh_quantization).

    Parameters
    ----------
    values : (n, k) integer array
    normalized : bool

    Returns
    -------
    (n, k) float64
    """
    values = np.asarray(values)
    if not normalized or values.dtype.kind == "f":
        return values.astype(np.float64)
    bits = 8 * values.dtype.itemsize
    if values.dtype.kind == "u":
        return values / float(2**bits - 1)
    return np.maximum(values / float(2**(bits - 1) - 1), -1.0)
