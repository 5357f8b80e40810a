"""A glTF document's JSON checked before trimesh reads it (:func:`check_document`): every
index refers to something the file has, every accessor and buffer view is one glTF defines
and fits in its data, vertex attributes have their shapes, node transforms their sizes; the
first problem is one line naming the file and the key (``m.gltf: nodes[1].camera: 5 refers
to no camera (the file has 1 camera)``), where trimesh would raise a bare exception or read
garbage.  Only the JSON and the data's sizes are read, no geometry."""

import json
import os
import struct
import urllib.parse

from rtmesh.core.errors import MeshError


# the arrays of a glTF document that indices refer to: key -> (singular, plural) in messages
_ARRAYS = {"scenes": ("scene", "scenes"), "nodes": ("node", "nodes"), "meshes": ("mesh", "meshes"),
           "cameras": ("camera", "cameras"), "skins": ("skin", "skins"),
           "materials": ("material", "materials"), "textures": ("texture", "textures"),
           "images": ("image", "images"), "samplers": ("sampler", "samplers"),
           "accessors": ("accessor", "accessors"), "bufferViews": ("buffer view", "buffer views"),
           "buffers": ("buffer", "buffers")}
# glTF componentType -> (bytes, name); accessor type -> components
_COMPONENT_TYPES = {5120: (1, "BYTE"), 5121: (1, "UNSIGNED_BYTE"), 5122: (2, "SHORT"),
                    5123: (2, "UNSIGNED_SHORT"), 5125: (4, "UNSIGNED_INT"), 5126: (4, "FLOAT")}
_ACCESSOR_TYPES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_INDEX_COMPONENTS = (5121, 5123, 5125)
# the accessor types of the vertex attributes trimesh reads (a name or a prefix of names)
_ATTRIBUTE_TYPES = (("POSITION", ("VEC3",), "positions must be 3D (VEC3)"),
                    ("NORMAL", ("VEC3",), "normals must be 3D (VEC3)"),
                    ("TANGENT", ("VEC4",), "tangents must be VEC4"),
                    ("TEXCOORD_", ("VEC2",), "texture coordinates must be 2D (VEC2)"),
                    ("COLOR_", ("VEC3", "VEC4"), "colours must be RGB or RGBA (VEC3 or VEC4)"))
# the node transform properties: key -> how many numbers; a node's indices: key -> array
_NODE_NUMBERS = {"matrix": 16, "translation": 3, "rotation": 4, "scale": 3}
_NODE_INDICES = {"mesh": "meshes", "camera": "cameras", "skin": "skins"}
_DRACO = "KHR_draco_mesh_compression"


def check_document(path, doc, extents=True):
    """Raise MeshError naming the first key of a glTF document that trimesh cannot read:
    an index that refers to nothing (a scene, node, mesh, camera, skin, material, texture,
    image, sampler, accessor, buffer view or buffer the file does not have), an accessor
    with a componentType or type glTF does not define or that does not fit in its buffer
    view, a buffer view beyond the end of its buffer or with a byteStride glTF does not
    allow, a vertex attribute of the wrong shape (2D positions, 2D normals), indices that
    are not unsigned integers or do not make whole triangles, a node transform that is not
    the numbers it must be.  trimesh would report these as a bare ``KeyError``, an
    ``AssertionError`` or a ``list index out of range``, or fail later (positions of two
    coordinates fail when they are transformed).

    One pass over the JSON and the sizes of the buffers (no geometry is read), a few
    milliseconds for ten thousand nodes.

    Parameters
    ----------
    path : str
        The file (GLB: its binary chunk's size is read; ``.gltf``: its data URIs' and
        external buffers' sizes).
    doc : dict
        Its JSON (:func:`read_gltf_json`).
    extents : bool
        Whether to check where the buffer views and accessors lie in the data (their byte
        ranges and strides).  False for a file :mod:`rtmesh.loaders.gltf_compression`
        rewrites before trimesh reads it: it reads the buffers and views itself and names
        what does not fit in its own words.

    Raises
    ------
    MeshError
        ``file: key: what is wrong``, e.g. ``m.gltf: accessors[3].componentType: 9999 is not
        a glTF component type (...)`` or ``m.gltf: nodes[1].camera: 5 refers to no camera (the
        file has 1 camera)``.
    """
    _Document(path, doc).check(extents)


