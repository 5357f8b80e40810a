"""A trimesh mesh or scene graph flattened into rtmesh's :class:`MeshPart` list: node
transforms applied, normals from the file or smoothed by angle, texture coordinates and
vertex colours carried, materials imported, meshes placed many times kept as
:class:`Placement`, and the nodes that cannot be rendered skipped with one warning a kind."""

import collections
import logging

import numpy as np
import trimesh

from rtmesh.core.errors import MeshError
from rtmesh.geometry import build_kernels
from rtmesh.geometry.smoothing import CREASE_ANGLE, smooth_vertex_normals
from rtmesh.io.colour import srgb_to_linear
from rtmesh.loaders.trimesh_materials import material_from_trimesh
from rtmesh.scene.instances import worth_instancing
from rtmesh.scene.model import MeshPart, Placement

log = logging.getLogger(__name__)


def _file_has_vertex_normals(mesh):
    """True when the loader stored normals read from the file (trimesh keeps them cached)."""
    cache = getattr(getattr(mesh, "_cache", None), "cache", {})
    return "vertex_normals" in cache


def vertex_colours(mesh):
    """Linear RGBA vertex colours of a trimesh mesh, (v, 4) float, or None.

    glTF's COLOR_0 is linear already; every other format's 8-bit colours are sRGB-encoded.
    """
    visual = mesh.visual
    colours = None
    if getattr(visual, "kind", None) == "vertex" and isinstance(visual, trimesh.visual.ColorVisuals):
        colours = visual.vertex_colors
    elif hasattr(visual, "vertex_attributes"):
        colours = visual.vertex_attributes.get("color")
    if colours is None or len(colours) != len(mesh.vertices):
        return None
    colours = np.asarray(colours, dtype=np.float64)
    if colours.max(initial=0.0) > 1.0 or np.asarray(colours).dtype.kind in "ui":
        colours = colours / 255.0
    if "from_gltf_primitive" not in getattr(mesh, "metadata", {}):
        colours = np.concatenate([srgb_to_linear(colours[:, :3]), colours[:, 3:]], axis=1)
    return colours


