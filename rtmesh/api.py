"""The Python API: load a scene, render it, write the image."""

import dataclasses
import os

import trimesh

from rtmesh.core.errors import SceneError
from rtmesh.loaders.importers import default_integrator, load_mesh_scene, scene_from_trimesh
from rtmesh.loaders.scene_file import read_scene_file
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene.model import Scene

SCENE_EXTENSIONS = (".toml",)


def load_scene(source, check_settings=None, **settings):
    """Load a scene from a scene file, a mesh file, or a trimesh object.

    Parameters
    ----------
    source : str, os.PathLike, trimesh.Trimesh or trimesh.Scene
        A ``.toml`` scene file, a mesh file (OBJ, glTF/GLB, PLY, STL, OFF, USD), or an in-memory
        trimesh object.  Meshes get an automatic camera and the default light rig.
    check_settings : callable, optional
        Called with the validated settings before any mesh is read; raises to refuse them
        (the command line's memory check, :func:`rtmesh.rendering.memory.check`).
    **settings
        Render settings (see :class:`RenderSettings`) overriding the scene file's.

    Returns
    -------
    scene : Scene
    settings : RenderSettings
    """
    overrides = {k: v for k, v in settings.items() if v is not None}
    in_memory = isinstance(source, (trimesh.Trimesh, trimesh.Scene))
    if not in_memory and os.path.splitext(os.fspath(source))[1].lower() in SCENE_EXTENSIONS:
        return read_scene_file(source, overrides, check_settings)
    if not in_memory:
        # glTF renders path traced unless asked otherwise; other mesh files with Whitted
        overrides.setdefault("integrator", default_integrator(source))
    base = RenderSettings(**overrides)
    try:
        base.validate()
    except ValueError as exc:
        raise SceneError(f"render settings: {exc}") from None
    if check_settings is not None:
        check_settings(base)
    # the automatic camera frames the bounds for the image's aspect ratio
    aspect = base.width / base.height
    physical = base.integrator == "path"
    if in_memory:
        scene = scene_from_trimesh(source, aspect=aspect, physical=physical)
    else:
        scene = load_mesh_scene(source, aspect=aspect, physical=physical)
    return scene, base


def render(scene, settings=None, progress=None, **overrides):
    """Render a scene.

    Parameters
    ----------
    scene : Scene, str, os.PathLike, trimesh.Trimesh or trimesh.Scene
        A loaded scene, or anything :func:`load_scene` accepts.
    settings : RenderSettings, optional
    progress : callable, optional
        ``progress(chunks_done, chunks_total)``.
    **overrides
        Render settings to change (``width=256, spp=16``...).

    Returns
    -------
    RenderResult
        ``image`` (height, width, 3) float32 linear radiance, ``passes``, ``stats``.
    """
    if not isinstance(scene, Scene):
        scene, loaded = load_scene(scene, **overrides)
        settings = settings or loaded
    elif settings is None:
        settings = RenderSettings(**overrides)
    elif overrides:
        settings = dataclasses.replace(settings, **overrides)
    return Integrator(scene, settings).render(progress)
