"""One batch job: load one asset, render its views, write its images.

This module runs inside a worker (a local worker process or a Dask worker).  It never
raises for a bad asset: every failure comes back as a result with the stage it happened in
(``load``, ``render``, ``write``, ``time``, ``memory``), so the batch goes on.  Each result
also says what the asset was made from (``inputs``: the mesh file and every file its load
read) and what was written (``outputs``: size and checksum of each file), see
:mod:`rtmesh.batch.identity`.  A batch's jobs leave their files at temporary names for the
submitting process to put in place (:mod:`rtmesh.batch.publish`).
"""

import contextlib
import dataclasses
import os
import tempfile
import time
from dataclasses import dataclass

import numpy as np

from rtmesh.batch.asset_meta import WarningLog, asset_meta, write_meta
from rtmesh.batch.bop import BOP_SUFFIXES, write_view_files
from rtmesh.batch.coco import COCO_SUFFIX, Instance, image_annotations, image_entry, write_coco
from rtmesh.batch.flow import FLOW_PASSES, flow_suffix, seen_points, view_flow, write_flo
from rtmesh.batch.identity import OpenedFiles, describe
from rtmesh.batch.normalize import asset_to_world, transform_points
from rtmesh.batch.publish import discard
from rtmesh.core import runtime
from rtmesh.core.errors import RtmeshError
from rtmesh.io.atomic_files import staged
from rtmesh.io.images import write_depth_png, write_display_image, write_image
from rtmesh.loaders.importers import default_integrator, mesh_file_parts
from rtmesh.materials.table import Material, MaterialTable
from rtmesh.rendering.centre_rays import centre_passes
from rtmesh.rendering import memory
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene.camera import frame_bounds
from rtmesh.scene.camera_json import camera_record, write_camera_json
from rtmesh.scene.model import MeshPart, Scene, default_lights
from rtmesh.scene.studio import studio_background

