"""Batch conversion: render whole asset collections, locally or on a Dask cluster.

>>> import rtmesh
>>> report = rtmesh.batch_convert(["models/"], "thumbs/", width=128, height=128)  # doctest: +SKIP
>>> report.counts  # doctest: +SKIP
{'assets': 50, 'done': 49, 'skipped': 0, 'failed': 1, 'known_failed': 0, 'retried': 0,
 'not_attempted': 0, 'images': 50}

The pieces, one job each:

- :mod:`rtmesh.batch.inputs` finds the assets (files, folders, manifests) and names them;
- :mod:`rtmesh.batch.identity` says what an image depends on and whether it changed;
- :mod:`rtmesh.batch.options` checks what the batch is asked to do;
- this module plans one job per asset (its views and output files, minus those the ledger
  says are finished and unchanged) and runs them;
- :mod:`rtmesh.batch.books` keeps the books (ledger entries, per-asset files, the report)
  and :mod:`rtmesh.batch.progress` shows the progress;
- :mod:`rtmesh.batch.publish` puts the images in place, only from this process and only once
  they are recorded, and deals with what a killed run left;
- :mod:`rtmesh.batch.jobs` describes the jobs, :mod:`rtmesh.batch.worker` converts one asset
  inside a worker (its views' scenes from :mod:`rtmesh.batch.view_scenes`, their labels from
  :mod:`rtmesh.batch.view_labels`);
- :mod:`rtmesh.batch.pool` runs the jobs on local processes, :mod:`rtmesh.batch.dask_pool` on a
  Dask cluster;
- :mod:`rtmesh.batch.ledger` remembers finished and failed images so a re-run resumes.

Exit statuses of the ``rtmesh batch`` command (:attr:`rtmesh.batch.books.BatchReport.exit_code`):
:data:`EXIT_DONE` (0) every asset done, :data:`EXIT_FAILED` (1) some assets failed in this
run, :data:`EXIT_USAGE` (2) bad invocation (nothing ran), :data:`EXIT_CLUSTER_LOST` (3)
the Dask cluster was lost (resume to continue).
"""

import dataclasses
import json
import os
import tempfile
import time
import uuid

from rtmesh.batch.books import SUMMARY_NAME, Books
from rtmesh.batch.coco import COCO_SUFFIX, write_batch_annotations
from rtmesh.batch.contact_sheet import write_contact_sheets
from rtmesh.batch.flow import FLOW_PASSES, flow_suffix
from rtmesh.batch.datasets import dataset_suffixes
from rtmesh.batch.identity import image_fingerprint, inputs_unchanged, unchanged
from rtmesh.batch.inputs import InputError, discover
from rtmesh.batch.ledger import FINGERPRINT, INPUTS, OUTPUTS, STATUS, Ledger, decode
from rtmesh.batch.options import FORMATS, BatchOptions, check_names, check_passes
from rtmesh.batch.publish import Leftovers
from rtmesh.batch.view_sets import view_set
from rtmesh.batch.jobs import CAMERA_SUFFIX, VIEWS, AssetJob, ImageTask, fixed_view, turntable_views
from rtmesh.core import compile_ahead
from rtmesh.core.errors import OutputError
from rtmesh.core.runtime import usable_cores
from rtmesh.io.atomic_files import write_text
from rtmesh.loaders.importers import MESH_EXTENSIONS
from rtmesh.rendering.settings import PASSES

# names the run that holds the output folder, so that the tasks of an earlier run (its
# submitting process killed) stop early instead of rendering what nobody will put in place
RUN_FILE = ".rtmesh-batch-run"


_PLAN_CHUNK = 5000  # assets planned per ledger look-up


