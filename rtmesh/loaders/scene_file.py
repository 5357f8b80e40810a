"""TOML scene files: parsing, validation and conversion to a :class:`Scene`.

Every key is checked against a schema: unknown keys and wrong types are errors that name
the file and the key (``scene.toml: objects[2].smoth: unknown key``).  The keys are
documented in docs/SCENE_FORMAT.md.
"""

import collections
import dataclasses
import logging
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
from rtmesh.loaders.placements import copied
from rtmesh.materials.table import Material
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene.background import (BACKGROUND_TYPES, GradientBackground, SolidBackground, TransparentBackground,
                                     read_environment)
from rtmesh.scene.camera import Camera
from rtmesh.materials.models import MODEL_NAMES
from rtmesh.rendering import memory
from rtmesh.rendering.settings import CAUSTICS, INTEGRATORS
from rtmesh.scene import instances
from rtmesh.scene.instances import worth_instancing
from rtmesh.scene.model import MeshPart, Placement, Scene

log = logging.getLogger(__name__)

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
    "exposure": _float, "tonemap": _str, "dither": _bool,
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
    "motion": _table, "instances": _str,
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
    tables = [r.fields(table, OBJECT_KEYS, f"objects[{i}]") for i, table in enumerate(objects)]
    placing = _Placing(r, tables, base_dir)
    parts, file_cameras, file_lights = [], [], []
    for i, values in enumerate(tables):
        where = f"objects[{i}]"
        parts.extend(_object_parts(r, values, where, base_dir, materials, material_index, placing, i))
        if "mesh" in values:
            try:
                cameras, lights = file_cameras_and_lights(_mesh_path(values, base_dir), _transform(values),
                                                          physical=settings.integrator == "path")
            except RtmeshError as exc:
                raise r.error(f"{where}.mesh", str(exc)) from None
            file_cameras.extend(cameras)
            if values.get("import_lights", True):
                if lights and placing.rows[i] is not None:
                    log.warning("%s: %s: the file's %d lights are placed once, by the object's transform, not "
                                "by each of its instances (import_lights = false drops them)", source, where,
                                len(lights))
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
        placements=placing.placements(),
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


def _object_parts(r, values, where, base_dir, materials, material_index, placing, index):
    """The mesh parts one ``[[objects]]`` table makes (its meshes placed by instances join
    ``placing``)."""
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
        parts = placing.file_parts(values, where, index, material, materials, material_index)
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
    name = name or f"{kind}{where[7:]}"
    material = 0 if material is None else material
    rows = placing.rows[index]
    if rows is not None:
        # the primitive in its own coordinates, placed by each row, then by the object's transform
        model = MeshPart(name, np.asarray(mesh.vertices), np.asarray(mesh.faces), material,
                         np.asarray(mesh.vertex_normals) if smooth else None, category=values.get("category"))
        parts = placing.placed(model, transform @ rows, name, values.get("category"), index, moving=motion is not None)
        for part in parts:
            part.motion = motion
        return parts
    vertices = trimesh.transform_points(mesh.vertices, transform)
    faces = np.asarray(mesh.faces)
    if np.linalg.det(transform[:3, :3]) < 0:
        faces = faces[:, ::-1]
    normals = None
    if smooth:
        normals = np.asarray(mesh.vertex_normals) @ np.linalg.inv(transform[:3, :3])
    return [MeshPart(name, vertices, faces, material, normals, motion,
                     category=values.get("category"), to_world=transform)]


