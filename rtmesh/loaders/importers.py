"""trimesh -> rtmesh: meshes, scene graphs and their materials as :class:`MeshPart` lists."""

import collections
import io
import logging
import os

import numpy as np
import trimesh

from rtmesh.core.errors import MeshError, RtmeshError
from rtmesh.geometry import build_kernels
from rtmesh.geometry.smoothing import CREASE_ANGLE, smooth_vertex_normals
from rtmesh.io.colour import srgb_to_linear
from rtmesh.io.texture_images import Texture, image_size_guard
from rtmesh.loaders import gltf_compression
from rtmesh.loaders.gltf_nodes import (GLTF_EXTENSIONS, check_external_files, check_node_graph,
                                       file_cameras_and_lights, flattened_size, read_gltf_json)
from rtmesh.loaders.gltf_images import GltfImages
from rtmesh.loaders.gltf_materials import gltf_json_materials, gltf_material
from rtmesh.loaders.mtl_materials import mtl_material, obj_materials
from rtmesh.loaders.mesh_files import check_content, check_file, format_name
from rtmesh.loaders.obj_polygons import triangulate_polygons
from rtmesh.loaders.placements import copied
from rtmesh.loaders.usd_files import USD_EXTENSIONS, load_usd_scene, read_usd
from rtmesh.materials.table import PHYSICAL_MODELS, Material
from rtmesh.rendering import memory
from rtmesh.scene.instances import worth_instancing
from rtmesh.scene.model import MeshPart, Placement, Scene

log = logging.getLogger(__name__)

# files trimesh reads
TRIMESH_EXTENSIONS = (".obj", ".ply", ".stl", ".glb", ".gltf", ".off")
# every mesh file rtmesh renders: trimesh's and USD (rtmesh.loaders.usd_files)
MESH_EXTENSIONS = TRIMESH_EXTENSIONS + USD_EXTENSIONS


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
    check_file(path)
    ext = os.path.splitext(path)[1].lower()
    if ext in USD_EXTENSIONS:
        raise MeshError(f"{path}: a USD file is not a trimesh scene (read it with mesh_file_parts or "
                        "load_mesh_scene)")
    if ext not in TRIMESH_EXTENSIONS:
        raise MeshError(f"{path}: unsupported mesh format {ext or '(none)'!r}; use "
                        + ", ".join(MESH_EXTENSIONS))
    check_content(path, ext)
    if ext == ".gltf":
        check_external_files(path, read_gltf_json(path))
    try:
        with image_size_guard(path):  # textures trimesh decodes: too large is one message
            scene = _load(path, ext)
    except RtmeshError:  # ours, one line already (a missing codec is a MissingExtraError)
        raise
    except IndexError as exc:
        raise MeshError(f"{path}: cannot read mesh: a face refers to a vertex the file does not "
                        f"have ({exc})") from exc
    except ImportError as exc:
        # trimesh guesses the encoding of text that is not UTF-8 with an optional module
        raise MeshError(f"{path}: not a valid {format_name(ext)} file (text that is not UTF-8)") from exc
    except Exception as exc:  # trimesh raises many types for malformed files
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise MeshError(f"{path}: cannot read mesh: {detail}") from exc
    # parts_from_trimesh reads the file's own materials (MTL maps, glTF extensions)
    scene.metadata["rtmesh_file_materials"] = FileMaterials(path)
    return scene


def _load(path, ext):
    """trimesh's scene of a mesh file, processed (see :func:`process`)."""
    if ext in GLTF_EXTENSIONS:
        # trimesh leaves glTF meshes unprocessed
        scene = trimesh.load(**_gltf_source(path, ext), force="scene")
        for key, geometry in scene.geometry.items():
            if isinstance(geometry, trimesh.Trimesh) and geometry.faces.ndim == 2 and len(geometry.faces):
                _drop_bad_index_faces(geometry, _geometry_source(path, scene, key))
        return scene
    # trimesh's processing, done by process() where it changes something
    scene = trimesh.load(**_obj_source(path, ext), force="scene", process=False)
    for key, geometry in scene.geometry.items():
        if isinstance(geometry, trimesh.Trimesh) and not geometry.metadata.get("processed"):
            _warn_if_short(geometry, _geometry_source(path, scene, key))
            process(geometry, _geometry_source(path, scene, key))
    return scene


