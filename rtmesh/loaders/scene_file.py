"""TOML scene files: parsing, validation and conversion to a :class:`Scene`.

Every key is checked against a schema: unknown keys and wrong types are errors that name
the file and the key (``scene.toml: objects[2].smoth: unknown key``).  The keys are
documented in docs/SCENE_FORMAT.md.
"""

import dataclasses
import math
import os

import numpy as np
import trimesh

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from rtmesh.core.errors import RtmeshError, SceneError
from rtmesh.geometry.motion import Motion
from rtmesh.loaders.gltf_nodes import file_cameras_and_lights
from rtmesh.loaders.importers import mesh_file_parts
from rtmesh.loaders.light_registry import LIGHT_TYPES
from rtmesh.materials.table import Material
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene.background import (BACKGROUND_TYPES, GradientBackground, SolidBackground, TransparentBackground,
                                     read_environment)
from rtmesh.scene.camera import Camera
from rtmesh.materials.models import MODEL_NAMES
from rtmesh.rendering.settings import CAUSTICS, INTEGRATORS
from rtmesh.scene.model import MeshPart, Scene

# ---------------------------------------------------------------- value types


# Every number of a scene file is finite and 0 or between these in magnitude: squares,
# products and reciprocals of coordinates, distances, intensities, roughnesses and indices
# of refraction then stay far inside float64, and a coordinate inside the float32 Embree
# holds (docs/LIMITS.md).
MIN_NUMBER, MAX_NUMBER = 1e-18, 1e18
_RANGE = f"0, or magnitude {MIN_NUMBER:g} to {MAX_NUMBER:g}"


def _is_number(v):
    return (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            and (v == 0 or MIN_NUMBER <= abs(v) <= MAX_NUMBER))


def _float(v):
    if not _is_number(v):
        raise TypeError(f"expected a finite number ({_RANGE})")
    return float(v)


def _positive(v):
    v = _float(v)
    if v <= 0:
        raise TypeError("expected a number > 0")
    return v


def _fov(v):
    v = _float(v)
    if not 0.0 < v < 180.0:
        raise TypeError("expected degrees more than 0 and less than 180")
    return v


def _non_negative(v):
    v = _float(v)
    if v < 0:
        raise TypeError("expected a number >= 0")
    return v


def _int(v):
    if not isinstance(v, int) or isinstance(v, bool):
        raise TypeError("expected an integer")
    return v


def _bool(v):
    if not isinstance(v, bool):
        raise TypeError("expected true or false")
    return v


def _str(v):
    if not isinstance(v, str):
        raise TypeError("expected a string")
    return v


def _vector(n):
    def convert(v):
        if not (isinstance(v, list) and len(v) == n and all(_is_number(x) for x in v)):
            raise TypeError(f"expected a list of {n} numbers (finite; {_RANGE})")
        return np.array(v, dtype=np.float64)
    return convert


_vec2, _vec3 = _vector(2), _vector(3)


def _colour(v):
    """A number (grey) or [r, g, b], all >= 0."""
    c = np.full(3, _float(v)) if _is_number(v) else _vec3(v) if isinstance(v, list) else None
    if c is None:
        raise TypeError(f"expected a number or a list of 3 numbers (finite; {_RANGE})")
    if (c < 0).any():
        raise TypeError("colour components must be >= 0")
    return c


def _reflectance(v):
    """A colour whose components are at most 1: a weight of the path through a bounce (more
    would gain energy at every bounce, up to an infinite image)."""
    c = _colour(v)
    if (c > 1).any():
        raise TypeError("colour components must be between 0 and 1 (a reflectance)")
    return c


def _scale(v):
    s = np.full(3, _float(v)) if _is_number(v) else _vec3(v)
    if (s == 0).any():
        raise TypeError("scale must not be zero")
    return s