def batch_convert(inputs, outdir, **options):
    """Render every asset named by ``inputs`` into ``outdir``, resuming an earlier run.

    Parameters
    ----------
    inputs : sequence of str or os.PathLike
        Mesh files, folders (searched recursively for mesh files) and manifests (one path per
        line, or CSV with per-asset overrides): see :func:`rtmesh.batch.inputs.discover`.
    outdir : str or os.PathLike
        Output folder, created if needed.  Images mirror the input tree:
        ``OUTDIR/<name>.<ext>`` for one view, ``OUTDIR/<name>.<view>.<ext>`` for several
        (``chairs/oak.obj.png``, ``chairs/oak.obj.turn007.png``), where the name is the
        asset's path relative to its input root.
    **options
        Fields of :class:`BatchOptions`.

    Returns
    -------
    BatchReport
        Failed assets are in the report; they do not raise.  A lost Dask cluster does not
        raise either: ``counts["not_attempted"]`` says how many assets are left for a resume.

    Raises
    ------
    RtmeshError
        Bad inputs or options, no asset found, an unwritable output folder, Dask missing or
        unreachable, no Dask worker able to write the output folder: raised before any job
        runs.
    """
    opts = BatchOptions(**options).validate()
    if isinstance(inputs, (str, os.PathLike)):
        inputs = [inputs]
    start = time.perf_counter()
    # (an output folder inside an input folder is not searched: its BOP models are meshes)
    assets = discover(inputs, skip=(outdir,))
    if not assets:
        raise InputError(f"no mesh files ({', '.join(MESH_EXTENSIONS)}) found in "
                         f"{', '.join(map(os.fspath, inputs)) or '(no inputs)'}")
    for asset in assets:
        _check_overrides(asset, opts)
    progress_stream = _open_progress_file(opts)
    outdir = os.path.abspath(os.fspath(outdir))
    _make_output_folder(outdir)
    if opts.scheduler is not None:
        _check_dask()
    run = uuid.uuid4().hex[:16]
    with Ledger(outdir) as ledger:
        write_text(os.path.join(outdir, RUN_FILE), run + "\n")
        # the temporaries a killed run left, found while this batch holds the folder (no
        # other submitting process is putting files in place) and after the run file names
        # this run (a task of an earlier run that writes later removes its files itself):
        # the plan rolls forward those its ledger rows recorded, the rest are removed
        leftovers = Leftovers(outdir)
        book = Books(ledger, outdir, opts, len(assets), progress_stream)
        try:
            jobs = plan(assets, outdir, opts, ledger, book, run, leftovers)
            leftovers.remove()
            book.start_progress()
            if not jobs:
                runner = "nothing to do"
            elif opts.scheduler is not None:
                from rtmesh.batch.dask_pool import ClusterLost, run_dask

                runner = "dask"
                try:
                    run_dask(jobs, opts.scheduler, book.on_image, book.on_job, run=run,
                             outdir=outdir, time_limit=opts.time_limit)
                except ClusterLost:
                    book.counts["not_attempted"] = len(jobs) - book.finished_jobs
            else:
                from rtmesh.batch.pool import run_local

                workers = opts.workers or usable_cores()
                used = min(workers, len(jobs))
                runner = f"{used} local worker{'s' if used > 1 else ''}"
                # the workers' warm-up compiles the kernels on a first run, a minute or so
                # before the first asset is done and the bar moves
                if compile_ahead.first_run():
                    book.progress.note(compile_ahead.FIRST_RUN_NOTE)
                run_local(jobs, workers, book.on_image, book.on_job, time_limit=opts.time_limit,
                          memory_limit=_memory_limit(opts.memory_limit, workers))
        finally:
            book.close()
        if opts.contact_sheet:
            write_contact_sheets(outdir, book.sheet)
        if opts.annotations:
            write_batch_annotations(outdir, book.sheet)
    report = book.report(time.perf_counter() - start, runner, run)
    report.path = os.path.join(outdir, SUMMARY_NAME)
    write_text(report.path, json.dumps(report.to_dict(), indent=1) + "\n")
    return report


def _check_overrides(asset, opts):
    o = asset.overrides
    where = f"{asset.source or asset.path}: "
    check_names(where + "views", o.get("views", ()), VIEWS)
    check_names(where + "formats", o.get("formats", ()), FORMATS)
    check_names(where + "passes", o.get("passes", ()), PASSES)
    check_passes(o.get("passes", opts.passes), o.get("formats", opts.formats), where)


def _open_progress_file(opts):
    """The file ``--progress jsonl`` appends to (None for stderr), opened before anything
    is created so a bad path stops the batch at once."""
    if opts.quiet or opts.progress != "jsonl" or not opts.progress_file:
        return None
    try:
        return open(opts.progress_file, "a", encoding="utf-8")
    except OSError as exc:
        raise OutputError(f"{opts.progress_file}: cannot write progress: {exc.strerror}") from None