class _Placing:
    """The meshes a scene file places more than once: a file that several objects import
    (with the same ``material`` and ``smooth``, not moving) or an object's ``instances``.

    Such a file is read once, in its own coordinates; each of its meshes that is worth
    instancing (:func:`rtmesh.scene.instances.worth_instancing`, counted over every
    placement in the scene) becomes one :class:`~rtmesh.scene.model.Placement` with a
    transform per placement (each row of ``instances``, then the object's transform), the
    others are copied (one part an object, :func:`rtmesh.loaders.placements.copied`).  A
    file imported once, or several times without a mesh worth instancing, and without
    ``instances``, is read by each object as before: by the object's transform (the same
    arithmetic, the same image).

    Attributes
    ----------
    rows : list of (k, 4, 4) float64 or None
        Each object's ``instances`` (None without).
    """

    def __init__(self, r, tables, base_dir):
        self.r, self.base_dir = r, base_dir
        self.rows = [_instance_rows(r, values, f"objects[{i}]", base_dir) if "instances" in values else None
                     for i, values in enumerate(tables)]
        # placements of each shared file in the whole scene
        self.uses = collections.Counter()
        for values, rows in zip(tables, self.rows):
            key = self._key(values)
            if key is not None:
                self.uses[key] += 1 if rows is None else len(rows)
        self.files = {}  # key -> (parts, placements) read once, in the file's coordinates
        # placed meshes: (key, piece) -> [part, transforms, names, categories]
        self.placed_meshes = {}

    def _key(self, values):
        """What makes two objects' meshes the same: the file, its material and smoothing;
        None for a primitive or a moving object (copied)."""
        if "mesh" not in values or "motion" in values:
            return None
        return os.path.realpath(_mesh_path(values, self.base_dir)), values.get("material"), values.get("smooth")

    def _read(self, values, where, material, transform=None):
        """``[parts, placements, imported materials]`` of an object's mesh file
        (``transform`` applied; None: in the file's coordinates); placements (the file's own
        meshes placed many times) unless the object moves."""
        mesh_path = _mesh_path(values, self.base_dir)
        inner = None if "motion" in values else []
        try:
            # trimesh's formats and USD (its meshes and materials; not its lights or cameras)
            parts, imported = mesh_file_parts(mesh_path, values.get("name") or os.path.basename(mesh_path),
                                              transform, material, values.get("smooth"), inner)
        except RtmeshError as exc:
            raise self.r.error(f"{where}.mesh", str(exc)) from None
        return [parts, inner or [], imported]

    @staticmethod
    def _adopt(read, materials, material_index):
        """Append the imported materials of a ``_read`` to ``materials`` (once) and point its
        parts at them: after the scene file's own, and one whose name a [materials.NAME]
        table defines replaced by that table.  Returns ``(parts, placements)``."""
        parts, inner, imported = read
        if imported:
            remap = [material_index.get(m.name, len(materials) + i) if m.name != "default"
                     else len(materials) + i for i, m in enumerate(imported)]
            for part in parts + [p.part for p in inner]:
                part.material = remap[part.material]
            materials.extend(imported)
            read[2] = []
        return parts, inner

    def _model(self, key, values, where, material):
        """An object's mesh file in its own coordinates, read once per ``key`` (every time
        for a None key: a moving object)."""
        if key is None:
            return self._read(values, where, material)
        if key not in self.files:
            self.files[key] = self._read(values, where, material)
        return self.files[key]

    def file_parts(self, values, where, index, material, materials, material_index):
        """The parts of a mesh object (its meshes placed by instances kept for
        :meth:`placements`)."""
        key, rows = self._key(values), self.rows[index]
        name, category = values.get("name"), values.get("category")
        shared = rows is not None
        if rows is None and key is not None and self.uses[key] > 1:
            # shared when the file places a mesh many times itself or one of its meshes is
            # worth instancing; else each object reads it as before (the same arithmetic)
            parts, inner, _ = self._model(key, values, where, material)
            shared = bool(inner) or any(worth_instancing(len(part.faces), self.uses[key]) for part in parts)
        if shared:
            parts, inner = self._adopt(self._model(key, values, where, material), materials, material_index)
        else:
            parts, inner = self._adopt(self._read(values, where, material, _transform(values)), materials,
                                       material_index)
        single = len(parts) + sum(len(placement.names) for placement in inner) == 1  # one mesh, placed once

        def label(own):
            return (name if single else f"{name}/{own}") if name else own

        if not shared:
            for part in parts:
                part.category = category
                part.name = label(part.name)
            for placement in inner:
                placement.names = [label(n) for n in placement.names]
                placement.part.category = category
                self._add(("object", index, id(placement)), placement.part, placement.transforms, placement.names,
                          None)
            return parts
        transforms = _transform(values)[None] if rows is None else _transform(values) @ rows
        out = []
        for piece, part in enumerate(parts):
            own = label(part.name)
            out.extend(self.placed(part, transforms, own, category, index, None if key is None else (key, piece),
                                   moving="motion" in values))
        for piece, placement in enumerate(inner):
            # placed twice: the file's placement, then the object's (one level for Embree)
            combined = (transforms[:, None] @ placement.transforms[None]).reshape(-1, 4, 4)
            names = [label(n) if rows is None else f"{label(n)}[{j}]" for j in range(len(transforms))
                     for n in placement.names]
            self._add((key, "inner", piece), placement.part, combined, names,
                      [category or label(n) for _ in range(len(transforms)) for n in placement.names])
        return out

    def placed(self, part, transforms, name, category, index, key=None, moving=False):
        """``part`` (model coordinates) placed by ``transforms`` for object ``index``:
        held for an instance :class:`Placement` when worth it (``key`` names the mesh it
        shares with other objects; None: this object's alone), else copied into one part
        (always for a ``moving`` object, which the caller sets moving).

        Returns
        -------
        list of MeshPart
            The copies (one part), or empty.
        """
        k = len(transforms)
        count = self.uses[key[0]] if key is not None else k
        names = [f"{name}[{j}]" for j in range(k)] if self.rows[index] is not None else [name] * k
        if not moving and worth_instancing(len(part.faces), count):
            self._add(key if key is not None else ("object", index), part, transforms, names, [category or name] * k)
            return []
        memory.check_load(self.r.source, f"objects[{index}]: {k} copies of {len(part.faces)} triangles",
                          memory.load_estimate(k * len(part.vertices), k * len(part.faces), k))
        copies = copied(part, transforms, f"{name} ({k} copies)" if k > 1 else name)
        copies.category = category
        if k == 1:  # the object's pose (annotations): its file's node, then its transform
            copies.to_world = transforms[0] @ (np.eye(4) if part.to_world is None else part.to_world)
        return [copies]

    def _add(self, key, part, transforms, names, categories):
        held = self.placed_meshes.setdefault(key, [part, [], [], []])
        held[1].append(np.asarray(transforms, dtype=np.float64))
        held[2].extend(names)
        held[3].extend(categories if categories is not None else [part.category or n for n in names])

    def placements(self):
        """Every mesh placed by instances, one :class:`Placement` each."""
        return [Placement(part, np.concatenate(transforms), names, categories)
                for part, transforms, names, categories in self.placed_meshes.values()]