def _str_list(v):
    if not (isinstance(v, list) and all(isinstance(x, str) for x in v)):
        raise TypeError("expected a list of strings")
    return tuple(v)


def _shutter(v):
    """[open, close] with open <= close."""
    times = _vec2(v)
    if times[1] < times[0]:
        raise TypeError("expected [open, close] with open <= close")
    return times


def _table(v):
    if not isinstance(v, dict):
        raise TypeError("expected a table")
    return v


def _one_of(*choices):
    def convert(v):
        if v not in choices:
            raise TypeError("expected one of " + ", ".join(repr(c) for c in choices))
        return v
    return convert


# ---------------------------------------------------------------- schema

RENDER_KEYS = {
    "width": _int, "height": _int, "spp": _int, "sampler": _str, "max_depth": _int,
    "seed": _int, "threads": _int, "chunk_samples": _int, "cutoff": _non_negative,
    "fresnel": _str, "ao_samples": _int, "ao_distance": _positive, "passes": _str_list,
    "light_samples": _int,
    "exposure": _float, "tonemap": _str,
    "target_error": _positive, "time_limit": _positive, "max_spp": _int, "denoise": _bool,
    "integrator": _one_of(*INTEGRATORS), "clamp": _non_negative, "caustics": _one_of(*CAUSTICS), "photons": _int,
}
CAMERA_KEYS = {
    "position": _vec3, "look_at": _vec3, "up": _vec3, "fov": _fov,
    "aperture": _non_negative, "focus_distance": _positive, "from_file": _str,
    "shutter": _shutter, "projection": _one_of("perspective", "orthographic"), "ortho_height": _positive,
}
ENVIRONMENT_KEYS = {"ambient": _colour, "background": _colour}
MATERIAL_KEYS = {
    "diffuse": _colour, "specular": _colour, "shininess": _non_negative, "ambient": _colour,
    "mirror": _reflectance, "transmission": _reflectance, "ior": _positive, "absorption": _colour,
    "emission": _colour, "roughness": _non_negative, "model": _one_of(*MODEL_NAMES),
}
OBJECT_KEYS = {
    "name": _str, "mesh": _str, "category": _str,
    "primitive": _one_of("icosphere", "box", "plane"),
    "subdivisions": _int, "radius": _positive, "extents": _vec3, "size": _vec2,
    "material": _str, "smooth": _bool,
    "translate": _vec3, "rotate": _vec3, "scale": _scale, "import_lights": _bool,
    "motion": _table,
}
MOTION_KEYS = {"translate": _vec3, "rotate_axis": _vec3, "rotate_degrees": _float}
# the keys of every registered light type, read by their kind (see rtmesh.lights.light_types)
_KEY_READERS = {"vec3": _vec3, "colour": _colour, "positive": _positive, "non_negative": _non_negative,
                "bool": _bool, "path": _str}


def light_keys():
    """The keys a ``[[lights]]`` table may have, with their readers, from the registry."""
    return {"type": _one_of(*LIGHT_TYPES),
            **{key: _KEY_READERS[kind] for t in LIGHT_TYPES.values() for key, kind in t.keys.items()}}

BACKGROUND_KEYS = {
    "type": _one_of(*BACKGROUND_TYPES), "colour": _colour, "top": _colour, "bottom": _colour,
    "file": _str, "rotation": _float, "intensity": _non_negative, "lighting": _bool,
}
BACKGROUND_ALLOWED = {
    "solid": ("colour", "lighting"), "gradient": ("top", "bottom", "lighting"),
    "environment": ("file", "rotation", "intensity", "lighting"), "transparent": (),
}
BACKGROUND_REQUIRED = {"solid": ("colour",), "gradient": ("top", "bottom"), "environment": ("file",),
                       "transparent": ()}
TOP_LEVEL = ("render", "camera", "environment", "background", "materials", "objects", "lights")


