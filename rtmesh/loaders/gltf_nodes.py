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
