"""The materials of a trimesh mesh as rtmesh's :class:`Material`: glTF PBR materials with
the file's material extensions, OBJ materials from the file's own MTL statements, built-in
``SimpleMaterial`` and face colours, and what a file's materials need beyond trimesh's
visuals (:class:`FileMaterials`)."""

import logging
import os

import numpy as np
import trimesh

from rtmesh.io.colour import srgb_to_linear
from rtmesh.io.texture_images import Texture
from rtmesh.loaders.gltf_images import GltfImages
from rtmesh.loaders.gltf_materials import gltf_json_materials, gltf_material
from rtmesh.loaders.gltf_nodes import GLTF_EXTENSIONS, read_gltf_json
from rtmesh.loaders.mtl_materials import mtl_material, obj_materials
from rtmesh.materials.table import Material

log = logging.getLogger(__name__)


def material_from_trimesh(visual, name, file_materials=None):
    """Map a trimesh visual's material onto rtmesh's :class:`Material`.

    glTF PBR materials go through :func:`rtmesh.loaders.gltf_materials.gltf_material` (with the
    file's material extensions when known); OBJ materials are taken from the file's own MTL
    statements by name (:func:`rtmesh.loaders.mtl_materials.obj_materials`) when the file is known,
    else from trimesh's parsed statements.  Face colours give their mean as the diffuse
    colour (vertex colours are carried per vertex, see :func:`rtmesh.loaders.trimesh_parts.vertex_colours`).

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