class _Reader:
    """Validates tables of a parsed scene file, naming the file and key in errors."""

    def __init__(self, source):
        self.source = source

    def error(self, where, message):
        return SceneError(f"{self.source}: {where}: {message}")

    def table(self, value, where):
        if not isinstance(value, dict):
            raise self.error(where, "expected a table")
        return value

    def array_of_tables(self, value, where):
        if not (isinstance(value, list) and all(isinstance(v, dict) for v in value)):
            raise self.error(where, f"expected an array of tables ([[{where}]])")
        return value

    def fields(self, table, schema, where):
        """Convert every key of ``table`` with ``schema``; unknown keys are errors."""
        out = {}
        for key, value in table.items():
            path = f"{where}.{key}" if where else key
            if key not in schema:
                raise self.error(path, "unknown key (expected one of " + ", ".join(schema) + ")")
            try:
                out[key] = schema[key](value)
            except TypeError as exc:
                raise self.error(path, str(exc)) from None
        return out


def read_scene_file(path, overrides=None, check_settings=None):
    """Load a TOML scene file.

    Parameters
    ----------
    path : str or os.PathLike
    overrides : dict, optional
        Render settings that take precedence over the file's ``[render]`` table
        (e.g. from the command line).
    check_settings : callable, optional
        Called with the validated settings before any mesh is loaded (the command line's
        memory check, :func:`rtmesh.rendering.memory.check`); it raises to refuse them.

    Returns
    -------
    scene : Scene
    settings : RenderSettings

    Raises
    ------
    SceneError
        Unreadable file, TOML syntax error, unknown key, wrong type or bad value.
    MeshError
        A mesh the scene names cannot be read.
    """
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            doc = tomllib.load(f)
    except FileNotFoundError:
        raise SceneError(f"{path}: no such scene file") from None
    except OSError as exc:
        raise SceneError(f"{path}: cannot read: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: TOML syntax error: {exc}") from None
    except UnicodeDecodeError:
        raise SceneError(f"{path}: not a UTF-8 text file") from None
    return scene_from_dict(doc, source=path, base_dir=os.path.dirname(os.path.abspath(path)),
                           overrides=overrides, check_settings=check_settings)


