"""trimesh -> rtmesh: meshes, scene graphs and their materials as :class:`MeshPart` lists."""

import logging
import os

import numpy as np
import trimesh

from rtmesh.core.errors import MeshError
from rtmesh.geometry import build_kernels
from rtmesh.geometry.smoothing import CREASE_ANGLE, smooth_vertex_normals
from rtmesh.io.colour import srgb_to_linear
from rtmesh.io.texture_images import Texture
from rtmesh.loaders.gltf_nodes import GLTF_EXTENSIONS, file_cameras_and_lights, read_gltf_json
from rtmesh.loaders.material_files import gltf_json_materials, gltf_material, mtl_material, obj_materials
from rtmesh.materials.table import Material
from rtmesh.scene.model import MeshPart, Scene

log = logging.getLogger(__name__)

MESH_EXTENSIONS = (".obj", ".ply", ".stl", ".glb", ".gltf", ".off")


def load_trimesh(path):
    """Read a mesh file with trimesh as a scene graph.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    trimesh.Scene

    Raises
    ------
    MeshError
        Missing file, unknown format, or a file trimesh cannot parse.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise MeshError(f"{path}: no such mesh file")
    ext = os.path.splitext(path)[1].lower()
    if ext not in MESH_EXTENSIONS:
        raise MeshError(f"{path}: unsupported mesh format {ext or '(none)'!r}; use "
                        + ", ".join(MESH_EXTENSIONS))
    try:
        if ext in GLTF_EXTENSIONS:
            scene = trimesh.load(path, force="scene")  # trimesh leaves glTF meshes unprocessed
        else:
            # trimesh's processing, done by process() where it changes something
            scene = trimesh.load(path, force="scene", process=False)
            for geometry in scene.geometry.values():
                if isinstance(geometry, trimesh.Trimesh) and not geometry.metadata.get("processed"):
                    process(geometry)
    except Exception as exc:  # trimesh raises many types for malformed files
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise MeshError(f"{path}: cannot read mesh: {detail}") from exc
    # parts_from_trimesh reads the file's own materials (MTL maps, glTF extensions)
    scene.metadata["rtmesh_file_materials"] = FileMaterials(path)
    return scene


def process(mesh):
    """What ``trimesh.load`` does to each mesh by default (``Trimesh.process``), faster.

    trimesh's processing drops non-finite vertices and merges duplicate ones (equal after
    rounding to ``trimesh.tol.merge``, with equal texture coordinates and normals); its
    merge sorts the vertices, 0.4 s for a mesh of a million triangles.  Most files have no
    duplicate vertices: one hash-table pass (:func:`rtmesh.geometry.build_kernels.rows_distinct`)
    shows that the merge would keep every vertex where it is, and trimesh's own processing
    runs only where it would not.  Either way the mesh's arrays come out the same.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Loaded with ``process=False``; processed in place.
    """
    if not mesh.is_empty and _merge_keeps_everything(mesh):
        mesh.metadata["processed"] = True
    else:
        mesh.process()


def _merge_keeps_everything(mesh):
    """True when trimesh's processing would change nothing: every vertex finite and used by
    a face, and no two vertices at the same position as trimesh rounds positions (distinct
    positions make distinct rows whatever texture coordinates or normals it also compares).
    """
    vertices, faces = mesh.vertices.view(np.ndarray), mesh.faces.view(np.ndarray)
    if not build_kernels.referenced_and_finite(vertices, faces):
        return False
    # trimesh.grouping.merge_vertices: positions scaled to whole units of tol.merge, rounded
    digits = trimesh.util.decimal_to_digits(trimesh.tol.merge)
    return build_kernels.rows_distinct((vertices * (10**digits)).round().astype(np.int64))


def _file_has_vertex_normals(mesh):
    """True when the loader stored normals read from the file (trimesh keeps them cached)."""
    cache = getattr(getattr(mesh, "_cache", None), "cache", {})
    return "vertex_normals" in cache


def material_from_trimesh(visual, name, file_materials=None):
    """Map a trimesh visual's material onto rtmesh's :class:`Material`.

    glTF PBR materials go through :func:`rtmesh.loaders.material_files.gltf_material` (with the
    file's material extensions when known); OBJ materials are taken from the file's own MTL
    statements by name (:func:`rtmesh.loaders.material_files.obj_materials`) when the file is known,
    else from trimesh's parsed statements.  Face colours give their mean as the diffuse
    colour (vertex colours are carried per vertex, see :func:`vertex_colours`).

    Parameters
    ----------
    visual : trimesh visual or None
    name : str
    file_materials : FileMaterials, optional

    Returns
    -------
    Material
    """
    material = getattr(visual, "material", None)
    if isinstance(material, trimesh.visual.material.PBRMaterial):
        json_material = file_materials.gltf.get(material.name) if file_materials else None
        return gltf_material(material, json_material, name)
    if isinstance(material, trimesh.visual.material.SimpleMaterial):
        if file_materials is not None and file_materials.obj is not None:
            found = file_materials.obj.get(material.name)
            return found if found is not None else Material(name=material.name or name)
        return _simple_material(material, name)
    colours = getattr(visual, "main_color", None)
    if getattr(visual, "kind", None) == "face" and colours is not None:
        return Material(name=name, diffuse=srgb_to_linear(np.asarray(colours, dtype=np.float64)[:3] / 255.0))
    return Material(name=name)


def _simple_material(material, name):
    """A trimesh ``SimpleMaterial`` not read from a known file (built in code)."""
    statements = {k.lower(): " ".join(str(x) for x in np.atleast_1d(v))
                  for k, v in (getattr(material, "kwargs", None) or {}).items()}
    for key, value in (("kd", material.diffuse), ("ka", material.ambient), ("ks", material.specular)):
        if key not in statements and value is not None:
            statements[key] = " ".join(str(x / 255.0) for x in np.asarray(value)[:3])
    result = mtl_material(statements, material.name or name, ".")
    image = getattr(material, "image", None)
    if image is not None and not _is_placeholder(material):
        result.diffuse_texture = Texture.from_pil(image, srgb=True, name=f"{result.name} image")
    return result


def _is_placeholder(material):
    """trimesh's stand-in for a missing material: no name, no statements, a tiny flat image."""
    image = getattr(material, "image", None)
    return (material.name is None and not getattr(material, "kwargs", None) and image is not None
            and image.size[0] * image.size[1] <= 4)


class FileMaterials:
    """What the materials of a mesh file need beyond trimesh's visuals.

    Attributes
    ----------
    obj : dict of str to Material or None
        An OBJ file's MTL materials by name (None for other formats).
    gltf : dict of str to dict
        A glTF file's material objects (JSON) by material name.
    drop_vertex_colours : bool
        The file's vertex colours are unusable (NaN in an OBJ: trimesh reads them as black).
    """

    def __init__(self, path=None):
        self.obj, self.gltf, self.drop_vertex_colours = None, {}, False
        if path is None:
            return
        ext = os.path.splitext(path)[1].lower()
        if ext == ".obj":
            self.obj, nan_vertices = obj_materials(path)
            if nan_vertices:
                log.warning("%s: %d vertices hold NaN values; the vertex colours are ignored",
                            os.path.basename(path), nan_vertices)
                self.drop_vertex_colours = True
        elif ext in GLTF_EXTENSIONS:
            self.gltf = gltf_json_materials(read_gltf_json(path))


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


def parts_from_trimesh(obj, name="mesh", transform=None, material=None, smooth=None):
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

    Returns
    -------
    parts : list of MeshPart
    materials : list of Material
        Imported materials, indexed by the parts' ``material`` (empty if ``material`` given).
    """
    transform = np.eye(4) if transform is None else np.asarray(transform, dtype=np.float64)
    if isinstance(obj, trimesh.Trimesh):
        nodes = [(name, np.eye(4), obj)]
    elif isinstance(obj, trimesh.Scene):
        nodes = []
        for node in obj.graph.nodes_geometry:
            node_transform, geometry_name = obj.graph[node]
            nodes.append((str(node), node_transform, obj.geometry[geometry_name]))
    else:
        raise MeshError(f"{name}: expected a trimesh.Trimesh or trimesh.Scene, got {type(obj).__name__}")

    file_materials = getattr(obj, "metadata", {}).get("rtmesh_file_materials")
    parts, materials, material_ids = [], [], {}
    for node_name, node_transform, mesh in nodes:
        if not isinstance(mesh, trimesh.Trimesh):
            log.warning("%s: node '%s' is a %s, not a triangle mesh; skipped",
                        name, node_name, type(mesh).__name__)
            continue
        if len(mesh.faces) == 0:
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
        matrix = transform @ node_transform
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
                materials.append(material_from_trimesh(visual, node_name, file_materials))
            mat = material_ids[key]
        else:
            mat = material
        parts.append(MeshPart(node_name, vertices, faces, mat, normals, uv=uv, vertex_colors=colours))
    return parts, materials


def scene_from_trimesh(obj, name="mesh", **scene_options):
    """A renderable :class:`Scene` from a trimesh mesh or scene (auto camera and lights).

    Parameters
    ----------
    obj : trimesh.Trimesh or trimesh.Scene
    name : str
        Used in messages.
    **scene_options
        Passed to :meth:`Scene.from_parts` (``camera``, ``lights``, ``ambient``, ``background``).
    """
    parts, materials = parts_from_trimesh(obj, name)
    if not parts:
        raise MeshError(f"{name}: nothing to render (no triangles)")
    scene_options.setdefault("ambient", np.full(3, 0.05))
    return Scene.from_parts(parts, materials, source=name, **scene_options)


def load_mesh_scene(path, **scene_options):
    """A renderable :class:`Scene` from a mesh file.

    A glTF file's first camera (perspective or orthographic) and its KHR_lights_punctual lights are used when
    it has them (see :mod:`rtmesh.loaders.gltf_nodes`); otherwise an automatic camera frames the
    mesh and the default light rig lights it.
    """
    obj = load_trimesh(path)
    cameras, lights = file_cameras_and_lights(path)
    if cameras:
        scene_options.setdefault("camera", cameras[0][1])
    if lights:
        scene_options.setdefault("lights", lights)
    return scene_from_trimesh(obj, name=os.fspath(path), **scene_options)