def _gltf_source(path, ext):
    """What trimesh reads of a glTF file: the file, or for one with compressed or quantised
    geometry a plain GLB of it (:mod:`rtmesh.loaders.gltf_compression`), its external
    images resolved as beside the file."""
    doc = read_gltf_json(path)
    check_node_graph(path, doc)
    copies, vertices, triangles = flattened_size(doc)
    memory.check_load(path, f"{copies} mesh nodes of {triangles} triangles in all, copied where not instanced",
                      memory.load_estimate(vertices, triangles, copies))
    if not gltf_compression.uses_decoded_extensions(doc):
        return dict(file_obj=path)
    return dict(file_obj=io.BytesIO(gltf_compression.plain_glb(path, doc)), file_type="glb",
                resolver=trimesh.resolvers.FilePathResolver(path))


def _warn_if_short(mesh, source):
    """Warn when a PLY file holds fewer elements than its header announces (trimesh reads
    what is there without a word): a truncated file, or a lying header."""
    raw = mesh.metadata.get("_ply_raw")
    if not isinstance(raw, dict):
        return
    short = []
    for name, element in raw.items():
        announced, data = element.get("length"), element.get("data")
        if not isinstance(announced, int) or not isinstance(data, dict) or not data:
            continue
        held = min(np.shape(column)[0] if np.ndim(column) else 0 for column in data.values())
        if held < announced:
            short.append(f"{held} of {announced} {name} elements")
    if short:
        log.warning("%s: the file holds fewer elements than its header announces (%s): truncated?",
                    source, ", ".join(short))


def _obj_source(path, ext):
    """What trimesh reads: the file, or for an OBJ with polygons of five or more corners its
    text with them ear-clipped (:mod:`rtmesh.loaders.obj_polygons`), materials resolved as beside
    the file."""
    if ext == ".obj":
        with open(path, "rb") as f:
            text = triangulate_polygons(f.read())
        if text is not None:
            return dict(file_obj=io.BytesIO(text), file_type="obj",
                        resolver=trimesh.resolvers.FilePathResolver(path))
    return dict(file_obj=path)


def _geometry_source(path, scene, key):
    """``file`` or ``file: object 'name'`` (for a file of several objects) in messages."""
    name = os.path.basename(path)
    return name if len(scene.geometry) == 1 else f"{name}: object '{key}'"


def process(mesh, source="mesh"):
    """What ``trimesh.load`` does to each mesh by default (``Trimesh.process``), faster and
    without losing geometry silently or at extreme scales.

    trimesh's processing drops non-finite vertices and merges duplicate ones (equal after
    rounding to ``trimesh.tol.merge``, with equal texture coordinates and normals).  Here:

    - faces that use a vertex with a NaN or infinite coordinate are dropped with a warning
      that counts them (trimesh drops them without a word);
    - vertices merge as trimesh merges them (:func:`merge_vertices`), but at a precision
      relative to the mesh's scale where ``tol.merge`` would be coarse for it (a model
      measured in nanometres), and without trimesh's conversion to 64-bit integers, which
      overflows for coordinates beyond about 1e10 and collapsed every vertex of such a
      model;
    - most files have no duplicate vertices: one hash-table pass
      (:func:`rtmesh.geometry.build_kernels.rows_distinct`) shows that the merge would keep every
      vertex where it is, and the merge (a sort, 0.4 s for a million triangles) runs only
      where it would not.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Loaded with ``process=False``; processed in place.
    source : str
        Names the mesh in warnings.
    """
    build_kernels.BUILD_KERNELS.prepare()
    faces = mesh.faces.view(np.ndarray)
    if mesh.vertices.ndim != 2 or mesh.vertices.shape[1] != 3:
        # trimesh reads every vertex with the column count of some line: one short line
        # (a truncated file) makes all of them 2D
        raise MeshError(f"{source}: vertices of {mesh.vertices.shape[-1]} coordinates, not 3 (a "
                        "vertex statement with too few values: a truncated file?)")
    if mesh.is_empty or faces.ndim != 2 or not len(faces):
        mesh.metadata["processed"] = True  # nothing to process (parts_from_trimesh skips it)
        return
    _drop_bad_index_faces(mesh, source)
    _drop_non_finite_faces(mesh, source)
    digits = merge_digits(mesh.vertices.view(np.ndarray), mesh.faces.view(np.ndarray))
    if not _merge_keeps_everything(mesh, digits):
        # as Trimesh.process: the cache lock keeps the file's normals across the merge
        with mesh._cache:
            merge_vertices(mesh, digits)
            mesh._cache.clear(exclude={"face_normals", "vertex_normals"})
    mesh.metadata["processed"] = True