def scene_from_dict(doc, source="scene", base_dir=".", overrides=None, check_settings=None):
    """Build a scene and its render settings from a parsed scene description.

    Parameters
    ----------
    doc : dict
        The parsed TOML document (see docs/SCENE_FORMAT.md).
    source : str
        Name used in error messages.
    base_dir : str
        Folder that relative mesh paths are resolved against.
    overrides : dict, optional
        Render settings overriding ``doc["render"]``.
    check_settings : callable, optional
        See :func:`read_scene_file`.

    Returns
    -------
    scene : Scene
    settings : RenderSettings
    """
    r = _Reader(source)
    for key in doc:
        if key not in TOP_LEVEL:
            raise r.error(key, "unknown key (expected one of " + ", ".join(TOP_LEVEL) + ")")

    render = r.fields(r.table(doc.get("render", {}), "render"), RENDER_KEYS, "render")
    render.update({k: v for k, v in (overrides or {}).items() if v is not None})
    try:
        settings = RenderSettings(**render).validate()
    except ValueError as exc:
        raise r.error("render", str(exc)) from None
    if check_settings is not None:
        check_settings(settings)

    environment = r.fields(r.table(doc.get("environment", {}), "environment"), ENVIRONMENT_KEYS,
                           "environment")

    materials, material_index = [Material("default")], {"default": 0}
    for name, table in r.table(doc.get("materials", {}), "materials").items():
        values = r.fields(r.table(table, f"materials.{name}"), MATERIAL_KEYS, f"materials.{name}")
        material_index[name] = len(materials)
        materials.append(Material(name=name, **values))

    objects = r.array_of_tables(doc.get("objects", []), "objects")
    if not objects:
        raise r.error("objects", "the scene has no objects (add at least one [[objects]] table)")
    parts, file_cameras, file_lights = [], [], []
    for i, table in enumerate(objects):
        where = f"objects[{i}]"
        values = r.fields(table, OBJECT_KEYS, where)
        parts.extend(_object_parts(r, values, where, base_dir, materials, material_index))
        if "mesh" in values:
            try:
                cameras, lights = file_cameras_and_lights(_mesh_path(values, base_dir), _transform(values),
                                                          physical=settings.integrator == "path")
            except RtmeshError as exc:
                raise r.error(f"{where}.mesh", str(exc)) from None
            file_cameras.extend(cameras)
            if values.get("import_lights", True):
                file_lights.extend(lights)
        elif "import_lights" in values:
            raise r.error(f"{where}.import_lights", "does not apply to a primitive")

    lights = None
    if "lights" in doc:
        keys = light_keys()
        lights = [_light(r, r.fields(t, keys, f"lights[{i}]"), f"lights[{i}]", base_dir)
                  for i, t in enumerate(r.array_of_tables(doc["lights"], "lights"))]
    if file_lights:
        # a glTF file's own lights join the scene file's (and replace the default rig)
        lights = (lights or []) + file_lights

    camera = None
    if "camera" in doc:
        camera = _camera(r, r.fields(r.table(doc["camera"], "camera"), CAMERA_KEYS, "camera"),
                         file_cameras)

    scene = Scene.from_parts(
        parts, materials, lights=lights, camera=camera,
        # a little ambient light for the default rig under whitted (path has no ambient term)
        ambient=environment.get("ambient", np.zeros(3) if lights is not None or settings.integrator == "path"
                                else np.full(3, 0.05)),
        background=_background(r, doc, environment, base_dir),
        source=source, aspect=settings.width / settings.height, physical=settings.integrator == "path",
    )
    return scene, settings


def _background(r, doc, environment, base_dir):
    """The scene's background from ``[background]`` (or ``[environment].background``)."""
    if "background" not in doc:
        return environment.get("background", np.zeros(3))
    if "background" in environment:
        raise r.error("background", "give the background either as [background] or as "
                      "environment.background, not both")
    values = r.fields(r.table(doc["background"], "background"), BACKGROUND_KEYS, "background")
    kind = values.get("type", "solid")
    for key in values:
        if key != "type" and key not in BACKGROUND_ALLOWED[kind]:
            raise r.error(f"background.{key}", f"does not apply to a {kind} background")
    for key in BACKGROUND_REQUIRED[kind]:
        if key not in values:
            raise r.error(f"background.{key}", f"missing (a {kind} background needs "
                          + " and ".join(BACKGROUND_REQUIRED[kind]) + ")")
    if kind == "solid":
        background = SolidBackground(values["colour"])
    elif kind == "gradient":
        background = GradientBackground(values["top"], values["bottom"])
    elif kind == "transparent":
        return TransparentBackground()
    else:
        path = values["file"]
        if not os.path.isabs(path):
            path = os.path.join(base_dir, path)
        try:
            background = read_environment(path, values.get("rotation", 0.0), values.get("intensity", 1.0))
        except RtmeshError as exc:
            raise r.error("background.file", str(exc)) from None
    # unset: decided by the integrator (on for scenes with physically based materials)
    background.lighting = values.get("lighting")
    return background


