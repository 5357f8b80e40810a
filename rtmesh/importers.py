"""trimesh -> rtmesh: meshes, scene graphs and their materials as :class:`MeshPart` lists."""

import logging
import os

import numpy as np
import trimesh

from .errors import MeshError
from .gltf_scene import file_cameras_and_lights
from .materials import Material
from .scene import MeshPart, Scene

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
        return trimesh.load(path, force="scene")
    except Exception as exc:  # trimesh raises many types for malformed files
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise MeshError(f"{path}: cannot read mesh: {detail}") from exc


def _file_has_vertex_normals(mesh):
    """True when the loader stored normals read from the file (trimesh keeps them cached)."""
    cache = getattr(getattr(mesh, "_cache", None), "cache", {})
    return "vertex_normals" in cache


def material_from_trimesh(visual, name):
    """Map a trimesh visual's material onto rtmesh's Blinn-Phong :class:`Material`.

    OBJ/MTL materials (``SimpleMaterial``) give diffuse, specular and shininess directly.
    glTF PBR materials give ``diffuse = base * (1 - metallic)``, a specular colour blended
    from 0.04 (dielectrics) to ``base`` (metals), a shininess from the roughness
    (``2 / r^4 - 2``, the Blinn-Phong exponent with the same highlight width as a GGX lobe of
    roughness ``r^2``), and a tinted mirror reflectance ``base * metallic``.  Vertex and face
    colours give their mean as the diffuse colour.

    Parameters
    ----------
    visual : trimesh visual or None
    name : str

    Returns
    -------
    Material
    """
    material = getattr(visual, "material", None)
    if isinstance(material, trimesh.visual.material.PBRMaterial):
        base = np.asarray(material.baseColorFactor if material.baseColorFactor is not None
                          else [255, 255, 255, 255], dtype=np.float64)
        base = base[:3] / 255.0 if base.max() > 1.0 else base[:3]
        metallic = float(material.metallicFactor if material.metallicFactor is not None else 1.0)
        roughness = float(material.roughnessFactor if material.roughnessFactor is not None else 1.0)
        if material.baseColorTexture is not None:
            # until textures are sampled, the mean texel colour stands in for the texture
            base = base * _mean_texture_colour(material.baseColorTexture)
        r4 = max(roughness, 0.05) ** 4
        return Material(
            name=material.name or name,
            diffuse=base * (1.0 - metallic),
            specular=0.04 * (1.0 - metallic) + base * metallic,
            shininess=float(np.clip(2.0 / r4 - 2.0, 1.0, 10000.0)),
            mirror=base * metallic * (1.0 - roughness),
        )
    if isinstance(material, trimesh.visual.material.SimpleMaterial):
        return _mtl_material(material, name)
    colours = getattr(visual, "main_color", None)
    if colours is not None and getattr(visual, "defined", False):
        return Material(name=name, diffuse=np.asarray(colours, dtype=np.float64)[:3] / 255.0)
    return Material(name=name)


def _mtl_floats(kwargs, key, count):
    """A float or colour statement of an MTL file as trimesh keeps it, or None."""
    value = kwargs.get(key)
    if value is None:
        return None
    try:
        values = np.atleast_1d(np.asarray(value, dtype=np.float64)).ravel()
    except (TypeError, ValueError):
        return None
    if not len(values) or not np.isfinite(values).all():
        return None
    return float(values[0]) if count == 1 else np.resize(values, count)


# illum models of the MTL specification -> (lit, specular, mirror, transmissive)
_ILLUM = {
    0: (False, False, False, False),  # colour on, no lighting: Kd shown as is
    1: (True, False, False, False),  # diffuse only
    2: (True, True, False, False),  # Blinn-Phong
    3: (True, True, True, False),  # + ray-traced reflection (Ks)
    4: (True, True, True, True),  # glass: reflection + transparency (1 - d)
    5: (True, True, True, False),  # reflection with Fresnel (treated as mirror Ks)
    6: (True, True, True, True),  # reflection + refraction (Ni)
    7: (True, True, True, True),  # reflection + refraction with Fresnel
    8: (True, True, True, False),  # reflection, not ray traced (treated as 3)
    9: (True, True, True, True),  # glass, not ray traced (treated as 4)
    10: (True, True, False, False),  # shadow matte (treated as 2)
}


