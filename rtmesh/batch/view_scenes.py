"""An asset loaded once for all its views, and the scene and integrator each view renders.

A batch job (:mod:`rtmesh.batch.worker`) reads its mesh once (:func:`load_asset`, within the
worker process's load limit: :func:`set_memory_limit`), builds one scene for the views with
a ground plane and one for those without, and renders every view from them with its own
camera and default light rig (:func:`integrator_for_view`); :func:`asset_objects` says
which of a view's objects make the asset.
"""

import dataclasses
from dataclasses import dataclass

import numpy as np

from rtmesh.batch.normalize import asset_to_world, transform_points
from rtmesh.loaders.importers import mesh_file_parts
from rtmesh.materials.table import Material, MaterialTable
from rtmesh.rendering import memory
from rtmesh.rendering.integrator import Integrator
from rtmesh.scene.camera import frame_bounds
from rtmesh.scene.model import MeshPart, Scene, default_lights
from rtmesh.scene.studio import studio_background

# set by a worker process that runs under an address-space limit (set_memory_limit): the
# note of its failure messages, and the bytes each asset's load may take (0: not checked, as
# on a Dask worker, whose memory the cluster guards)
MEMORY_LIMIT_NOTE = ""
LOAD_LIMIT = 0


def set_memory_limit(limit):
    """Tell the jobs of this worker process its address-space limit: each asset's load is
    checked against it before the memory is taken (:func:`rtmesh.rendering.memory.check_load`,
    as ``rtmesh render --memory-limit`` checks), and memory failures name it.

    Parameters
    ----------
    limit : int
        Bytes.
    """
    global MEMORY_LIMIT_NOTE, LOAD_LIMIT
    MEMORY_LIMIT_NOTE = f" (limit {limit / 2**30:.1f} GiB)"
    LOAD_LIMIT = limit


@dataclass(frozen=True)
class LoadedAsset:
    """One asset as loaded for all its views (:func:`load_asset`).

    Attributes
    ----------
    parts : list of MeshPart
        World-space meshes, normalised if asked.
    placements : list of Placement
        Meshes the file places many times, built once and placed by Embree instances as
        ``rtmesh render`` places them (:mod:`rtmesh.loaders.placements`); their transforms
        include the normalisation.
    materials : list of Material
    bounds : (2, 3) float
        The asset's bounds, every placement included, after normalisation.
    to_world : (4, 4) float
        What normalisation applied to the file's coordinates (identity without).
    world_objects : int
        How many objects the world-space parts make: a view's ground plane, added after
        them and before the placements' objects (:meth:`Scene.from_parts` puts placements
        last), is object ``world_objects``.
    """

    parts: list
    placements: list
    materials: list
    bounds: np.ndarray
    to_world: np.ndarray
    world_objects: int

def load_asset(job):
    """Read the mesh once for all its views, with the placements of the meshes it places
    many times (glTF node reuse and ``EXT_mesh_gpu_instancing``, USD instancers), as
    ``rtmesh render`` reads it: the path integrator traces them as Embree instances, the
    others render their copies (:class:`rtmesh.rendering.integrator.Integrator`).

    Returns
    -------
    LoadedAsset
    """
    placements = []
    parts, materials = mesh_file_parts(job.path, placements=placements)  # trimesh's formats and USD
    # Scene.from_parts drops broken triangles and raises when nothing is left; build the
    # scene once here so an empty asset fails at the load stage, and frame its clean bounds
    scene = Scene.from_parts(parts, materials, lights=[], source=job.path, placements=placements)  # (no rig needed)
    bounds = scene.bounds
    world_objects = len(scene.object_names) - (0 if scene.instances is None else len(scene.instances))
    to_world = asset_to_world(bounds, job.normalize)
    if job.normalize:
        # uniform scale and shift: normals, uv and colours stay as they are
        parts = [dataclasses.replace(p, vertices=transform_points(to_world, p.vertices)) for p in parts]
        placements = [dataclasses.replace(p, transforms=to_world @ p.transforms) for p in placements]
        bounds = transform_points(to_world, bounds)
    return LoadedAsset(parts, placements, materials, bounds, to_world, world_objects)


def integrator_for_view(built, loaded, view, settings, ground):
    """The integrator rendering ``view``, sharing one built scene between views.

    ``built`` maps "has a ground plane" to the integrator of the first view built with that
    geometry (views from below leave the plane out, so an asset has at most two builds);
    later views take it with their own camera and lights (:meth:`Integrator.with_view`).
    It also keeps the integrators of the last :data:`_KEPT_VIEWS` views asked for (by
    ``("view", view)``): a view's flow needs its neighbours', which render next or just did.
    """
    key = ("view", view)
    if key in built:
        return built[key]
    with_ground = _has_ground(ground, view)
    integrator = built.get(with_ground)
    bounds = loaded.bounds
    if integrator is None:
        scene = _scene_for_view(loaded, view, settings, ground)
        # an integrator that cannot trace the placements flattens them, within the worker's
        # limit (rtmesh.rendering.memory.check_flattening), as rtmesh render does
        with memory.loading_limit(LOAD_LIMIT):
            integrator = built[with_ground] = Integrator(scene, settings)
    else:
        camera, lights = _camera_and_lights(bounds, view, settings)
        if integrator.plan.physical:
            # the studio environment turned to this view's rig camera, as the three-light rig is
            integrator = integrator.with_view(camera, [], studio_background(_rig_camera(bounds, view, settings)))
        elif settings.integrator == "path":
            integrator = integrator.with_view(camera, lights, studio_background(_rig_camera(bounds, view, settings)))
        else:
            integrator = integrator.with_view(camera, lights)
    kept = [k for k in built if isinstance(k, tuple)]
    for old in kept[:max(len(kept) + 1 - _KEPT_VIEWS, 0)]:
        del built[old]
    built[key] = integrator
    return integrator


