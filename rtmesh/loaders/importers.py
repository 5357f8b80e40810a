"""Mesh files in: any file rtmesh renders (trimesh's formats and USD) read into parts, or
into a renderable :class:`Scene` with its own camera and lights; trimesh's formats read as
trimesh scene graphs (:func:`load_trimesh`), which :mod:`rtmesh.loaders.trimesh_parts`
flattens into :class:`MeshPart` lists."""

import io
import logging
import os

import numpy as np
import trimesh

from rtmesh.core.errors import MeshError, RtmeshError
from rtmesh.io.texture_images import image_size_guard
from rtmesh.loaders import gltf_compression
from rtmesh.loaders.gltf_checks import check_document
from rtmesh.loaders.gltf_nodes import (GLTF_EXTENSIONS, check_external_files, check_node_graph, file_cameras_and_lights,
                                       flattened_size, read_gltf_json)
from rtmesh.loaders.mesh_files import check_content, check_file, format_name
from rtmesh.loaders.mesh_processing import drop_bad_index_faces, process
from rtmesh.loaders.obj_polygons import triangulate_polygons
from rtmesh.loaders.placements import copied
from rtmesh.loaders.trimesh_materials import FileMaterials
from rtmesh.loaders.trimesh_parts import parts_from_trimesh
from rtmesh.loaders.usd_files import load_usd_scene, read_usd
from rtmesh.loaders.usd_stage import USD_EXTENSIONS
from rtmesh.materials.table import PHYSICAL_MODELS
from rtmesh.rendering import memory
from rtmesh.scene.model import Scene

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
    """trimesh's scene of a mesh file, processed (see :func:`process`).

    trimesh's readers cast the file's floats to integers to group them (a PLY file's
    per-face texture coordinates, ``grouping.unique_rows``), which NumPy warns about for NaN
    and infinite values; such values are dropped or replaced later with rtmesh's own
    warning (faces with non-finite vertices here, texture coordinates and colours by
    :meth:`Scene.from_parts`), so within trimesh's reading NumPy's invalid-value warnings
    are off (``np.errstate``: this thread only, restored after).
    """
    if ext in GLTF_EXTENSIONS:
        # trimesh leaves glTF meshes unprocessed
        source = _gltf_source(path, ext)
        with np.errstate(invalid="ignore"):
            scene = trimesh.load(**source, force="scene")
        for key, geometry in scene.geometry.items():
            if isinstance(geometry, trimesh.Trimesh) and geometry.faces.ndim == 2 and len(geometry.faces):
                drop_bad_index_faces(geometry, _geometry_source(path, scene, key))
        return scene
    # trimesh's processing, done by process() where it changes something
    source = _obj_source(path, ext)
    with np.errstate(invalid="ignore"):
        scene = trimesh.load(**source, force="scene", process=False)
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
    # bad indices and accessors in one line, not trimesh's bare exceptions (the data of a file
    # gltf_compression rewrites: checked as it reads it)
    decoded = gltf_compression.uses_decoded_extensions(doc)
    check_document(path, doc, extents=not decoded)
    copies, vertices, triangles = flattened_size(doc)
    memory.check_load(path, f"{copies} mesh nodes of {triangles} triangles in all, copied where not instanced",
                      memory.load_estimate(vertices, triangles, copies))
    if not decoded:
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
    text with them ear-clipped (:mod:`rtmesh.loaders.obj_polygons`), or without the UTF-8
    byte order mark it starts with (trimesh would read the first line's ``v`` as ``\\ufeffv``
    and lose that vertex), materials resolved as beside the file."""
    if ext == ".obj":
        with open(path, "rb") as f:
            data = f.read()
        bom = data.startswith(_UTF8_BOM)
        data = data[len(_UTF8_BOM):] if bom else data
        text = triangulate_polygons(data)
        text = data if text is None and bom else text
        if text is not None:
            return dict(file_obj=io.BytesIO(text), file_type="obj",
                        resolver=trimesh.resolvers.FilePathResolver(path))
    return dict(file_obj=path)


_UTF8_BOM = b"\xef\xbb\xbf"


def _geometry_source(path, scene, key):
    """``file`` or ``file: object 'name'`` (for a file of several objects) in messages."""
    name = os.path.basename(path)
    return name if len(scene.geometry) == 1 else f"{name}: object '{key}'"


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