def _shown(value):
    """A JSON value in a message, at most 40 characters."""
    text = json.dumps(value) if isinstance(value, (list, dict, str, bool)) or value is None else repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _is_int(value):
    return type(value) is int  # JSON's integers (not true and false)


_NUMBER_TYPES = frozenset((int, float))  # JSON's numbers (not true and false)


class _Document:
    """The checks of :func:`check_document`."""

    def __init__(self, path, doc):
        self.path, self.doc = path, doc
        self.arrays = {key: self._array(key) for key in _ARRAYS}

    def fail(self, key, message):
        raise MeshError(f"{self.path}: {key}: {message}")

    def _array(self, key):
        value = self.doc.get(key)
        if value is None:
            return []
        if not isinstance(value, list):
            self.fail(key, f"expected an array (got {_shown(value)})")
        for i, entry in enumerate(value):
            if not isinstance(entry, dict):
                self.fail(f"{key}[{i}]", f"expected an object (got {_shown(entry)})")
        return value

    def index(self, key, value, target):
        count = len(self.arrays[target])
        if not (type(value) is int and 0 <= value < count):
            singular, plural = _ARRAYS[target]
            self.fail(key, f"{_shown(value)} refers to no {singular} (the file has {count} "
                           f"{singular if count == 1 else plural})")
        return value

    def integer(self, key, value, least=0):
        if not (_is_int(value) and value >= least):
            self.fail(key, f"{_shown(value)} is not an integer >= {least}")
        return value

    def listed(self, key, value):
        if not isinstance(value, list):
            self.fail(key, f"expected an array (got {_shown(value)})")
        return value

    def check(self, extents=True):
        self.scenes_and_nodes()
        self.buffers_and_views(extents)
        self.accessor_types()
        self.meshes()  # what the primitives' accessors must be, before whether they fit their views
        if extents:
            self.accessor_extents()
        self.materials_and_textures()

    def scenes_and_nodes(self):
        doc, scenes = self.doc, self.arrays["scenes"]
        if "scenes" in doc:
            if not scenes:
                self.fail("scenes", "an empty array: the file has no scene to show")
            self.index("scene", doc.get("scene", 0), "scenes")
        count = len(self.arrays["nodes"])
        for i, scene in enumerate(scenes):
            for j, node in enumerate(self.listed(f"scenes[{i}].nodes", scene.get("nodes", []))):
                if not (type(node) is int and 0 <= node < count):
                    self.index(f"scenes[{i}].nodes[{j}]", node, "nodes")
        nodes = self.arrays["nodes"]
        counts = {key: len(self.arrays[target]) for key, target in _NODE_INDICES.items()}
        counts["children"] = len(nodes)
        for i, node in enumerate(nodes):
            # (the loop of a file of many nodes: each value tested inline, formatted on failure)
            for key, value in node.items():
                if key in counts:
                    if key != "children":
                        if not (type(value) is int and 0 <= value < counts[key]):
                            self.index(f"nodes[{i}].{key}", value, _NODE_INDICES[key])
                        continue
                    for j, child in enumerate(self.listed(f"nodes[{i}].children", value)):
                        if not (type(child) is int and 0 <= child < counts["children"]):
                            self.index(f"nodes[{i}].children[{j}]", child, "nodes")
                elif key in _NODE_NUMBERS and not (type(value) is list and len(value) == _NODE_NUMBERS[key]
                                                   and all(map(_NUMBER_TYPES.__contains__, map(type, value)))):
                    count = _NODE_NUMBERS[key]
                    got = f"{len(value)} values" if isinstance(value, list) and len(value) != count else _shown(value)
                    self.fail(f"nodes[{i}].{key}", f"expected {count} numbers (got {got})")

    def buffers_and_views(self, extents=True):
        sizes = self._buffer_sizes() if extents else None
        for i, view in enumerate(self.arrays["bufferViews"]):
            key = f"bufferViews[{i}]"
            buffer = self.index(f"{key}.buffer", view.get("buffer"), "buffers")
            offset = self.integer(f"{key}.byteOffset", view.get("byteOffset", 0))
            length = self.integer(f"{key}.byteLength", view.get("byteLength"))
            stride = view.get("byteStride")
            if stride is not None and not (_is_int(stride) and 4 <= stride <= 252 and stride % 4 == 0):
                self.fail(f"{key}.byteStride", f"{_shown(stride)} is not a glTF byte stride (a multiple of 4 "
                                               "from 4 to 252)")
            if extents and sizes[buffer] is not None and offset + length > sizes[buffer]:
                self.fail(key, f"bytes {offset} to {offset + length} lie beyond the end of buffers[{buffer}] "
                               f"({sizes[buffer]} bytes): a truncated file or a wrong byteOffset?")

    def _buffer_sizes(self):
        """Bytes each buffer holds: its data where the file has it (a GLB's binary chunk, a
        data URI, an external file), else its declared byteLength; None when neither."""
        folder = os.path.dirname(os.path.abspath(self.path))
        glb_chunk = _glb_binary_size(self.path) if self.path.lower().endswith(".glb") else None
        sizes = []
        for i, buffer in enumerate(self.arrays["buffers"]):
            declared = buffer.get("byteLength")
            if declared is not None:
                self.integer(f"buffers[{i}].byteLength", declared)
            uri, size = buffer.get("uri"), None
            if uri is None:
                size = glb_chunk if i == 0 else None
            elif isinstance(uri, str) and uri.startswith("data:"):
                header, _, payload = uri.partition(",")
                if header.endswith(";base64"):
                    if len(payload) % 4:
                        self.fail(f"buffers[{i}].uri", f"malformed base64 data ({len(payload)} characters, not a "
                                                       "multiple of 4): a truncated file?")
                    size = len(payload) // 4 * 3 - (len(payload) - len(payload.rstrip("=")))
            elif isinstance(uri, str):
                target = os.path.join(folder, urllib.parse.unquote(uri))
                size = os.path.getsize(target) if os.path.isfile(target) else None
            sizes.append(size if size is not None else declared)
        return sizes

    def accessor_types(self):
        for i, accessor in enumerate(self.arrays["accessors"]):
            key = f"accessors[{i}]"
            component, kind = accessor.get("componentType"), accessor.get("type")
            if not _is_int(component) or component not in _COMPONENT_TYPES:
                self.fail(f"{key}.componentType", f"{_shown(component)} is not a glTF component type "
                                                  "(5120, 5121, 5122, 5123, 5125 or 5126)")
            if not isinstance(kind, str) or kind not in _ACCESSOR_TYPES:
                self.fail(f"{key}.type", f"{_shown(kind)} is not a glTF accessor type (SCALAR, VEC2, VEC3, "
                                         "VEC4, MAT2, MAT3 or MAT4)")
            self.integer(f"{key}.count", accessor.get("count"))
            self.integer(f"{key}.byteOffset", accessor.get("byteOffset", 0))
            if "bufferView" in accessor:
                self.index(f"{key}.bufferView", accessor["bufferView"], "bufferViews")

    def accessor_extents(self):
        views = self.arrays["bufferViews"]
        for i, accessor in enumerate(self.arrays["accessors"]):
            if "bufferView" not in accessor:
                continue  # zeros, or filled by an extension (Draco)
            key, view = f"accessors[{i}]", views[accessor["bufferView"]]
            component, kind = accessor["componentType"], accessor["type"]
            count, offset = accessor["count"], accessor.get("byteOffset", 0)
            element = _COMPONENT_TYPES[component][0] * _ACCESSOR_TYPES[kind]
            stride = view.get("byteStride") or element
            if stride < element:
                self.fail(key, f"{kind} {_COMPONENT_TYPES[component][1]} elements of {element} bytes do not fit "
                               f"in the byteStride {stride} of bufferViews[{accessor['bufferView']}]")
            needed = offset + (stride * (count - 1) + element if count else 0)
            if needed > view["byteLength"]:
                self.fail(key, f"{count} {kind} elements of {element} bytes from byte {offset} need {needed} "
                               f"bytes; bufferViews[{accessor['bufferView']}] holds {view['byteLength']}")

    def meshes(self):
        accessors = self.arrays["accessors"]
        for m, mesh in enumerate(self.arrays["meshes"]):
            for p, primitive in enumerate(self.listed(f"meshes[{m}].primitives", mesh.get("primitives", []))):
                where = f"meshes[{m}].primitives[{p}]"
                if not isinstance(primitive, dict):
                    self.fail(where, f"expected an object (got {_shown(primitive)})")
                attributes = primitive.get("attributes", {})
                if not isinstance(attributes, dict):
                    self.fail(f"{where}.attributes", f"expected an object (got {_shown(attributes)})")
                for name, index in attributes.items():
                    kind = accessors[self.index(f"{where}.attributes.{name}", index, "accessors")]["type"]
                    for prefix, kinds, what in _ATTRIBUTE_TYPES:
                        if (name == prefix or prefix.endswith("_") and name.startswith(prefix)) and kind not in kinds:
                            self.fail(f"{where}.attributes.{name}", f"accessors[{index}] is {kind}; {what}")
                for t, target in enumerate(self.listed(f"{where}.targets", primitive.get("targets", []))):
                    for name, index in (target.items() if isinstance(target, dict) else ()):
                        self.index(f"{where}.targets[{t}].{name}", index, "accessors")
                if "material" in primitive:
                    self.index(f"{where}.material", primitive["material"], "materials")
                mode = primitive.get("mode", 4)
                if not (_is_int(mode) and 0 <= mode <= 6):
                    self.fail(f"{where}.mode", f"{_shown(mode)} is not a glTF primitive mode (0 to 6)")
                if "indices" in primitive:
                    index = self.index(f"{where}.indices", primitive["indices"], "accessors")
                    accessor = accessors[index]
                    component, kind = accessor["componentType"], accessor["type"]
                    if kind != "SCALAR" or component not in _INDEX_COMPONENTS:
                        held = f"{kind} {_COMPONENT_TYPES[component][1]}"
                        self.fail(f"{where}.indices", f"accessors[{index}] holds {held} values; indices must be "
                                                      "SCALAR UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT")
                    corners, key, what = accessor["count"], f"{where}.indices", "indices"
                else:
                    position = attributes.get("POSITION")
                    corners = accessors[position]["count"] if position is not None else 0
                    key, what = f"{where}.attributes.POSITION", "vertices (no indices)"
                draco = _DRACO in (primitive.get("extensions") or {})  # counted after decoding
                if mode == 4 and corners % 3 and not draco:
                    self.fail(key, f"{corners} {what} do not make whole triangles (not a multiple of 3)")

    def materials_and_textures(self):
        for i, material in enumerate(self.arrays["materials"]):
            self._texture_references(f"materials[{i}]", material)
        for i, texture in enumerate(self.arrays["textures"]):
            if "source" in texture:
                self.index(f"textures[{i}].source", texture["source"], "images")
            if "sampler" in texture:
                self.index(f"textures[{i}].sampler", texture["sampler"], "samplers")
            extensions = texture.get("extensions")
            for name, spec in (extensions.items() if isinstance(extensions, dict) else ()):
                if isinstance(spec, dict) and "source" in spec:  # KHR_texture_basisu, EXT_texture_webp...
                    self.index(f"textures[{i}].extensions.{name}.source", spec["source"], "images")
        for i, image in enumerate(self.arrays["images"]):
            if "bufferView" in image:
                self.index(f"images[{i}].bufferView", image["bufferView"], "bufferViews")

    def _texture_references(self, key, value):
        """The ``index`` of every textureInfo (a ``...Texture`` object) under a material,
        its extensions' included."""
        for name, entry in value.items():
            if not isinstance(entry, dict) or name == "extras":
                continue
            if name.endswith("Texture") and "index" in entry:
                self.index(f"{key}.{name}.index", entry["index"], "textures")
            self._texture_references(f"{key}.{name}", entry)


def _glb_binary_size(path):
    """Bytes of a GLB file's binary chunk that the file holds (0 without one)."""
    with open(path, "rb") as f:
        head = f.read(20)
        if len(head) < 20:
            return 0
        at = 20 + struct.unpack_from("<I", head, 12)[0]
        f.seek(at)
        chunk = f.read(8)
        size = os.fstat(f.fileno()).st_size
    if len(chunk) < 8 or struct.unpack_from("<I", chunk, 4)[0] != 0x004E4942:  # "BIN\0"
        return 0
    return max(0, min(struct.unpack_from("<I", chunk, 0)[0], size - at - 8))