def _drop_bad_index_faces(mesh, source):
    """Drop the faces that refer to vertices the file does not have, saying how many."""
    faces = mesh.faces.view(np.ndarray)
    if faces.min() >= 0 and faces.max() < len(mesh.vertices):
        return
    bad = ((faces < 0) | (faces >= len(mesh.vertices))).any(axis=1)
    if bad.any():
        log.warning("%s: dropped %d of %d faces that refer to vertices the file does not have",
                    source, int(bad.sum()), len(faces))
        mesh.faces = faces[~bad]


def _drop_non_finite_faces(mesh, source):
    """Drop the faces that use a vertex with a NaN or infinite coordinate, saying how many."""
    vertices, faces = mesh.vertices.view(np.ndarray), mesh.faces.view(np.ndarray)
    if np.isfinite(vertices).all():
        return
    finite = np.isfinite(vertices).all(axis=1)
    bad = ~finite[faces].all(axis=1)
    log.warning("%s: dropped %d of %d faces that use vertices with NaN or infinite coordinates "
                "(%d such vertices)", source, int(bad.sum()), len(faces), int((~finite).sum()))
    mesh.remove_infinite_values()


def merge_digits(vertices, faces):
    """Decimal digits at which vertices merge: trimesh's (``tol.merge``), or finer for a
    mesh whose typical edge is not long against it.

    The tolerance is at most ``MERGE_FRACTION`` of the median edge length (of up to 4096
    faces evenly spread), so merging never collapses the edges of a small model; for every
    model with a typical edge longer than 1e-3 it is trimesh's.

    Parameters
    ----------
    vertices : (v, 3) float
        Finite.
    faces : (f, 3) int

    Returns
    -------
    int
    """
    digits = trimesh.util.decimal_to_digits(trimesh.tol.merge)
    if not len(faces):
        return digits
    sample = faces[::max(1, len(faces) // 4096)]
    corners = vertices[sample]
    lengths = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)
    lengths = lengths[lengths > 0.0]
    if not len(lengths):
        return digits
    tolerance = min(trimesh.tol.merge, MERGE_FRACTION * float(np.median(lengths)))
    return max(digits, trimesh.util.decimal_to_digits(tolerance))


# a merge tolerance at most this fraction of a mesh's median edge (see merge_digits)
MERGE_FRACTION = 1e-5


def _merge_keys(mesh, digits, with_attributes=True):
    """The rows trimesh's merge compares (position, and texture coordinates and normals
    unless ``with_attributes`` is False), rounded as it rounds them, as int64: converted as
    trimesh converts them where they fit, else the bits of the rounded floats (equal rounded
    values have equal bits once ``+ 0.0`` turns -0.0 into 0.0), so that no conversion
    overflows at any scale."""
    stacked = [mesh.vertices.view(np.ndarray) * (10.0**digits)]
    if with_attributes:
        visual = mesh.visual
        if (visual.defined and visual.kind == "texture" and visual.uv is not None
                and len(visual.uv) == len(mesh.vertices)):
            stacked.append(np.asarray(visual.uv, dtype=np.float64) * 1e4)  # trimesh: 4 digits
        normals = mesh._cache["vertex_normals"]
        if np.shape(normals) == mesh.vertices.shape:
            stacked.append(np.asarray(normals, dtype=np.float64) * 1e2)  # trimesh: 2 digits
    keys = np.column_stack(stacked).round()
    if -2.0**62 < keys.min() and keys.max() < 2.0**62:  # False for NaN (texture coordinates)
        return keys.astype(np.int64)  # trimesh's keys exactly (and its fast hashing of them)
    return np.ascontiguousarray(keys + 0.0).view(np.int64)


def merge_vertices(mesh, digits):
    """``trimesh.grouping.merge_vertices`` at ``digits`` (same groups, same order), with the
    rows compared by :func:`_merge_keys` instead of as int64 conversions.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Finite vertices; merged in place.
    digits : int
    """
    referenced = np.zeros(len(mesh.vertices), dtype=bool)
    referenced[mesh.faces] = True
    keys = _merge_keys(mesh, digits)
    unique, inverse_referenced = trimesh.grouping.unique_rows(keys[referenced], keep_order=True)
    inverse = np.zeros(len(mesh.vertices), dtype=np.int64)
    inverse[referenced] = inverse_referenced
    mesh.update_vertices(mask=np.nonzero(referenced)[0][unique], inverse=inverse)


def _merge_keeps_everything(mesh, digits=None):
    """True when the merge would change nothing: every vertex finite and used by a face, and
    no two vertices at the same position as the merge rounds positions (at ``digits``;
    None: :func:`merge_digits`) (distinct positions make distinct rows whatever texture
    coordinates or normals it also compares).
    """
    vertices, faces = mesh.vertices.view(np.ndarray), mesh.faces.view(np.ndarray)
    if not build_kernels.referenced_and_finite(vertices, faces):
        return False
    if digits is None:
        digits = merge_digits(vertices, faces)
    return build_kernels.rows_distinct(_merge_keys(mesh, digits, with_attributes=False))


def _file_has_vertex_normals(mesh):
    """True when the loader stored normals read from the file (trimesh keeps them cached)."""
    cache = getattr(getattr(mesh, "_cache", None), "cache", {})
    return "vertex_normals" in cache


def material_from_trimesh(visual, name, file_materials=None):
    """Map a trimesh visual's material onto rtmesh's :class:`Material`.

    glTF PBR materials go through :func:`rtmesh.loaders.gltf_materials.gltf_material` (with the
    file's material extensions when known); OBJ materials are taken from the file's own MTL
    statements by name (:func:`rtmesh.loaders.mtl_materials.obj_materials`) when the file is known,
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
        return gltf_material(material, json_material, name, file_materials.source if file_materials else None)
    if isinstance(material, trimesh.visual.material.SimpleMaterial):
        if file_materials is not None and file_materials.obj is not None:
            found = file_materials.obj.get(material.name)
            return found if found is not None else Material(name=material.name or name)
        return _simple_material(material, name)
    colours = getattr(visual, "main_color", None)
    if getattr(visual, "kind", None) == "face" and colours is not None:
        return Material(name=name, diffuse=srgb_to_linear(np.asarray(colours, dtype=np.float64)[:3] / 255.0))
    if file_materials is not None and file_materials.gltf_file:
        # a glTF primitive without a material has the format's default material: white,
        # metallic 1, roughness 1 (glTF 2.0 specification, "Materials"), as three.js and the
        # Khronos sample viewer show it
        return gltf_material(trimesh.visual.material.PBRMaterial(name=f"{name} (glTF default)"), None, name)
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
    gltf_file : bool
        The file is glTF: a primitive without a material gets the format's default one.
    source : str or None
        The file's name, for messages.
    """

    def __init__(self, path=None):
        self.obj, self.gltf, self.drop_vertex_colours = None, {}, False
        self.gltf_file = False
        self.source = None if path is None else os.path.basename(path)
        if path is None:
            return
        ext = os.path.splitext(path)[1].lower()
        self.gltf_file = ext in GLTF_EXTENSIONS
        if ext == ".obj":
            self.obj, nan_colours = obj_materials(path)
            if nan_colours:
                log.warning("%s: %d vertex colours hold NaN values; the vertex colours are ignored",
                            os.path.basename(path), nan_colours)
                self.drop_vertex_colours = True
        elif ext in GLTF_EXTENSIONS:
            doc = read_gltf_json(path)
            self.gltf = gltf_json_materials(doc, os.path.basename(path), GltfImages(path, doc))


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
    placements = []
    parts, materials = parts_from_trimesh(obj, name, placements=placements)
    if not parts and not placements:
        raise MeshError(f"{name}: nothing to render (no triangles)")
    if not scene_options.get("physical") and not any(m.model in PHYSICAL_MODELS and not m.unlit
                                                      for m in materials):
        # a little ambient light for the three-light rig; the studio environment of
        # physically based assets lights them from every direction itself
        scene_options.setdefault("ambient", np.full(3, 0.05))
    return Scene.from_parts(parts, materials, source=name, placements=placements, **scene_options)


def default_integrator(path):
    """The integrator a mesh file renders with when none is asked for: ``"path"`` for glTF
    and USD (their formats define physically based materials and lights), ``"whitted"``
    otherwise."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    return "path" if ext in GLTF_EXTENSIONS or ext in USD_EXTENSIONS else "whitted"


def mesh_file_parts(path, name=None, transform=None, material=None, smooth=None, placements=None):
    """The parts and materials of any mesh file rtmesh renders (trimesh's formats and USD),
    without camera or lights (the batch and scene files' objects read files this way).

    Parameters
    ----------
    path : str or os.PathLike
    name : str, optional
        As :func:`parts_from_trimesh`'s (default: the path); USD parts keep their prim paths.
    transform : (4, 4) float, optional
        Applied after the file's own transforms.
    material : int, optional
        Material index for every part; None imports the file's materials.
    smooth : bool, optional
        As :func:`parts_from_trimesh`'s; for USD, False drops the normals and True or None
        keeps them (meshes without normals are smoothed by angle).
    placements : list, optional
        Given, the file's meshes placed many times and worth instancing (glTF node reuse,
        USD point instancers and instanceable prims) are appended to it as
        :class:`~rtmesh.scene.model.Placement` (their transforms after ``transform``);
        None: they are copied into the parts.

    Returns
    -------
    parts : list of MeshPart
    materials : list of Material
        Imported materials, indexed by the parts' ``material`` (empty if ``material`` given).
    """
    path = os.fspath(path)
    if os.path.splitext(path)[1].lower() not in USD_EXTENSIONS:
        return parts_from_trimesh(load_trimesh(path), name or path, transform, material, smooth, placements)
    content = read_usd(path)
    parts, materials = content.parts, content.materials
    for part in parts + [placement.part for placement in content.placements]:
        if smooth is False:
            part.vertex_normals = None
        if material is not None:
            part.material = material
    matrix = None if transform is None else np.asarray(transform, dtype=np.float64)
    if matrix is not None:
        normal_matrix = np.linalg.inv(matrix[:3, :3]).T
        mirrored = np.linalg.det(matrix[:3, :3]) < 0
        for part in parts:
            part.vertices = trimesh.transform_points(part.vertices, matrix)
            part.faces = part.faces[:, ::-1] if mirrored else part.faces
            if part.vertex_normals is not None:
                part.vertex_normals = part.vertex_normals @ normal_matrix.T
    for placement in content.placements:
        if matrix is not None:
            placement.transforms = matrix @ placement.transforms
        if placements is None:  # copied: one part of all the copies
            k, mesh = len(placement.transforms), placement.part
            memory.check_load(path, f"{mesh.name}: {k} copies of {len(mesh.faces)} triangles",
                              memory.load_estimate(k * len(mesh.vertices), k * len(mesh.faces), k))
            parts.append(copied(placement.part, placement.transforms, f"{placement.part.name} ({k} copies)"))
        else:
            placements.append(placement)
    return parts, [] if material is not None else materials


def load_mesh_scene(path, physical=False, **scene_options):
    """A renderable :class:`Scene` from a mesh file.

    A glTF file's first camera (perspective or orthographic) and its KHR_lights_punctual lights are used when
    it has them (see :mod:`rtmesh.loaders.gltf_nodes`); otherwise an automatic camera frames the
    mesh and the default light rig lights it.  ``physical``: the scene is for the path
    integrator (light units and the default rig, :meth:`Scene.from_parts`).
    USD files go through :func:`rtmesh.loaders.usd_files.load_usd_scene` (their cameras
    and lights likewise).
    """
    if os.path.splitext(os.fspath(path))[1].lower() in USD_EXTENSIONS:
        return load_usd_scene(path, physical=physical, **scene_options)
    obj = load_trimesh(path)
    cameras, lights = file_cameras_and_lights(path, physical=physical)
    scene_options["physical"] = physical
    if cameras:
        scene_options.setdefault("camera", cameras[0][1])
    if lights:
        scene_options.setdefault("lights", lights)
    return scene_from_trimesh(obj, name=os.fspath(path), **scene_options)