def _instance_rows(r, values, where, base_dir):
    """An object's ``instances``: the (k, 4, 4) float64 transforms of its ``.npy`` file.

    Raises
    ------
    SceneError
        ``scene.toml: objects[1].instances: trees.npy: ...``: the file is missing or not a
        ``.npy`` array of numbers of shape (k, 4, 4), or a transform is not finite, not
        affine, singular or beyond the scene file's range of numbers.
    """
    path = values["instances"]
    path = path if os.path.isabs(path) else os.path.join(base_dir, path)
    key = f"{where}.instances"
    try:
        with open(path, "rb") as f:
            try:
                version = np.lib.format.read_magic(f)
                read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                               else np.lib.format.read_array_header_2_0)
                shape, _, dtype = read_header(f)
            except ValueError:
                raise r.error(key, f"{path}: not a NumPy .npy file") from None
            if dtype.kind not in "fiu" or dtype.fields is not None:
                raise r.error(key, f"{path}: holds {dtype} values, not numbers")
            if len(shape) != 3 or shape[1:] != (4, 4) or shape[0] < 1:
                raise r.error(key, f"{path}: an array of shape {shape}, expected (k, 4, 4) with k >= 1 "
                                   "(a model-to-world transform a row)")
            # a placement's records are counted before the file is read (its mesh with it later)
            memory.check_load(path, f"{shape[0]} instance transforms", memory.load_estimate(0, 0, shape[0]))
            f.seek(0)
            try:
                rows = np.lib.format.read_array(f, allow_pickle=False).astype(np.float64)
            except ValueError as exc:
                raise r.error(key, f"{path}: truncated or corrupt ({exc})") from None
    except OSError as exc:
        raise r.error(key, f"cannot read {path}: {exc.strerror or exc}") from None
    problem = instances.check_transforms(rows, range(len(rows)), path)
    if problem is None and (np.abs(rows) > MAX_NUMBER).any():
        row = int(np.flatnonzero((np.abs(rows) > MAX_NUMBER).any(axis=(1, 2)))[0])
        problem = f"{path}: instance {row} has a number beyond {MAX_NUMBER:g} in magnitude"
    if problem is not None:
        raise r.error(key, problem)
    return rows


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
