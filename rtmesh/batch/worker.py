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
import os
import tempfile
import time

import numpy as np

from rtmesh.batch import view_scenes
from rtmesh.batch.asset_meta import WarningLog, asset_meta, write_meta
from rtmesh.batch.bop import BOP_SUFFIXES, write_view_files
from rtmesh.batch.coco import COCO_SUFFIX, write_coco
from rtmesh.batch.flow import FLOW_PASSES, flow_suffix, write_flo
from rtmesh.batch.identity import OpenedFiles, describe
from rtmesh.batch.jobs import CAMERA_SUFFIX, DEPTH_PNG_SUFFIX, MASK_PNG_SUFFIX, AssetJob, ImageTask, fixed_view
from rtmesh.batch.publish import discard
from rtmesh.batch.view_labels import image_fragment, label_passes, neighbour_flows
from rtmesh.batch.view_scenes import asset_objects, integrator_for_view, load_asset
from rtmesh.core import runtime
from rtmesh.core.errors import RtmeshError
from rtmesh.io.atomic_files import staged
from rtmesh.io.images import write_depth_png, write_display_image, write_image
from rtmesh.loaders.importers import default_integrator
from rtmesh.rendering import memory
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene.camera_json import camera_record, write_camera_json


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
    try:
        # a render beyond the worker's memory fails at once, as rtmesh render refuses it
        # (without a worker limit, as on a Dask worker: beyond the memory available now)
        memory.check(settings, view_scenes.LOAD_LIMIT or None)
    except RtmeshError as exc:
        fail_all(job.images, "memory", str(exc))
        return _job_result(job, results, start)
    opened = OpenedFiles()
    try:
        # a file too large for the worker's limit fails here, at the load stage, in one line
        with opened, WarningLog() as warnings, memory.loading_limit(view_scenes.LOAD_LIMIT):
            loaded = load_asset(job)
    except MemoryError:
        fail_all(job.images, "memory", f"out of memory while loading{view_scenes.MEMORY_LIMIT_NOTE}")
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
            integrator = integrator_for_view(built, loaded, task.view, settings, job.ground)
            result = integrator.render(progress=check)
            labels = label_passes(integrator, result, task)
            passes = result.passes
            if task.flow:
                passes = {**passes, **neighbour_flows(labels, task, built, loaded, settings, job.ground)}
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
                                             asset_objects(scene, job.ground, task.view, loaded), job.units, accels)
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
                                   stage="memory",
                                   message=f"out of memory during {stage}{view_scenes.MEMORY_LIMIT_NOTE}")
        except Exception as exc:
            outcome = image_result(job, task, "failed", time.perf_counter() - image_start, inputs,
                                   stage=stage, message=_one_line(exc))
        emit(outcome)
    return _job_result(job, results, start)

def _writing(job):
    """Where the job's writes go: a :func:`rtmesh.io.atomic_files.staged` block (the files
    stay at their temporary names) for a staged job, else straight into place."""
    return staged() if job.staged else contextlib.nullcontext([])


def _relative(job, pending):
    """``(temporary, path)`` pairs of a staged block as names relative to the output folder."""
    return [[os.path.relpath(tmp, job.outdir), os.path.relpath(path, job.outdir)] for tmp, path in pending]


def warm_up():
    """Convert a tiny asset the way a job does (load, smooth, render, write a PNG, in a
    temporary folder) under each integrator, so that the kernels are compiled, or loaded
    from numba's disk cache, before a worker's first real asset, whose time limit then does
    not pay for them: Whitted (a mesh file's default; a bare mesh takes the fused direct
    stage) and path (glTF's default, and the kernel that renders every other Whitted scene).
    Run within :func:`rtmesh.core.compile_ahead.helper` on a first run, the helper process
    compiles half of each.

    Returns
    -------
    tuple of dict
        :func:`run_job`'s result of each render.
    """
    with tempfile.TemporaryDirectory(prefix="rtmesh-warm-up-") as folder:
        path = os.path.join(folder, "warm-up.obj")
        with open(path, "w", encoding="utf-8") as f:
            f.write("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
        results = []
        for integrator in ("whitted", "path"):
            task = ImageTask(f"warm-up-{integrator}", fixed_view("iso"), (f"warm-up-{integrator}.png",), "")
            settings = {"width": 8, "height": 8, "spp": 1, "threads": 1, "integrator": integrator}
            results.append(run_job(AssetJob("warm-up.obj", path, folder, settings, (task,), ground=True)))
        return tuple(results)


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