def _object_parts(r, values, where, base_dir, materials, material_index):
    """The mesh parts one ``[[objects]]`` table makes."""
    has_mesh, has_primitive = "mesh" in values, "primitive" in values
    if has_mesh == has_primitive:
        raise r.error(where, "needs exactly one of 'mesh' or 'primitive'")
    material = None
    if "material" in values:
        if values["material"] not in material_index:
            raise r.error(f"{where}.material", f"unknown material {values['material']!r} "
                          "(define it in a [materials.NAME] table)")
        material = material_index[values["material"]]
    primitive_keys = {"icosphere": ("subdivisions", "radius"), "box": ("extents",), "plane": ("size",)}
    for key in ("subdivisions", "radius", "extents", "size"):
        if key in values and (not has_primitive or key not in primitive_keys[values["primitive"]]):
            raise r.error(f"{where}.{key}", "does not apply to this object"
                          + (f" (a {values['primitive']})" if has_primitive else " (a mesh file)"))
    transform = _transform(values)
    motion = _motion(r, values["motion"], f"{where}.motion") if "motion" in values else None
    name = values.get("name")
    smooth = values.get("smooth")
    if has_mesh:
        mesh_path = _mesh_path(values, base_dir)
        try:
            # trimesh's formats and USD (its meshes and materials; not its lights or cameras)
            parts, imported = mesh_file_parts(mesh_path, name or os.path.basename(mesh_path), transform,
                                              material, smooth)
        except RtmeshError as exc:
            raise r.error(f"{where}.mesh", str(exc)) from None
        # imported materials are appended after the scene file's own; one whose name a
        # [materials.NAME] table defines is replaced by that table
        if material is None:
            remap = [material_index.get(m.name, len(materials) + i) if m.name != "default"
                     else len(materials) + i for i, m in enumerate(imported)]
            for part in parts:
                part.material = remap[part.material]
            materials.extend(imported)
        for part in parts:
            part.category = values.get("category")
            if name:
                part.name = name if len(parts) == 1 else f"{name}/{part.name}"
        if motion is not None:
            # the parts of one object turn about the centre of the whole object
            points = np.concatenate([p.vertices for p in parts]) if parts else np.zeros((1, 3))
            motion.centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
            for part in parts:
                part.motion = motion
        return parts

    kind = values["primitive"]
    if kind == "icosphere":
        subdivisions = values.get("subdivisions", 3)
        if not 0 <= subdivisions <= 8:
            raise r.error(f"{where}.subdivisions", "expected an integer from 0 to 8")
        radius = values.get("radius", 1.0)
        if radius >= 1e-12:
            mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
        else:
            # trimesh moves the unit sphere's vertices by (radius - |v|) onto the radius,
            # which cancels to nothing this small: scale the unit sphere instead
            mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
            mesh = trimesh.Trimesh(mesh.vertices * radius, mesh.faces, process=False)
        default_smooth = True
    elif kind == "box":
        mesh = trimesh.creation.box(extents=values.get("extents", np.ones(3)))
        default_smooth = False
    else:
        sx, sy = values.get("size", np.array([1.0, 1.0])) * 0.5
        if sx <= 0 or sy <= 0:
            raise r.error(f"{where}.size", "expected two numbers > 0")
        mesh = trimesh.Trimesh(
            vertices=[[-sx, -sy, 0], [sx, -sy, 0], [sx, sy, 0], [-sx, sy, 0]],
            faces=[[0, 1, 2], [0, 2, 3]], process=False)
        default_smooth = False
    smooth = default_smooth if smooth is None else smooth
    vertices = trimesh.transform_points(mesh.vertices, transform)
    faces = np.asarray(mesh.faces)
    if np.linalg.det(transform[:3, :3]) < 0:
        faces = faces[:, ::-1]
    normals = None
    if smooth:
        normals = np.asarray(mesh.vertex_normals) @ np.linalg.inv(transform[:3, :3])
    return [MeshPart(name or f"{kind}{where[7:]}", vertices, faces,
                     0 if material is None else material, normals, motion,
                     category=values.get("category"), to_world=transform)]


def _mesh_path(values, base_dir):
    """An object's mesh file, resolved against the scene file's folder."""
    path = values["mesh"]
    return path if os.path.isabs(path) else os.path.join(base_dir, path)


