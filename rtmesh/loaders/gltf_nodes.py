"""Cameras and KHR_lights_punctual lights of glTF files.

trimesh reads a glTF file's meshes and node transforms but keeps at most one camera (and
not its name) and no lights, so this module reads the file's JSON itself: it walks the
node hierarchy of the default scene, composing each node's ``matrix`` or
translation/rotation/scale with its parents' (the same world transforms trimesh gives the
meshes), and turns every camera node and light node into an rtmesh camera or light.

Conventions (glTF 2.0)
----------------------
* A camera looks down its node's -Z axis with +Y up.  Perspective cameras keep ``yfov``
  as rtmesh's vertical field of view; ``aspectRatio`` is not used (the image's width and
  height set the aspect) and ``znear``/``zfar`` are not used (rtmesh does not clip).
  Orthographic cameras are skipped with a warning.
* A light shines down its node's -Z axis.  KHR_lights_punctual gives intensities in
  photometric units: candela (lm/sr) for point and spot lights, lux (lm/m^2) for
  directional lights.  rtmesh renders them the way real-time glTF viewers (three.js,
  Filament, Babylon) display them: a white Lambertian surface 1 m from a 1 cd light, or
  under 1 lx, has radiance 1/pi.  rtmesh's diffuse term has no 1/pi (see
  :mod:`rtmesh.materials.table`), so ``intensity = color * candela / pi`` and
  ``irradiance = color * lux / pi`` under the Whitted integrator; the path integrator's
  Lambert term has the 1/pi, so there (``physical``) candela and lux map 1:1 to W/sr and
  W/m^2.  Spot cone angles (radians) become rtmesh's inner
  and outer half-angles (degrees; rtmesh blends between them with a smoothstep in the
  cosine where glTF suggests a squared linear ramp).  ``range`` is not used (rtmesh
  lights fall off as 1/d^2 without a cut-off).
"""

import collections
import json
import logging
import math
import os
import struct
import urllib.parse

import numpy as np

from rtmesh.core.errors import MeshError
from rtmesh.lights.point_lights import DirectionalLight, PointLight, SpotLight
from rtmesh.scene.camera import Camera
from rtmesh.loaders.placements import held_copies

log = logging.getLogger(__name__)

GLTF_EXTENSIONS = (".gltf", ".glb")
_GLB_MAGIC = 0x46546C67  # "glTF"
_JSON_CHUNK = 0x4E4F534A  # "JSON"


def read_gltf_json(path):
    """The JSON document of a ``.gltf`` or ``.glb`` file.

    Raises
    ------
    MeshError
        The file is not valid glTF JSON / GLB.
    """
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            data = f.read()
        if path.lower().endswith(".glb"):
            magic, _, _ = struct.unpack_from("<III", data, 0)
            length, kind = struct.unpack_from("<II", data, 12)
            if magic != _GLB_MAGIC or kind != _JSON_CHUNK:
                raise ValueError("not a GLB file")
            data = data[20:20 + length]
        doc = json.loads(data.decode("utf-8"))
        if not isinstance(doc, dict):
            raise ValueError("the glTF JSON is not an object")
        return doc
    except (OSError, ValueError, struct.error, UnicodeDecodeError) as exc:
        raise MeshError(f"{path}: cannot read glTF JSON: {exc}") from None


def check_external_files(path, doc):
    """Raise MeshError naming the first buffer or image file a ``.gltf`` file refers to that
    does not exist (trimesh would report only the file name).

    Parameters
    ----------
    path : str
        The ``.gltf`` file; relative URIs are resolved against its folder.
    doc : dict
        Its JSON.
    """
    folder = os.path.dirname(os.path.abspath(path))
    for kind in ("buffers", "images"):
        for entry in doc.get(kind) or []:
            uri = entry.get("uri") if isinstance(entry, dict) else None
            if not isinstance(uri, str) or uri.startswith("data:"):
                continue
            target = os.path.join(folder, urllib.parse.unquote(uri))
            if not os.path.isfile(target):
                raise MeshError(f"{path}: {kind[:-1]} file {uri} not found (looked for {target})")