def plan(assets, outdir, opts, ledger, book, run="", leftovers=None):
    """One job per asset with the images that are not finished and unchanged.

    An image is skipped when the ledger has it ``done`` with the same fingerprint, its
    inputs are unchanged and its files are there with the recorded size and checksum
    (size and time with ``trust_mtime``), or are among ``leftovers`` with that content (a
    run killed between recording the image and putting it in place: they are put in place
    now, and the row names this run as the one that did).  An image that failed before
    with the same fingerprint and inputs is a known failure: tried again with
    ``retry_failed``, else left.

    Returns
    -------
    list of AssetJob
        Skipped assets and known failures are entered in ``book`` directly.
    """
    jobs = []
    local_threads = opts.threads or max(1, usable_cores() // (opts.workers or usable_cores()))
    threads = opts.threads or (1 if opts.scheduler is not None else local_threads)
    run_file = os.path.join(outdir, RUN_FILE) if opts.scheduler is not None else ""
    shared = {}
    for first in range(0, len(assets), _PLAN_CHUNK):
        chunk = [_image_tasks(asset, opts, shared) for asset in assets[first:first + _PLAN_CHUNK]]
        found = {} if opts.force else ledger.lookup([t.key for _, _, tasks in chunk for t in tasks])
        for asset, fields, tasks in chunk:
            todo, skipped, known, retried = [], [], [], False
            checked = {}  # encoded inputs -> unchanged? (shared by an asset's images)
            for task in tasks:
                entry = found.get(task.key)
                if entry is None or entry[FINGERPRINT] != task.fingerprint:
                    todo.append(task)
                    continue
                same = checked.get(entry[INPUTS])
                if same is None:
                    same = checked[entry[INPUTS]] = inputs_unchanged(
                        decode(entry[INPUTS]), asset.path, opts.trust_mtime)
                if not same:
                    todo.append(task)
                elif entry[STATUS] == "done":
                    state = _files_in_place(decode(entry[OUTPUTS]), outdir, opts.trust_mtime, leftovers)
                    if state is None:
                        todo.append(task)
                    else:
                        if state == "rolled forward":
                            ledger.set_run(task.key, run)
                        skipped.append(task)
                elif opts.retry_failed:
                    todo.append(task)
                    retried = True
                else:
                    known.append(task)
            book.planned(asset, skipped, known, retried if todo else False, bool(todo))
            if todo:
                jobs.append(AssetJob(asset.name, asset.path, outdir, {**fields, "threads": threads},
                                     tuple(todo), opts.ground, run, run_file, opts.normalize,
                                     opts.asset_meta, staged=True, units=opts.units))
    return jobs


def _files_in_place(outputs, outdir, trust_mtime, leftovers):
    """``"in place"`` when every recorded output file is there unchanged, ``"rolled
    forward"`` when some were put there from ``leftovers`` (:class:`Leftovers`), None when
    a file is missing or different."""
    state = "in place"
    for entry in outputs:
        path = os.path.join(outdir, entry[0])
        if unchanged(entry, path, trust_mtime):
            continue
        if leftovers is None or not leftovers.roll_forward(entry, path):
            return None
        state = "rolled forward"
    return state


def _image_tasks(asset, opts, shared):
    """The asset, its render fields and one ImageTask per view.

    ``shared`` caches what depends only on the settings (fields, views, fingerprints) by
    the asset's overrides, so most assets of a batch (no overrides) pay only for names.
    """
    o = asset.overrides
    cache_key = json.dumps(o, sort_keys=True) if o else ""
    settings = shared.get(cache_key)
    if settings is None:
        fields = opts.render_fields(o)
        frames = o.get("turntable", opts.turntable)
        if frames:
            views = turntable_views(frames)
        elif opts.view_set and "views" not in o:
            views = view_set(opts.view_set, fields["seed"], opts.elevation, opts.radius_jitter)
        else:
            views = [fixed_view(v) for v in o.get("views", opts.views)]
        if opts.ortho and not frames:
            views = [dataclasses.replace(view, orthographic=True) for view in views]
        # the file names are the image's key (its identity) plus the formats (and the camera)
        suffixes = [f".{fmt}" for fmt in o.get("formats", opts.formats)]
        extras = dataset_suffixes(opts.dataset, fields["passes"])
        suffixes += [CAMERA_SUFFIX] * (opts.camera_json and not extras) + extras + [COCO_SUFFIX] * opts.annotations
        if opts.flow and opts.flow_format == "flo":
            suffixes += [flow_suffix(name) for name in FLOW_PASSES]
        # (a metadata file is written by the job that loads the asset: asking for it redoes them)
        extra = {k: v for k, v in (("normalize", opts.normalize), ("asset_meta", opts.asset_meta),
                                   ("units", opts.dataset == "bop" and opts.units)) if v}
        flows = [()] * len(views)
        if opts.flow:  # each view's neighbours in order: their cameras make its flow
            flows = [(views[i - 1] if i else None, views[i + 1] if i + 1 < len(views) else None)
                     for i in range(len(views))]
        views = [(view, flow, image_fingerprint(
                    fields, view.identity(), [f"*{x}" for x in suffixes], opts.ground,
                    {**extra, "flow": [v and v.identity() for v in flow]} if flow else extra))
                 for view, flow in zip(views, flows)]
        settings = shared[cache_key] = (fields, views, suffixes)
    fields, views, suffixes = settings
    tasks = []
    for view, flow, fingerprint in views:
        key = asset.name if len(views) == 1 else f"{asset.name}.{view.name}"
        tasks.append(ImageTask(key, view, tuple(f"{key}{x}" for x in suffixes), fingerprint, flow))
    return asset, fields, tasks


def _make_output_folder(outdir):
    try:
        os.makedirs(outdir, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise OutputError(f"{outdir}: cannot create the output folder: a file is in the way") from None
    except OSError as exc:
        raise OutputError(f"{outdir}: cannot create the output folder: {exc.strerror}") from None
    # os.access says yes to root for any folder; a real file proves the folder takes writes
    try:
        with tempfile.TemporaryFile(dir=outdir):
            pass
    except OSError as exc:
        raise OutputError(f"{outdir}: output folder is not writable: {exc.strerror}") from None


def _check_dask():
    try:
        import distributed  # noqa: F401
    except ImportError:
        from rtmesh.batch.dask_pool import DASK_MISSING

        raise InputError(DASK_MISSING) from None


def _memory_limit(requested, workers):
    """Bytes per local worker: as asked, 0 for no guard, else RAM / workers (>= 2 GiB)."""
    if requested is not None:
        return requested or None
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None
    # address space, not resident memory: libraries and thread stacks reserve more than
    # they use, so the guard is generous and stops only true runaways
    return max(2 * 2**30, total // max(1, workers))