# Directions from the subject towards the camera, and the camera's up vector.  "iso" is the
# automatic camera's direction (rtmesh.scene.camera.frame_bounds); top and bottom need another up
# vector, since +Y is parallel to their view.
VIEWS = {
    "iso": ((0.6, 0.45, 1.0), (0.0, 1.0, 0.0)),
    "front": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    "back": ((0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
    "left": ((-1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    "right": ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    "top": ((0.0, 1.0, 0.0), (0.0, 0.0, -1.0)),
    "bottom": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
}
# the file next to an image that describes its camera (``--camera-json``), and the depth
# (16-bit PNG, millimetres) and mask (8-bit PNG) images of datasets (rtmesh.batch.datasets)
CAMERA_SUFFIX = ".camera.json"
DEPTH_PNG_SUFFIX, MASK_PNG_SUFFIX = ".depth.png", ".mask.png"


@dataclass(frozen=True)
class View:
    """Where one image is seen from.

    Attributes
    ----------
    name : str
        ``iso``, ``front``... or ``turn007`` for frame 7 of a turntable.
    direction : (3,) tuple of float
        From the centre of the asset's bounding sphere towards the camera.
    up : (3,) tuple of float
    light_direction : (3,) tuple of float
        Camera direction the default light rig is placed for: the view's own for fixed views
        (each is well lit), frame 0's for a turntable (lights stay put while the camera
        orbits, so the shading moves across the object as it would on a real turntable).
    orthographic : bool
        An orthographic camera whose view height fits the asset's bounding sphere (CAD
        views, ``--ortho``) instead of the perspective one.
    distance_scale : float
        The camera's distance from the centre, as a multiple of the auto-framed distance
        (radius jitter of view sets; 1 frames the bounding sphere exactly).
    """

    name: str
    direction: tuple
    up: tuple = (0.0, 1.0, 0.0)
    light_direction: tuple | None = None
    orthographic: bool = False
    distance_scale: float = 1.0

    def identity(self):
        """The view's fields for its images' fingerprint; fields added after rtmesh 0.1 are
        left out at their defaults, so the images of earlier batches keep their fingerprints."""
        fields = dataclasses.asdict(self)
        for name, default in (("orthographic", False), ("distance_scale", 1.0)):
            if fields[name] == default:
                del fields[name]
        return fields


def fixed_view(name):
    """The named fixed view (see ``VIEWS``); raises KeyError for an unknown name."""
    direction, up = VIEWS[name]
    return View(name, direction, up, direction)


def turntable_views(frames):
    """``frames`` views orbiting the vertical (+Y) axis at the ``iso`` view's elevation.

    Frame 0 is the ``iso`` view; the camera moves counter-clockwise seen from above.
    """
    (x, y, z), up = VIEWS["iso"]
    radius, start = np.hypot(x, z), np.arctan2(x, z)
    views = []
    for k in range(frames):
        angle = start + 2.0 * np.pi * k / frames
        direction = (float(radius * np.sin(angle)), y, float(radius * np.cos(angle)))
        views.append(View(f"turn{k:03d}", direction, up, (x, y, z)))
    return views


@dataclass(frozen=True)
class ImageTask:
    """One image of an asset: a view, written in one or more formats.

    Attributes
    ----------
    key : str
        Ledger key: output path relative to the output folder, without extension.
    view : View
    files : tuple of str
        Output files relative to the output folder, one per format.
    fingerprint : str
        Hash of everything the image depends on (input file, settings, view, formats).
    flow : tuple of (View or None)
        With ``--flow``: the views before and after this one in the asset's order (None at
        either end), whose flow passes the image gets (:mod:`rtmesh.batch.flow`); empty
        without.
    """

    key: str
    view: View
    files: tuple
    fingerprint: str
    flow: tuple = ()


@dataclass(frozen=True)
class AssetJob:
    """Everything a worker needs to convert one asset; plain data, so it pickles.

    Attributes
    ----------
    asset : str
        Asset name (relative path, for messages and the report).
    path : str
        Absolute mesh path.
    outdir : str
        Absolute output folder (shared with the workers).
    settings : dict
        :class:`RenderSettings` fields.
    images : tuple of ImageTask
        The views still to do.
    ground : bool
        Put a grey ground plane under the asset (it catches the asset's shadow); views from
        below leave it out (it would hide the asset).
    run : str
        Id of the batch run the job belongs to.
    run_file : str
        If set, the file naming the batch run that owns the output folder: the job stops,
        writing nothing more, once it names another run (a resumed batch has taken over).
    normalize : str
        ``""``, ``unit-cube`` or ``unit-sphere``: move the asset first (see
        :mod:`rtmesh.batch.normalize`).
    meta : bool
        Write ``<asset>.meta.json`` once the asset is loaded (:mod:`rtmesh.batch.asset_meta`).
    units : str
        The scene units of ``--dataset bop`` (``m``, ``cm`` or ``mm``).
    staged : bool
        Leave every file at its hidden temporary name and report that name (``staged`` and
        ``side_files`` in the results), for the submitting process to rename into place
        once it has recorded the image (:mod:`rtmesh.batch.publish`); False writes the
        files in place.

    Output files of an image ending in :data:`CAMERA_SUFFIX` get the camera JSON of the
    image (:func:`rtmesh.scene.camera_json.camera_record`), the others the image.
    """

    asset: str
    path: str
    outdir: str
    settings: dict
    images: tuple
    ground: bool = False
    run: str = ""
    run_file: str = ""
    normalize: str = ""
    meta: bool = False
    staged: bool = False
    units: str = "m"


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
    """One asset as loaded for all its views (:func:`_load`).

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


class TimeLimitExceeded(Exception):
    """Raised inside a render when the job's deadline passes (cooperative time limit)."""


class Superseded(Exception):
    """Raised inside a job whose batch run no longer owns the output folder."""


def current_run(run_file):
    """The run id written in ``run_file`` ("" if it cannot be read)."""
    try:
        with open(run_file, encoding="utf-8") as f:
            return f.read().strip()
    except OSError:
        return ""


def run_job(job, on_image=None, deadline=None, abandoned=None):
    """Convert one asset: load it once, then render and write each of its views.

    Parameters
    ----------
    job : AssetJob
    on_image : callable, optional
        ``on_image(image_result)`` after each image's files are all written, so the caller
        can record it at once.
    deadline : float, optional
        ``time.monotonic()`` value after which the job stops between render chunks (used
        where the job cannot be killed from outside, as on a Dask worker).
    abandoned : callable, optional
        ``abandoned()`` is True once nobody waits for the job's result any more (its Dask
        client is gone): the job then stops like a superseded one, before its next write.

    Returns
    -------
    dict
        ``asset``, ``seconds``, ``superseded`` (True when the job stopped because a newer
        run owns the output folder or nobody waits for it: its unfinished images are left
        out, and the staged files of images not yet handed to ``on_image`` are removed),
        ``images``: one dict per image task with ``key``, ``fingerprint``, ``status``
        (``"done"`` or ``"failed"``), ``asset``, ``run``, ``files``, ``seconds``,
        ``inputs``, ``outputs``, for failures ``stage`` and ``message`` (one line), and
        for a staged job's done images ``staged`` (the temporary name of each of
        ``files``, relative to the output folder).  The first image result of a staged
        job that wrote the asset's metadata file also has ``side_files``: ``[temporary,
        name]`` pairs to put in place with it.
    """
    start = time.perf_counter()
    results = []
    inputs = []
    last_check = [0.0]
    side = []  # the asset's staged metadata file: it goes with the job's first image result
    handed = [0]  # results already given to on_image (their files are the caller's)

    def stop_if_superseded():
        if abandoned is not None and abandoned():
            raise Superseded()
        # the run file is read at most twice a second between render chunks
        if job.run_file and time.monotonic() - last_check[0] > 0.5:
            last_check[0] = time.monotonic()
            if current_run(job.run_file) != job.run:
                raise Superseded()

    def check(done=None, total=None):
        _check_deadline(deadline)
        stop_if_superseded()

    def emit(result):
        if side:
            result["side_files"] = side[:]
            side.clear()
        results.append(result)
        if on_image:
            on_image(result)
            handed[0] = len(results)

    def fail_all(tasks, stage, message):
        for task in tasks:
            emit(image_result(job, task, "failed", 0.0, inputs, stage=stage, message=message))

    def superseded():
        # nobody will put these files in place: the next run would only remove them
        for result in results[handed[0]:]:
            discard(job.outdir, result.get("staged", ()))
            discard(job.outdir, [t for t, _ in result.get("side_files", ())])
        discard(job.outdir, [t for t, _ in side])
        return _job_result(job, results, start, superseded=True)

    try:
        fields = dict(job.settings)
        if fields.get("integrator") is None:
            # glTF path traced, other files with Whitted, unless the batch asks for one
            fields["integrator"] = default_integrator(job.path)
        settings = RenderSettings(**fields).validate()
    except (TypeError, ValueError) as exc:
        fail_all(job.images, "settings", str(exc))
        return _job_result(job, results, start)
    opened = OpenedFiles()
    try:
        # a file too large for the worker's limit fails here, at the load stage, in one line
        with opened, WarningLog() as warnings, memory.loading_limit(LOAD_LIMIT):
            loaded = _load(job)
    except MemoryError:
        fail_all(job.images, "memory", f"out of memory while loading{MEMORY_LIMIT_NOTE}")
        return _job_result(job, results, start)
    except Exception as exc:  # any failure of one asset is that asset's, not the batch's
        inputs.extend(opened.entries(job.path))
        fail_all(job.images, "load", _one_line(exc))
        return _job_result(job, results, start)
    inputs.extend(opened.entries(job.path))
    if job.meta:
        try:
            check()
            with _writing(job) as pending:
                write_meta(job.outdir, job.asset, asset_meta(job.asset, job.path, loaded.parts, loaded.materials,
                                                             loaded.bounds, loaded.to_world, inputs, warnings.lines,
                                                             loaded.placements))
            side.extend(_relative(job, pending))
        except (Superseded, TimeLimitExceeded):
            pass  # the images' loop below stops the same way
        except Exception as exc:
            fail_all(job.images, "write", _one_line(exc))
            return _job_result(job, results, start)

    built = {}  # with a ground plane? -> the integrator built for the first such view
    accels = {}  # the asset's own Embree scene, for the amodal masks of every view
    for i, task in enumerate(job.images):
        image_start = time.perf_counter()
        stage = "render"
        try:
            check()
            integrator = _integrator_for_view(built, loaded, task.view, settings, job.ground)
            result = integrator.render(progress=check)
            labels = _labels(integrator, result, task)
            passes = result.passes
            if task.flow:
                passes = {**passes, **_flows(labels, task, built, loaded, settings, job.ground)}
            stage = "write"
            last_check[0] = 0.0  # always ask just before writing
            check()
            paths = [os.path.abspath(os.path.join(job.outdir, name)) for name in task.files]
            with runtime.render_pool(settings.thread_count) as workers, _writing(job) as pending:
                fragment = None
                if (workers is not None and any(f.endswith(COCO_SUFFIX) for f in task.files)
                        and not any(f.endswith(BOP_SUFFIXES) for f in task.files)):
                    # the COCO fragment formed beside the image writes (its Embree rays and
                    # OpenImageIO's encoders run without the GIL); BOP files share its cache
                    fragment = workers.submit(image_fragment, integrator, labels, task, settings, loaded,
                                              job.asset, job.ground, accels)
                for name, path in zip(task.files, paths):
                    os.makedirs(os.path.dirname(path), exist_ok=True)
                    if name.endswith(CAMERA_SUFFIX):
                        scene = integrator.scene
                        write_camera_json(path, camera_record(scene.camera, settings.width, settings.height,
                                                              integrator.scene_bounds, loaded.to_world))
                    elif name.endswith(DEPTH_PNG_SUFFIX):
                        write_depth_png(path, result.passes["depth"][:, :, 0])
                    elif name.endswith(BOP_SUFFIXES):
                        if name.endswith(BOP_SUFFIXES[0]):  # the other three with it
                            scene = integrator.scene
                            record = camera_record(scene.camera, settings.width, settings.height,
                                                   integrator.scene_bounds, loaded.to_world)
                            bop_paths = {x: p for x in BOP_SUFFIXES for p in paths if p.endswith(x)}
                            write_view_files(bop_paths, integrator, labels, record,
                                             _asset_objects(scene, job.ground, task.view, loaded), job.units, accels)
                    elif name.endswith(COCO_SUFFIX):
                        write_coco(path, fragment.result() if fragment is not None else
                                   image_fragment(integrator, labels, task, settings, loaded, job.asset,
                                                  job.ground, accels))
                    elif name.endswith(MASK_PNG_SUFFIX):
                        write_display_image(path, (result.passes["alpha"][:, :, :1] > 0.5).astype(np.float64))
                    elif name.endswith(".flo"):
                        write_flo(path, passes[next(f for f in FLOW_PASSES if name.endswith(flow_suffix(f)))])
                    else:
                        write_image(path, result.image, passes, settings.exposure, settings.tonemap,
                                    header=settings.header(), dither=settings.dither)
                # superseded while writing: the block's temporaries are removed, not reported.
                # The run file is read again: a run that took the folder removes the
                # temporaries already there when it did; later ones are this task's to remove
                last_check[0] = 0.0
                stop_if_superseded()
            written = {path: tmp for tmp, path in pending}
            outputs = [describe(written.get(path, path), name) for name, path in zip(task.files, paths)]
            extra = {"staged": [t for t, _ in _relative(job, pending)]} if job.staged else {}
            outcome = image_result(job, task, "done", time.perf_counter() - image_start, inputs,
                                   outputs=outputs, **extra)
        except Superseded:
            return superseded()
        except TimeLimitExceeded:
            fail_all(job.images[i:], "time", "time limit exceeded")
            break
        except MemoryError:
            outcome = image_result(job, task, "failed", time.perf_counter() - image_start, inputs,
                                   stage="memory", message=f"out of memory during {stage}{MEMORY_LIMIT_NOTE}")
        except Exception as exc:
            outcome = image_result(job, task, "failed", time.perf_counter() - image_start, inputs,
                                   stage=stage, message=_one_line(exc))
        emit(outcome)
    return _job_result(job, results, start)


def _labels(integrator, result, task):
    """The render's passes and the pixel-centre passes a view's annotations, BOP files and
    flow read (:mod:`rtmesh.rendering.centre_rays`), each traced once, only those asked for
    and not rendered already; they go to no image unless the passes named them."""
    wanted = set()
    if any(f.endswith((COCO_SUFFIX,) + BOP_SUFFIXES) for f in task.files):
        wanted.add("object_id")
    if any(f.endswith(BOP_SUFFIXES) for f in task.files):
        wanted.add("depth_center")
    if task.flow:
        wanted.add("position_center")
    return {**centre_passes(integrator, sorted(wanted - set(result.passes))), **result.passes}


def image_fragment(integrator, labels, task, settings, loaded, asset, ground, accels=None):
    """The COCO fragment of one batch image (:mod:`rtmesh.batch.coco`): the asset
    (:class:`LoadedAsset` ``loaded``, named ``asset``) is one instance of category ``asset``,
    its model frame the asset file's; the ground plane is not annotated
    (:func:`_asset_objects`)."""
    scene = integrator.scene
    to_world = loaded.to_world
    record = camera_record(scene.camera, settings.width, settings.height, integrator.scene_bounds, to_world)
    objects = _asset_objects(scene, ground, task.view, loaded)
    pictures = [f for f in task.files if f.endswith((".png", ".jpg", ".exr"))
                and not f.endswith((DEPTH_PNG_SUFFIX, MASK_PNG_SUFFIX))]
    instance = Instance(asset, asset, objects, np.asarray(to_world, dtype=np.float64))
    annotations = image_annotations(integrator, record, [instance], labels["object_id"], accels)
    return {"image": image_entry(os.path.basename(pictures[0]), record), "annotations": annotations}


def _flows(labels, task, built, loaded, settings, ground):
    """``flow_forward`` and ``flow_backward`` of one view (see :mod:`rtmesh.batch.flow`),
    towards the views of ``task.flow``, each traced in its own view's scene; the two run
    side by side on the render's threads (their rays go to Embree without the GIL)."""
    position = labels["position_center"]
    seen = seen_points(position)  # the view's points, for both directions
    calls = {}
    for name, view in zip(("flow_backward", "flow_forward"), task.flow):
        other = record = None
        if view is not None:
            other = _integrator_for_view(built, loaded, view, settings, ground)
            scene = other.scene
            record = camera_record(scene.camera, settings.width, settings.height, other.scene_bounds,
                                   loaded.to_world)
        calls[name] = (position, other, record, seen)
    traced = [name for name, call in calls.items() if call[1] is not None]
    flows = {name: view_flow(*call) for name, call in calls.items() if name not in traced}
    with runtime.render_pool(min(settings.thread_count, len(traced))) as workers:
        later = {name: workers.submit(view_flow, *calls[name]) for name in traced[1:]} if workers else {}
        for name in traced:
            if name not in later:
                flows[name] = view_flow(*calls[name])
        flows.update({name: future.result() for name, future in later.items()})
    return {name: flows[name] for name in FLOW_PASSES}


def _asset_objects(scene, ground, view, loaded):
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


def _writing(job):
    """Where the job's writes go: a :func:`rtmesh.io.atomic_files.staged` block (the files
    stay at their temporary names) for a staged job, else straight into place."""
    return staged() if job.staged else contextlib.nullcontext([])


def _relative(job, pending):
    """``(temporary, path)`` pairs of a staged block as names relative to the output folder."""
    return [[os.path.relpath(tmp, job.outdir), os.path.relpath(path, job.outdir)] for tmp, path in pending]


def warm_up():
    """Convert a tiny asset the way a job does (load, smooth, render, write a PNG, in a
    temporary folder), so that the kernels are compiled, or loaded from numba's disk cache,
    before a worker's first real asset, whose time limit then does not pay for them."""
    with tempfile.TemporaryDirectory(prefix="rtmesh-warm-up-") as folder:
        path = os.path.join(folder, "warm-up.obj")
        with open(path, "w", encoding="utf-8") as f:
            f.write("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
        task = ImageTask("warm-up", fixed_view("iso"), ("warm-up.png",), "")
        settings = {"width": 8, "height": 8, "spp": 1, "threads": 1}
        return run_job(AssetJob("warm-up.obj", path, folder, settings, (task,), ground=True))


def _load(job):
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


def _integrator_for_view(built, loaded, view, settings, ground):
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


def _check_deadline(deadline):
    if deadline is not None and time.monotonic() > deadline:
        raise TimeLimitExceeded()


def _one_line(exc):
    """An exception as one line of text (RtmeshError messages already name the file)."""
    text = " ".join(str(exc).split())
    if isinstance(exc, RtmeshError):
        return text
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def image_result(job, task, status, seconds, inputs=(), outputs=(), **fields):
    """One image's result, as :func:`run_job` reports it (also used by the runners for
    images a lost worker never finished)."""
    return {"asset": job.asset, "run": job.run, "key": task.key, "fingerprint": task.fingerprint, "status": status,
            "files": list(task.files), "seconds": round(seconds, 4), "inputs": list(inputs),
            "outputs": list(outputs), **fields}


def _job_result(job, images, start, superseded=False):
    return {"asset": job.asset, "seconds": round(time.perf_counter() - start, 4),
            "superseded": superseded, "images": images}