def check_node_graph(path, doc):
    """Raise MeshError for a glTF node graph with a cycle, which glTF forbids, naming the
    nodes that form it (trimesh would otherwise warn once for every node it cannot place).

    Parameters
    ----------
    path : str
        For the message.
    doc : dict
        glTF JSON.

    Raises
    ------
    MeshError
        ``file: 2 nodes form a cycle: 'a' -> 'b' -> 'a' (glTF forbids cycles in the node graph)``.
    """
    nodes = doc.get("nodes") or []
    children = [[c for c in (n.get("children") or []) if isinstance(c, int) and 0 <= c < len(nodes)]
                if isinstance(n, dict) else [] for n in nodes]
    state = [0] * len(nodes)  # 0 unseen, 1 on the current path, 2 done
    for start in range(len(nodes)):
        if state[start]:
            continue
        path_nodes, stack = [], [(start, iter(children[start]))]
        state[start] = 1
        path_nodes.append(start)
        while stack:
            node, pending = stack[-1]
            child = next(pending, None)
            if child is None:
                state[node] = 2
                stack.pop()
                path_nodes.pop()
            elif state[child] == 1:
                cycle = path_nodes[path_nodes.index(child):] + [child]
                names = " -> ".join(_node_name(nodes, i) for i in cycle)
                raise MeshError(f"{path}: {len(cycle) - 1} nodes form a cycle: {names} (glTF forbids "
                                "cycles in the node graph)")
            elif state[child] == 0:
                state[child] = 1
                path_nodes.append(child)
                stack.append((child, iter(children[child])))


def _node_name(nodes, index):
    """A node's name in messages: ``'name'``, or ``nodes[3]`` for one without a name."""
    name = nodes[index].get("name") if isinstance(nodes[index], dict) else None
    return repr(name) if isinstance(name, str) and name else f"nodes[{index}]"


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