def parts_from_trimesh(obj, name="mesh", transform=None, material=None, smooth=None, placements=None):
    """Flatten a trimesh object (mesh or scene graph) into world-space parts.

    Parameters
    ----------
    obj : trimesh.Trimesh or trimesh.Scene
    name : str
        Name for a bare mesh (scene-graph nodes keep their own names).
    transform : (4, 4) float, optional
        Applied after each node's own transform.
    material : int, optional
        Material index for every part; None imports each geometry's own material.
    smooth : bool, optional
        True forces smooth shading, False flat; None uses the file's vertex normals where it
        has them and smooths by angle where it does not (split along edges of 20 degrees
        or more, see :mod:`rtmesh.geometry.smoothing`).
    placements : list, optional
        Given, a mesh that several nodes place and that is large enough to pay
        (:func:`rtmesh.scene.instances.worth_instancing`) is appended to it as one
        :class:`~rtmesh.scene.model.Placement` (the mesh once, in its own coordinates, and
        each node's transform) instead of a copy per node.

    Returns
    -------
    parts : list of MeshPart
    materials : list of Material
        Imported materials, indexed by the parts' ``material`` (empty if ``material`` given).
    """
    transform = np.eye(4) if transform is None else np.asarray(transform, dtype=np.float64)
    skipped = {kind: [] for kind in _SKIPPED}  # node names by why they are not rendered
    if isinstance(obj, trimesh.Trimesh):
        nodes = [(name, np.eye(4), obj)]
    elif isinstance(obj, trimesh.Scene):
        nodes = []
        for node in obj.graph.nodes_geometry:
            try:
                # a non-finite node matrix composes without a NumPy warning; such a node is
                # skipped below with one of ours
                with np.errstate(invalid="ignore", over="ignore"):
                    node_transform, geometry_name = obj.graph[node]
            except ValueError:  # trimesh: "Iteration limit exceeded!"
                skipped["unplaced"].append(str(node))
                continue
            nodes.append((str(node), node_transform, obj.geometry[geometry_name]))
    else:
        raise MeshError(f"{name}: expected a trimesh.Trimesh or trimesh.Scene, got {type(obj).__name__}")

    file_materials = getattr(obj, "metadata", {}).get("rtmesh_file_materials")
    parts, materials, material_ids = [], [], {}
    # meshes built once and placed by instances: id(mesh) -> (prototype part, transforms, names)
    uses = collections.Counter(id(mesh) for _, _, mesh in nodes)
    placed = {}
    for node_name, node_transform, mesh in nodes:
        if not isinstance(mesh, trimesh.Trimesh):
            skipped["not_a_mesh"].append(f"{node_name} ({type(mesh).__name__})")
            continue
        if len(mesh.faces) == 0:
            continue
        if mesh.vertices.ndim != 2 or mesh.vertices.shape[1] != 3:
            # (a glTF file's are checked before trimesh reads it: gltf_checks.check_document)
            raise MeshError(f"{name}: node '{node_name}': vertices of {mesh.vertices.shape[-1]} coordinates; "
                            "positions must be 3D")
        instanced = placements is not None and worth_instancing(len(mesh.faces), uses[id(mesh)])
        if instanced and id(mesh) in placed:
            # the mesh is built already: only this node's placement
            with np.errstate(invalid="ignore", over="ignore"):
                matrix = transform @ node_transform
            if not (np.isfinite(matrix).all() and np.linalg.det(matrix[:3, :3]) != 0.0):
                skipped["hidden"].append(node_name)
                continue
            placed[id(mesh)][1].append(matrix)
            placed[id(mesh)][2].append(node_name)
            continue
        # the material and per-vertex attributes come from the mesh as loaded
        visual = mesh.visual
        uv = getattr(visual, "uv", None)
        uv = None if uv is None or len(uv) != len(mesh.vertices) else np.asarray(uv, dtype=np.float64)
        colours = None if file_materials and file_materials.drop_vertex_colours else vertex_colours(mesh)
        vertices, faces, normals = np.asarray(mesh.vertices), np.asarray(mesh.faces), None
        if smooth is not False:
            if _file_has_vertex_normals(mesh):
                normals = np.asarray(mesh.vertex_normals)
            else:
                # split at creases (unless smooth shading is forced), smooth elsewhere;
                # per-vertex attributes follow the vertices they were split from
                vertices, faces, normals, original = smooth_vertex_normals(
                    vertices, faces, CREASE_ANGLE if smooth is None else None)
                uv = None if uv is None else uv[original]
                colours = None if colours is None else colours[original]
        with np.errstate(invalid="ignore", over="ignore"):  # a non-finite node: skipped next
            matrix = transform @ node_transform
        if not (np.isfinite(matrix).all() and np.linalg.det(matrix[:3, :3]) != 0.0):
            # exporters hide parts with a zero scale: nothing of them would be seen
            skipped["hidden"].append(node_name)
            continue
        # the mesh in its own coordinates, which a placed mesh keeps
        model = (vertices, faces, normals)
        vertices = trimesh.transform_points(vertices, matrix)
        if np.linalg.det(matrix[:3, :3]) < 0:
            faces = faces[:, ::-1]  # a mirroring transform flips the winding
        if normals is not None:
            # normals transform with the inverse transpose of the linear part; the identity
            # leaves finite normals as they are (unless a -0.0 would turn +0.0), so a mesh
            # placed as it is skips the product
            normal_matrix = np.linalg.inv(matrix[:3, :3]).T
            if not (np.array_equal(normal_matrix, np.eye(3))
                    and build_kernels.finite_without_negative_zero(normals)):
                with np.errstate(invalid="ignore"):
                    normals = normals @ normal_matrix.T
        if material is None:
            key = id(getattr(visual, "material", visual))
            if key not in material_ids:
                material_ids[key] = len(materials)
                try:
                    materials.append(material_from_trimesh(visual, node_name, file_materials))
                except MeshError as exc:  # a texture of the file: name the file too
                    raise MeshError(f"{name}: {exc}") from None
            mat = material_ids[key]
        else:
            mat = material
        if instanced:
            # built once in its own coordinates; each placement's transform takes it to the world
            part = MeshPart(node_name, model[0], model[1], mat, model[2], uv=uv, vertex_colors=colours)
            placed[id(mesh)] = (part, [matrix], [node_name])
            continue
        parts.append(MeshPart(node_name, vertices, faces, mat, normals, uv=uv, vertex_colors=colours,
                              to_world=matrix))
    for part, matrices, names in placed.values():
        placements.append(Placement(part, np.array(matrices), names))
    for kind, names in skipped.items():
        if names:
            log.warning("%s: %s", name, _SKIPPED[kind](names))
    return parts, materials


def _listed(names, most=5):
    """``'a', 'b', 'c'`` or ``'a', ..., 'e' and 7 more``: node names in a warning, sorted."""
    names = sorted(names)
    shown = ", ".join(f"'{n}'" for n in names[:most])
    return shown if len(names) <= most else f"{shown} and {len(names) - most} more"


def _nodes(names):
    return f"node {_listed(names)} has" if len(names) == 1 else f"{len(names)} nodes ({_listed(names)}) have"


# the nodes parts_from_trimesh skips, one warning a kind and file
_SKIPPED = {
    "unplaced": lambda names: (f"{_nodes(names)} no transform from the scene's root (a cycle in the node "
                               "graph, which glTF forbids); skipped"),
    "not_a_mesh": lambda names: (f"{_nodes(names)} no triangle mesh (a path or point cloud); skipped"),
    "hidden": lambda names: (f"{_nodes(names)} a zero scale (a singular transform, which hides it) or a "
                             "non-finite one; not rendered"),
}