def _transform(values):
    """4x4 matrix: scale, then rotate (X, then Y, then Z, degrees), then translate."""
    matrix = np.diag(np.append(values.get("scale", np.ones(3)), 1.0))
    rx, ry, rz = np.radians(values.get("rotate", np.zeros(3)))
    rotation = (trimesh.transformations.rotation_matrix(rz, [0, 0, 1])
                @ trimesh.transformations.rotation_matrix(ry, [0, 1, 0])
                @ trimesh.transformations.rotation_matrix(rx, [1, 0, 0]))
    matrix = rotation @ matrix
    matrix[:3, 3] = values.get("translate", np.zeros(3))
    return matrix


def _motion(r, table, where):
    """A :class:`Motion` from an object's ``motion`` table."""
    values = r.fields(r.table(table, where), MOTION_KEYS, where)
    degrees = values.get("rotate_degrees", 0.0)
    if degrees != 0.0 and "rotate_axis" not in values:
        raise r.error(f"{where}.rotate_axis", "missing (needed by rotate_degrees)")
    try:
        return Motion(values.get("translate", np.zeros(3)),
                      values.get("rotate_axis", np.array([0.0, 1.0, 0.0])), degrees)
    except ValueError as exc:
        raise r.error(where, str(exc)) from None


def _light(r, values, where, base_dir):
    """A light from its read ``[[lights]]`` table, through its type's registry entry (file
    names are taken relative to ``base_dir``, the scene file's folder)."""
    kind = values.get("type")
    if kind is None:
        names = list(LIGHT_TYPES)
        raise r.error(f"{where}.type", f"missing ({', '.join(names[:-1])} or {names[-1]})")
    light_type = LIGHT_TYPES[kind]
    for key in values:
        if key != "type" and key not in light_type.keys:
            raise r.error(f"{where}.{key}", f"does not apply to a {kind} light")
    for key in light_type.required:
        if key not in values:
            raise r.error(f"{where}.{key}", f"missing (a {kind} light needs {', '.join(light_type.required)})")
    for key, key_kind in light_type.keys.items():
        if key_kind == "path" and key in values:
            path = os.path.join(base_dir, values[key])
            if not os.path.isfile(path):
                raise r.error(f"{where}.{key}", f"no such file: {path}")
            values = {**values, key: path}
    try:
        return light_type.build(values)
    except ValueError as exc:
        raise r.error(where, str(exc)) from None


def _camera(r, values, file_cameras=()):
    if "from_file" in values:
        return _file_camera(r, values, file_cameras)
    for key in ("position", "look_at"):
        if key not in values:
            raise r.error(f"camera.{key}", "missing")
    try:
        camera = Camera(values["position"], values["look_at"], values.get("up", np.array([0.0, 1.0, 0.0])),
                        fov=values.get("fov", 45.0), aperture=values.get("aperture", 0.0),
                        focus_distance=values.get("focus_distance"),
                        shutter=tuple(values.get("shutter", (0.0, 0.0))),
                        projection=values.get("projection", "perspective"),
                        ortho_height=values.get("ortho_height"))
        camera.frame()
    except ValueError as exc:
        raise r.error("camera", str(exc)) from None
    return camera


def _file_camera(r, values, file_cameras):
    """The camera named ``from_file`` among the cameras of the scene's glTF objects."""
    for key in values:
        if key not in ("from_file", "aperture", "focus_distance"):
            raise r.error(f"camera.{key}", "does not apply with from_file (the file sets it)")
    name = values["from_file"]
    for names, camera in file_cameras:
        if name in names:
            return dataclasses.replace(camera, aperture=values.get("aperture", 0.0),
                                       focus_distance=values.get("focus_distance"))
    available = ", ".join(repr(n[0]) for n, _ in file_cameras if n) or "none"
    raise r.error("camera.from_file", f"no camera named {name!r} in the scene's glTF files "
                  f"(available: {available})")


def settings_fields():
    """Names of the render settings a scene file or the command line may set."""
    return [f.name for f in dataclasses.fields(RenderSettings)]