def node_world_transforms(doc):
    """World transform of every node of the default scene.

    Parameters
    ----------
    doc : dict
        glTF JSON.

    Returns
    -------
    list of (int, (4, 4) float)
        ``(node index, world matrix)`` in depth-first order from the scene's roots.
    """
    nodes = doc.get("nodes", [])
    scenes = doc.get("scenes")
    if scenes:
        roots = scenes[doc.get("scene", 0)].get("nodes", [])
    else:  # no scenes: every node that is nobody's child is a root
        children = {c for n in nodes for c in n.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    out = []
    stack = [(i, np.eye(4)) for i in reversed(roots)]
    seen = set()
    while stack:
        index, parent = stack.pop()
        if index in seen or not 0 <= index < len(nodes):
            continue  # a cycle or a bad index: glTF forbids both; do not loop forever
        seen.add(index)
        with np.errstate(invalid="ignore", over="ignore"):  # non-finite nodes are skipped later
            world = parent @ _local_matrix(nodes[index])
        out.append((index, world))
        stack.extend((c, world) for c in reversed(nodes[index].get("children", [])))
    return out


def flattened_size(doc):
    """What the file's meshes come to in memory: a mesh placed by several nodes once when it
    is large enough to be instanced (:func:`rtmesh.loaders.placements.held_copies`), else
    a copy for every node that places it; counted from accessor counts, before reading a
    byte of geometry.

    Parameters
    ----------
    doc : dict
        glTF JSON.

    Returns
    -------
    copies : int
        Mesh nodes of the default scene (each EXT_mesh_gpu_instancing instance a node).
    vertices, triangles : int
        Over every copy and instanced mesh held.
    """
    accessors = doc.get("accessors") or []
    meshes = doc.get("meshes") or []

    def count(index):
        if isinstance(index, int) and 0 <= index < len(accessors) and isinstance(accessors[index], dict):
            value = accessors[index].get("count", 0)
            return value if isinstance(value, int) and value > 0 else 0
        return 0

    sizes = []
    for mesh in meshes:
        vertices = triangles = 0
        for primitive in (mesh.get("primitives") or []) if isinstance(mesh, dict) else []:
            if not isinstance(primitive, dict):
                continue
            corners = count((primitive.get("attributes") or {}).get("POSITION"))
            vertices += corners
            if "indices" in primitive:
                corners = count(primitive["indices"])
            triangles += corners // 3
        sizes.append((vertices, triangles))
    nodes = doc.get("nodes") or []
    placements = collections.Counter()
    for index, _ in node_world_transforms(doc):
        mesh = nodes[index].get("mesh") if isinstance(nodes[index], dict) else None
        if isinstance(mesh, int) and 0 <= mesh < len(sizes):
            # EXT_mesh_gpu_instancing: a placement for each instance
            instancing = (nodes[index].get("extensions") or {}).get("EXT_mesh_gpu_instancing") or {}
            attributes = list((instancing.get("attributes") or {}).values())
            placements[mesh] += count(attributes[0]) if attributes else 1
    copies = sum(placements.values())
    # a mesh worth instancing is built once (rtmesh.scene.instances), the others copied
    held = {mesh: held_copies(sizes[mesh][1], placed) for mesh, placed in placements.items()}
    vertices = sum(held[mesh] * sizes[mesh][0] for mesh in held)
    triangles = sum(held[mesh] * sizes[mesh][1] for mesh in held)
    return copies, vertices, triangles


def _local_matrix(node):
    """A node's local transform: ``matrix`` (column-major) or T @ R @ S."""
    if "matrix" in node:
        return np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T
    x, y, z, w = node.get("rotation", (0.0, 0.0, 0.0, 1.0))
    rotation = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
    matrix = np.eye(4)
    matrix[:3, :3] = rotation * np.asarray(node.get("scale", (1.0, 1.0, 1.0)), dtype=np.float64)[None, :]
    matrix[:3, 3] = node.get("translation", (0.0, 0.0, 0.0))
    return matrix


def _frame(matrix):
    """Position, forward (-Z) and up (+Y) of a node's world matrix, unit directions; None
    for a matrix that is not finite or scales an axis to zero (a hidden node)."""
    if not np.isfinite(matrix).all():
        return None
    position = matrix[:3, 3].copy()
    forward = matrix[:3, :3] @ np.array([0.0, 0.0, -1.0])
    up = matrix[:3, :3] @ np.array([0.0, 1.0, 0.0])
    lengths = np.array([np.linalg.norm(forward), np.linalg.norm(up)])
    if not (np.isfinite(matrix).all() and (lengths > 0.0).all()):
        return None
    return position, forward / lengths[0], up / lengths[1]


def _placed(transform, world):
    """``transform @ world``; a non-finite world matrix (a broken node) stays non-finite
    without a NumPy warning, for :func:`_frame` to refuse."""
    with np.errstate(invalid="ignore", over="ignore"):
        return transform @ world


def _hidden(source, what, node):
    log.warning("%s: %s node '%s' has a zero scale (or a non-finite transform); skipped",
                source, what, node.get("name", "?"))


def cameras_from_gltf(doc, transform=None, source="gltf"):
    """Perspective and orthographic cameras of the file's camera nodes.

    Parameters
    ----------
    doc : dict
        glTF JSON.
    transform : (4, 4) float, optional
        Applied after the nodes' world transforms (the scene file's object transform).
    source : str
        For warnings.

    Returns
    -------
    list of (names, Camera)
        ``names`` is a tuple of the names the camera answers to: the node's and the camera's.
    """
    transform = np.eye(4) if transform is None else np.asarray(transform, dtype=np.float64)
    cameras = doc.get("cameras", [])
    out = []
    for index, world in node_world_transforms(doc):
        node = doc["nodes"][index]
        if "camera" not in node:
            continue
        spec = cameras[node["camera"]]
        names = tuple(n for n in (node.get("name"), spec.get("name")) if n)
        kind = spec.get("type")
        if kind not in ("perspective", "orthographic") or kind not in spec:
            log.warning("%s: camera %s is %s, neither perspective nor orthographic; skipped", source,
                        names[0] if names else node["camera"], kind)
            continue
        frame = _frame(_placed(transform, world))
        if frame is None:
            _hidden(source, "camera", node)
            continue
        position, forward, up = frame
        if kind == "perspective":
            camera = Camera(position, position + forward, up,
                            fov=math.degrees(float(spec["perspective"]["yfov"])))
        else:
            # ymag is half the view's height in the camera's node frame: scaled by the node
            # transform's scale along its up axis
            up_scale = float(np.linalg.norm((transform @ world)[:3, :3] @ [0.0, 1.0, 0.0]))
            camera = Camera(position, position + forward, up, projection="orthographic",
                            ortho_height=2.0 * float(spec["orthographic"]["ymag"]) * up_scale)
        out.append((names, camera))
    return out


def lights_from_gltf(doc, transform=None, source="gltf", physical=False):
    """rtmesh lights of the file's KHR_lights_punctual light nodes (see the module docstring
    for the unit conversion; ``physical``: the path integrator's units).  ``source`` names
    the file in warnings (a light node with a zero scale is skipped).

    Parameters
    ----------
    transform : (4, 4) or (k, 4, 4) float, optional
        Where the file is placed; with ``k`` transforms (a file placed ``k`` times) each of
        its lights is placed ``k`` times, placement by placement.

    Returns
    -------
    list of PointLight, SpotLight or DirectionalLight
    """
    transforms = (np.eye(4) if transform is None else np.asarray(transform, dtype=np.float64)).reshape(-1, 4, 4)
    table = doc.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights", [])
    out = []
    nodes = list(node_world_transforms(doc))
    for j, placement in enumerate(transforms):
        for index, world in nodes:
            ref = doc["nodes"][index].get("extensions", {}).get("KHR_lights_punctual")
            if ref is None:
                continue
            i = ref.get("light") if isinstance(ref, dict) else None
            if not (isinstance(i, int) and not isinstance(i, bool) and 0 <= i < len(table)):
                raise MeshError(f"{source}: nodes[{index}].extensions.KHR_lights_punctual.light: {i!r} is not "
                                f"one of the file's {len(table)} lights")
            frame = _frame(_placed(placement, world))
            if frame is None:
                if j == 0:  # (placements are not singular: the node's own scale, once)
                    _hidden(source, "light", doc["nodes"][index])
                continue
            out.append(_light_at(table[i], frame, physical, f"KHR_lights_punctual.lights[{i}]", source))
    return out


def _light_at(spec, frame, physical, where=None, source=None):
    """The light of a KHR_lights_punctual entry ``spec`` at a node's ``frame`` (as
    :func:`_frame` gives it).

    Its values must be ones a scene file accepts for its own lights (docs/SCENE_FORMAT.md):
    ``color`` 3 numbers >= 0 and ``intensity`` a number >= 0, each finite and 0 or of a
    magnitude from 1e-18 to 1e18, and their product at most 1e18 (the largest intensity a
    scene file takes); ``type`` point, spot or directional; spot cone angles from 0 to pi
    with ``innerConeAngle`` at most ``outerConeAngle``.

    Parameters
    ----------
    where : str, optional
        The entry's key in messages, ``KHR_lights_punctual.lights[0]``.
    source : str, optional
        The file: with it a bad value is a one-line MeshError ``m.gltf:
        KHR_lights_punctual.lights[0].color: ...``; without, a ValueError with the key and
        the problem (:func:`file_cameras_and_lights` names the file).

    Raises
    ------
    MeshError or ValueError
        A value the scene file would refuse, or an unknown light type.
    """
    from rtmesh.loaders.scene_keys import MAX_NUMBER, _colour, _non_negative

    def refuse(key, problem):
        name = f"{where}.{key}" if where else f"KHR_lights_punctual light {key}"
        if source is None:
            raise ValueError(f"{name}: {problem}")
        raise MeshError(f"{source}: {name}: {problem}")

    def read(key, reader, value):
        try:
            return reader(value)
        except TypeError as exc:
            refuse(key, f"{exc} (got {value!r})")

    if not isinstance(spec, dict):
        refuse("type", f"expected a light (a JSON object), not {spec!r}")
    kind = spec.get("type")
    if kind not in ("point", "spot", "directional"):
        refuse("type", f"expected 'point', 'spot' or 'directional' (got {kind!r})")
    colour = spec.get("color", [1.0, 1.0, 1.0])
    if not isinstance(colour, list):
        refuse("color", f"expected a list of 3 numbers (got {colour!r})")
    colour = read("color", _colour, colour)
    candela = read("intensity", _non_negative, spec.get("intensity", 1.0))
    if (colour * candela > MAX_NUMBER).any():
        refuse("intensity", f"color x intensity {float(np.max(colour * candela)):g} is more than the largest "
                            f"intensity a scene file takes ({MAX_NUMBER:g})")
    position, direction, _ = frame
    # photometric value -> rtmesh units: viewers show cd / d^2 * kd / pi; Whitted has no 1/pi
    power = colour * candela / (1.0 if physical else math.pi)
    if kind == "point":
        return PointLight(position, power)
    if kind == "directional":
        return DirectionalLight(direction, power)
    cone = spec.get("spot", {})
    if not isinstance(cone, dict):
        refuse("spot", f"expected an object with innerConeAngle and outerConeAngle (got {cone!r})")
    inner = read("spot.innerConeAngle", _non_negative, cone.get("innerConeAngle", 0.0))
    outer = read("spot.outerConeAngle", _non_negative, cone.get("outerConeAngle", math.pi / 4.0))
    if outer > math.pi:
        refuse("spot.outerConeAngle", f"expected radians from 0 to pi (got {outer:g})")
    if inner > outer:
        # as a scene file refuses inner_angle > outer_angle
        refuse("spot.innerConeAngle", f"{inner:g} is more than spot.outerConeAngle {outer:g} (the cone's "
                                      "full-intensity part must lie inside it)")
    return SpotLight(position, direction, power, math.degrees(inner), math.degrees(outer))


def file_cameras_and_lights(path, transform=None, physical=False, light_transforms=None, lights=True):
    """Cameras and lights of a mesh file: empty lists unless it is glTF (lights in the path
    integrator's units when ``physical``), placed by ``transform`` ((4, 4)); the lights by
    each of ``light_transforms`` ((k, 4, 4)) instead when given (a file placed k times).
    Without ``lights`` no light is read (nor warned about).

    Returns
    -------
    cameras : list of (names, Camera)
    lights : list

    Raises
    ------
    MeshError
        Unreadable glTF JSON or a malformed camera or light.
    """
    path = os.fspath(path)
    if os.path.splitext(path)[1].lower() not in GLTF_EXTENSIONS:
        return [], []
    doc = read_gltf_json(path)
    try:
        return (cameras_from_gltf(doc, transform, source=path),
                lights_from_gltf(doc, transform if light_transforms is None else light_transforms, source=path,
                                 physical=physical) if lights else [])
    except (KeyError, IndexError, TypeError, ValueError, AttributeError) as exc:
        # a camera or light entry that breaks the glTF schema (a bad index, a missing yfov)
        raise MeshError(f"{path}: malformed glTF camera or light: {type(exc).__name__}: {exc}") from None
