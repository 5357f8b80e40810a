"""TOML scene files: parsing, validation and conversion to a :class:`Scene`.

Every key is checked against a schema (:mod:`rtmesh.loaders.scene_keys`): unknown keys and
wrong types are errors that name the file and the key (``scene.toml: objects[2].smoth:
unknown key``).  The keys are documented in docs/SCENE_FORMAT.md.  This module reads the
whole file: its render settings, materials, lights, camera and background; each
``[[objects]]`` table's meshes come from :mod:`rtmesh.loaders.scene_objects`.
"""

import dataclasses
import logging
import os

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from rtmesh.core.errors import MeshError, RtmeshError, SceneError
from rtmesh.loaders.gltf_nodes import file_cameras_and_lights
from rtmesh.loaders.light_registry import LIGHT_TYPES
from rtmesh.loaders.mesh_files import check_file
from rtmesh.loaders.scene_keys import (BACKGROUND_ALLOWED, BACKGROUND_KEYS, BACKGROUND_REQUIRED, CAMERA_KEYS,
                                       ENVIRONMENT_KEYS, MATERIAL_KEYS, OBJECT_KEYS, RENDER_KEYS, TOP_LEVEL,
                                       TableReader, light_keys)
from rtmesh.loaders.scene_objects import MeshPlacing, object_mesh_path, object_parts, object_transform
from rtmesh.materials.table import Material
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene.background import GradientBackground, SolidBackground, TransparentBackground, read_environment
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene

log = logging.getLogger(__name__)

# The largest scene file rtmesh reads (docs/LIMITS.md): scene files are small text (meshes,
# images and instance arrays live in files of their own), and a larger one, or a device
# such as /dev/zero, would otherwise be read into memory without limit.
MAX_SCENE_FILE_BYTES = 16 << 20


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
        Unreadable file, not a regular file, larger than :data:`MAX_SCENE_FILE_BYTES`, TOML
        syntax error, unknown key, wrong type or bad value.
    MeshError
        A mesh the scene names cannot be read.
    """
    path = os.fspath(path)
    try:
        check_file(path, "scene file")  # missing, a directory, a device, a link loop
    except MeshError as exc:
        raise SceneError(str(exc)) from None
    try:
        with open(path, "rb") as f:
            # at most one byte beyond the limit (a file may grow, or report no size: /proc)
            data = f.read(MAX_SCENE_FILE_BYTES + 1)
        if len(data) > MAX_SCENE_FILE_BYTES:
            raise SceneError(f"{path}: scene file larger than rtmesh reads ({MAX_SCENE_FILE_BYTES >> 20} MiB; "
                             "scene files are small text: keep meshes and instances in files of their own)")
        doc = tomllib.loads(data.decode("utf-8"))
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
    r = TableReader(source)
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
    placing = MeshPlacing(r, tables, base_dir)
    parts, file_cameras, file_lights = [], [], []
    for i, values in enumerate(tables):
        where = f"objects[{i}]"
        parts.extend(object_parts(r, values, where, base_dir, materials, material_index, placing, i))
        if "mesh" in values:
            try:
                # the file's lights at each of the object's instances (rows after the object's
                # transform, as its meshes are placed); its cameras by the object's transform
                transform, rows = object_transform(values), placing.rows[i]
                cameras, lights = file_cameras_and_lights(object_mesh_path(values, base_dir), transform,
                                                          physical=settings.integrator == "path",
                                                          light_transforms=None if rows is None else transform @ rows,
                                                          lights=values.get("import_lights", True))
            except RtmeshError as exc:
                raise r.error(f"{where}.mesh", str(exc)) from None
            file_cameras.extend(cameras)
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
    except MeshError as exc:
        # a file the light reads cannot be used (a projector's corrupt image): name its key
        files = [key for key, key_kind in light_type.keys.items() if key_kind == "path" and key in values]
        raise r.error(f"{where}.{files[0]}" if len(files) == 1 else where, str(exc)) from None
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