# the previous, current and next view of a --flow sequence
_KEPT_VIEWS = 3


def _camera_and_lights(bounds, view, settings):
    """The camera framing the asset from ``view`` and the default light rig of the view.

    The perspective camera fits the bounding sphere in view (:func:`frame_bounds`), moved
    along its axis by ``view.distance_scale``; the orthographic one stands in the same place
    and its view fits the sphere (height ``2 r``, or ``2 r / aspect`` for a tall image).
    """
    aspect = settings.width / settings.height
    camera = frame_bounds(bounds, aspect=aspect, direction=view.direction, up=view.up)
    if view.distance_scale != 1.0:
        camera = dataclasses.replace(
            camera, position=camera.look_at + view.distance_scale * (camera.position - camera.look_at))
    if view.orthographic:
        radius = max(0.5 * float(np.linalg.norm(bounds[1] - bounds[0])), 1e-6)
        camera = dataclasses.replace(camera, projection="orthographic",
                                     ortho_height=2.0 * radius / min(aspect, 1.0))
    return camera, default_lights(_rig_camera(bounds, view, settings), physical=settings.integrator == "path")


def _rig_camera(bounds, view, settings):
    """The camera the light rig of ``view`` is placed for: its ``light_direction`` (fixed
    lighting for turntables), else the view's own direction."""
    return frame_bounds(bounds, aspect=settings.width / settings.height,
                        direction=view.light_direction or view.direction, up=view.up)


def _scene_for_view(loaded, view, settings, ground):
    """The asset's scene (a :class:`LoadedAsset`), framed from ``view`` and lit by the
    default rig; its placements stay placements (:attr:`Scene.instances`)."""
    bounds, placements = loaded.bounds, loaded.placements
    camera, lights = _camera_and_lights(bounds, view, settings)
    parts, materials = list(loaded.parts), list(loaded.materials) or [Material()]
    if _has_ground(ground, view):
        parts.append(_ground_part(bounds, len(materials)))
        materials.append(Material(name="ground", diffuse=np.full(3, 0.8)))
    if MaterialTable(materials).any_physical:
        # glTF metallic-roughness assets: the studio environment, turned to the view's rig
        # camera, instead of the three-light rig (see rtmesh.scene.studio)
        return Scene.from_parts(parts, materials, lights=[], camera=camera, ambient=np.zeros(3),
                                background=studio_background(_rig_camera(bounds, view, settings)),
                                source=view.name, placements=placements)
    if settings.integrator == "path":
        # the rig in the path integrator's units, with the studio environment instead of ambient light
        return Scene.from_parts(parts, materials, lights=lights, camera=camera, ambient=np.zeros(3),
                                background=studio_background(_rig_camera(bounds, view, settings)),
                                source=view.name, placements=placements)
    return Scene.from_parts(parts, materials, lights=lights, camera=camera,
                            ambient=np.full(3, 0.05), source=view.name, placements=placements)


def _ground_part(bounds, material):
    """A square under the asset (+Y up), four bounding radii wide, facing up."""
    centre = bounds.mean(axis=0)
    half = 2.0 * max(float(np.linalg.norm(bounds[1] - bounds[0])), 1e-6)
    # a hair below the lowest point so the asset's base does not z-fight with the plane
    y = bounds[0, 1] - 1e-4 * half
    x0, x1, z0, z1 = centre[0] - half, centre[0] + half, centre[2] - half, centre[2] + half
    vertices = np.array([[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]])
    faces = np.array([[0, 2, 1], [0, 3, 2]])  # counter-clockwise seen from +Y
    return MeshPart("ground", vertices, faces, material)


def asset_objects(scene, ground, view, loaded):
    """The objects of a view's scene that make the asset: all but the ground plane, where
    the view has it (object ``loaded.world_objects``: after the asset's world-space parts,
    before its placements; the last object of an asset without placements)."""
    objects = range(len(scene.object_names))
    if not _has_ground(ground, view):
        return tuple(objects)
    return tuple(k for k in objects if k != loaded.world_objects)


def _has_ground(ground, view):
    """Whether ``view`` of a batch with ``ground`` has the ground plane: views from below
    leave it out, where it would stand between the camera and the asset."""
    return bool(ground and view.direction[1] >= 0)