def _mtl_material(material, name):
    """Map an OBJ/MTL material onto rtmesh's model.

    Ka, Kd, Ks, Ke and Ns map to ambient, diffuse, specular, emission and shininess; the
    ``illum`` model chooses lighting, highlights, mirror reflection (weight Ks) and
    refraction (index Ni; weight Tf, times 1 - opacity for the "transparency" models 4 and 9).  Opacity comes from ``d`` (1 = opaque);
    ``Tr`` is only read when ``d`` is absent, as ``1 - Tr``, except that ``Tr 1`` is read as
    opaque: several exporters (MeshLab among them) write Tr as an opacity, and a model that
    disappears is the worse failure.  The colours trimesh quantised to 8 bits are read back
    at full precision from the file's statements when trimesh kept them.
    """
    kw = {k.lower(): v for k, v in (getattr(material, "kwargs", None) or {}).items()}

    def colour(key, fallback):
        value = _mtl_floats(kw, key, 3)
        return value if value is not None else fallback

    diffuse = colour("kd", np.asarray(material.diffuse, dtype=np.float64)[:3] / 255.0)
    ambient = colour("ka", diffuse)
    specular = colour("ks", np.asarray(material.specular, dtype=np.float64)[:3] / 255.0)
    emission = colour("ke", np.zeros(3))
    shininess = _mtl_floats(kw, "ns", 1)
    if shininess is None:
        shininess = float(material.glossiness) if material.glossiness else 32.0
    illum_value = _mtl_floats(kw, "illum", 1)
    illum = 2 if illum_value is None else int(illum_value)
    lit, has_specular, has_mirror, transmissive = _ILLUM.get(illum, _ILLUM[2])
    opacity = _mtl_floats(kw, "d", 1)
    if opacity is None:
        tr = _mtl_floats(kw, "tr", 1)
        opacity = 1.0 if tr is None or tr >= 1.0 else 1.0 - tr
    if getattr(material, "image", None) is not None:
        # until textures are sampled, the mean texel colour stands in for the texture
        diffuse = diffuse * _mean_texture_colour(material.image)
    transmission = np.zeros(3)
    if transmissive:
        tf = _mtl_floats(kw, "tf", 3)
        transmission = tf if tf is not None else np.ones(3)
        if illum in (4, 9):
            # "transparency" models: how much passes is the dissolve
            transmission = transmission * (1.0 - opacity)
    if not lit:
        emission, diffuse, ambient = emission + diffuse, np.zeros(3), np.zeros(3)
    return Material(
        name=material.name or name,
        diffuse=diffuse,
        ambient=ambient,
        specular=specular if has_specular else np.zeros(3),
        shininess=float(np.clip(shininess, 1.0, 10000.0)),
        mirror=specular if has_mirror else np.zeros(3),
        transmission=np.clip(transmission, 0.0, 1.0),
        ior=_mtl_floats(kw, "ni", 1) or 1.5,
        emission=emission,
    )


def _mean_texture_colour(image):
    """Mean linear colour of a PIL image (sRGB-decoded), (3,) float."""
    try:
        pixels = np.asarray(image.convert("RGB"), dtype=np.float64) / 255.0
    except Exception:  # a texture trimesh could not decode leaves the factor colour alone
        return np.ones(3)
    linear = np.where(pixels <= 0.04045, pixels / 12.92, ((pixels + 0.055) / 1.055) ** 2.4)
    return linear.reshape(-1, 3).mean(axis=0)


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
        has them and smooths by angle (30 degrees) where it does not.

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

    parts, materials, material_ids = [], [], {}
    for node_name, node_transform, mesh in nodes:
        if not isinstance(mesh, trimesh.Trimesh):
            log.warning("%s: node '%s' is a %s, not a triangle mesh; skipped",
                        name, node_name, type(mesh).__name__)
            continue
        if len(mesh.faces) == 0:
            continue
        if smooth is None and not _file_has_vertex_normals(mesh):
            mesh = mesh.smooth_shaded  # split at creases, smooth elsewhere
        matrix = transform @ node_transform
        vertices = trimesh.transform_points(mesh.vertices, matrix)
        faces = np.asarray(mesh.faces)
        if np.linalg.det(matrix[:3, :3]) < 0:
            faces = faces[:, ::-1]  # a mirroring transform flips the winding
        normals = None
        if smooth is not False:
            # normals transform with the inverse transpose of the linear part
            normal_matrix = np.linalg.inv(matrix[:3, :3]).T
            with np.errstate(invalid="ignore"):
                normals = np.asarray(mesh.vertex_normals) @ normal_matrix.T
        if material is None:
            key = id(getattr(mesh.visual, "material", mesh.visual))
            if key not in material_ids:
                material_ids[key] = len(materials)
                materials.append(material_from_trimesh(mesh.visual, node_name))
            mat = material_ids[key]
        else:
            mat = material
        parts.append(MeshPart(node_name, vertices, faces, mat, normals))
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

    A glTF file's first perspective camera and its KHR_lights_punctual lights are used when
    it has them (see :mod:`rtmesh.gltf_scene`); otherwise an automatic camera frames the
    mesh and the default light rig lights it.
    """
    obj = load_trimesh(path)
    cameras, lights = file_cameras_and_lights(path)
    if cameras:
        scene_options.setdefault("camera", cameras[0][1])
    if lights:
        scene_options.setdefault("lights", lights)
    return scene_from_trimesh(obj, name=os.fspath(path), **scene_options)
