"""Batch conversion: render whole asset collections, locally or on a Dask cluster.

>>> import rtmesh
>>> report = rtmesh.batch_convert(["models/"], "thumbs/", width=128, height=128)  # doctest: +SKIP
>>> report.counts  # doctest: +SKIP
{'assets': 50, 'done': 49, 'skipped': 0, 'failed': 1, 'known_failed': 0, 'retried': 0,
 'not_attempted': 0, 'images': 50}

The pieces, one job each:

- :mod:`rtmesh.batch.inputs` finds the assets (files, folders, manifests) and names them;
- :mod:`rtmesh.batch.identity` says what an image depends on and whether it changed;
- this module plans one job per asset (its views and output files, minus those the ledger
  says are finished and unchanged), runs them, keeps the books and writes the report;
- :mod:`rtmesh.batch.worker` converts one asset inside a worker;
- :mod:`rtmesh.batch.pool` runs the jobs on local processes, :mod:`rtmesh.batch.dask_pool` on a
  Dask cluster;
- :mod:`rtmesh.batch.ledger` remembers finished and failed images so a re-run resumes.

Exit statuses of the ``rtmesh batch`` command (:attr:`BatchReport.exit_code`):
:data:`EXIT_DONE` (0) every asset done, :data:`EXIT_FAILED` (1) some assets failed in this
run, :data:`EXIT_USAGE` (2) bad invocation (nothing ran), :data:`EXIT_CLUSTER_LOST` (3)
the Dask cluster was lost (resume to continue).
"""

import dataclasses
import json
import os
import re
import sys
import tempfile
import time
import uuid
from dataclasses import dataclass, field

from rtmesh import __version__
from rtmesh.batch.identity import image_fingerprint, inputs_unchanged, unchanged
from rtmesh.batch.inputs import InputError, discover
from rtmesh.batch.ledger import FINGERPRINT, INPUTS, OUTPUTS, STATUS, Ledger, decode
from rtmesh.batch.contact_sheet import write_contact_sheets
from rtmesh.batch.datasets import DATASETS, dataset_suffixes, write_dataset
from rtmesh.batch.movies import MOVIE_FORMATS, movie_frames, write_movie
from rtmesh.batch.normalize import NORMALIZE_MODES
from rtmesh.batch.view_sets import is_view_set, parse_elevation, view_set
from rtmesh.batch.worker import CAMERA_SUFFIX, VIEWS, AssetJob, ImageTask, fixed_view, turntable_views
from rtmesh.core.errors import OutputError
from rtmesh.loaders.importers import MESH_EXTENSIONS
from rtmesh.rendering.settings import PASSES, RenderSettings

FORMATS = ("png", "exr", "jpg")
REPORT_NAME = "rtmesh-batch-report.jsonl"
SUMMARY_NAME = "rtmesh-batch-summary.json"
RUN_FILE = ".rtmesh-batch-run"
PROGRESS_MODES = ("bar", "jsonl", "none")
EXIT_DONE, EXIT_FAILED, EXIT_USAGE, EXIT_CLUSTER_LOST = 0, 1, 2, 3
# address space a local worker needs to start (imports, thread stacks, the BLAS buffers)
MIN_MEMORY_LIMIT = 1 << 30
_PLAN_CHUNK = 5000  # assets planned per ledger look-up


@dataclass
class BatchOptions:
    """How to convert a batch; per-asset CSV columns override the render fields.

    Attributes
    ----------
    width, height, spp : int
        Image size and samples per pixel (a quick thumbnail by default).
    views : tuple of str
        Fixed views (``iso``, ``front``, ``back``, ``left``, ``right``, ``top``,
        ``bottom``), each auto-framed on the asset's bounding sphere; or one view set
        (``("fibonacci:N",)``, ``random:N``, ``rings:E1,E2,...xK``, see
        :mod:`rtmesh.batch.view_sets`).
    elevation : (2,) float
        Band of elevations, degrees, of ``random:N`` views.
    radius_jitter : float
        View sets: each camera's distance times a factor uniform in [1, 1 + J] (seeded).
    turntable : int
        If > 0, that many frames orbiting the asset instead of ``views``.
    formats : tuple of str
        ``png``, ``exr`` (linear float, with passes), ``jpg``; one render, written in each.
    passes : tuple of str
        Extra EXR channels (``ao``); they need ``exr`` among the formats.
    seed, max_depth, exposure, tonemap
        As for ``rtmesh render``.
    ground : bool
        Put a grey ground plane under each asset, catching its shadow (left out of views
        from below, where it would hide the asset).
    camera_json : bool
        Write each image's camera (intrinsics, poses in the OpenCV and OpenGL conventions,
        near/far, the normalisation applied) next to it as ``<image key>.camera.json``
        (:mod:`rtmesh.scene.camera_json`).
    normalize : str
        ``""`` (the asset as it is), ``unit-cube`` or ``unit-sphere``: centre and scale
        each asset first (:mod:`rtmesh.batch.normalize`).
    ortho : bool
        Orthographic cameras for the fixed views (front, top, side CAD views) instead of
        perspective ones.
    contact_sheet : bool
        Write ``rtmesh-contact-sheet.png`` per output folder: every finished image's
        thumbnail with its name (:mod:`rtmesh.batch.contact_sheet`).
    movie : str
        ``""``, ``webp`` or ``gif``: with ``turntable``, assemble each asset's frames into
        ``<asset>.turntable.webp|gif`` (:mod:`rtmesh.batch.movies`); needs png or jpg
        among the formats.
    asset_meta : bool
        Write ``<asset>.meta.json`` per asset a job loads: counts, bounds, materials,
        textures found and missing, load warnings (:mod:`rtmesh.batch.asset_meta`).
    dataset : str
        ``""``, ``nerfstudio`` or ``colmap``: write each finished asset's dataset files
        (:mod:`rtmesh.batch.datasets`); implies ``camera_json``.  With ``nerfstudio``, the
        ``depth`` and ``alpha`` passes also give depth and mask PNGs per image.
    workers : int or None
        Local worker processes; None uses every core.  Ignored with ``scheduler``.
    threads : int or None
        Render threads per job; None gives cores / workers locally and 1 on Dask (whose
        workers already run one task per thread).
    scheduler : str, distributed.Client or None
        A dask.distributed scheduler address (``tcp://host:8786``) or client.
    time_limit : float or None
        Seconds one asset may take (None: no limit).
    memory_limit : int or None
        Bytes of address space per local worker; None gives the machine's memory shared
        out between the workers (at least 2 GiB each); 0 turns the guard off.  A limit
        below :data:`MIN_MEMORY_LIMIT` is refused.
    force : bool
        Redo every image, ignoring the ledger.
    trust_mtime : bool
        Compare input files and finished images by size and modification time instead of
        by content (faster: reads no file to resume).
    retry_failed : bool
        True (default): assets that failed in an earlier run with the same inputs are tried
        again, once per run.  False: they are left as known failures.
    progress : str
        ``bar`` (a progress bar or log line on stderr), ``jsonl`` (one JSON line per
        finished asset) or ``none``.
    progress_file : str or None
        Where ``jsonl`` progress goes (default stderr).
    quiet : bool
        Same as ``progress="none"`` (kept for the ``-q`` flag).
    """

    width: int = 256
    height: int = 256
    spp: int = 4
    views: tuple = ("iso",)
    elevation: tuple = (-90.0, 90.0)
    radius_jitter: float = 0.0
    turntable: int = 0
    formats: tuple = ("png",)
    passes: tuple = ()
    seed: int = 0
    max_depth: int = 5
    exposure: float = 0.0
    tonemap: str = "reinhard"
    ground: bool = False
    camera_json: bool = False
    normalize: str = ""
    ortho: bool = False
    dataset: str = ""
    asset_meta: bool = False
    movie: str = ""
    contact_sheet: bool = False
    workers: int | None = None
    threads: int | None = None
    scheduler: object = None
    time_limit: float | None = 600.0
    memory_limit: int | None = None
    force: bool = False
    trust_mtime: bool = False
    retry_failed: bool = True
    progress: str = "bar"
    progress_file: str | None = None
    quiet: bool = False

    def validate(self):
        """Raise InputError naming the first bad option."""
        if self.view_set:
            try:
                parse_elevation(",".join(map(str, self.elevation)))
                view_set(self.view_set, 0, self.elevation, self.radius_jitter)
            except ValueError as exc:
                raise InputError(str(exc)) from None
        else:
            check_names("views", self.views, VIEWS)
        check_names("formats", self.formats, FORMATS)
        check_names("passes", self.passes, PASSES)
        check_names("progress", (self.progress,), PROGRESS_MODES)
        if self.normalize:
            check_names("normalize", (self.normalize,), NORMALIZE_MODES)
        if self.movie:
            check_names("movie", (self.movie,), MOVIE_FORMATS)
            if not self.turntable:
                raise InputError("movie: a movie is made of turntable frames: add --turntable N")
            if not {"png", "jpg"} & set(self.formats):
                raise InputError("movie: the frames are read from PNG or JPEG images: add png to the formats")
        if self.dataset:
            check_names("dataset", (self.dataset,), DATASETS)
            if self.ortho:
                raise InputError(f"dataset: {self.dataset} describes perspective cameras: leave out --ortho")
        if not self.views and not self.turntable:
            raise InputError("views: give at least one view (or a turntable)")
        if not self.formats:
            raise InputError("formats: give at least one output format")
        check_passes(self.passes, self.formats)
        for name in ("workers", "threads"):
            value = getattr(self, name)
            if value is not None and value < 1:
                raise InputError(f"{name}: must be >= 1, got {value}")
        if self.turntable < 0:
            raise InputError(f"turntable: must be >= 0, got {self.turntable}")
        if self.time_limit is not None and self.time_limit <= 0:
            raise InputError(f"time limit: must be > 0 seconds, got {self.time_limit}")
        if self.memory_limit and self.memory_limit < MIN_MEMORY_LIMIT:
            raise InputError(f"memory limit: {self.memory_limit / 2**20:.0f} MiB is below the "
                             f"{MIN_MEMORY_LIMIT / 2**30:.0f} GiB a worker process needs to start")
        try:
            RenderSettings(**self.render_fields({})).validate()
        except ValueError as exc:
            raise InputError(str(exc)) from None
        return self

    @property
    def view_set(self):
        """The view set spec given in ``views`` (``""`` for fixed views)."""
        return self.views[0] if len(self.views) == 1 and is_view_set(self.views[0]) else ""

    def render_fields(self, overrides):
        """RenderSettings fields for one asset (``overrides`` from its CSV row)."""
        pick = {k: overrides.get(k, getattr(self, k)) for k in ("width", "height", "spp", "seed")}
        return {**pick, "passes": tuple(overrides.get("passes", self.passes)),
                "max_depth": self.max_depth, "exposure": self.exposure, "tonemap": self.tonemap,
                "threads": self.threads}


def check_names(what, names, allowed):
    """Raise InputError if a name is not among ``allowed``."""
    for name in names:
        if name not in allowed:
            raise InputError(f"{what}: unknown {name!r} (expected {', '.join(allowed)})")


def check_passes(passes, formats, where=""):
    """Raise InputError for passes asked without an EXR output (only EXR holds them)."""
    if passes and "exr" not in formats:
        raise InputError(f"{where}passes: {', '.join(passes)} are written only to EXR files: "
                         f"add exr to the formats")


@dataclass
class BatchReport:
    """What a batch did.

    Also written to the output folder: ``rtmesh-batch-summary.json`` (this object without
    the per-asset list) and ``rtmesh-batch-report.jsonl`` (one JSON line per asset this run
    attempted or left as a known failure; assets finished by earlier runs are counted only).

    Attributes
    ----------
    counts : dict of str to int
        ``assets``; each one is ``done`` (by this run), ``skipped`` (finished by an earlier
        run, unchanged), ``failed`` (in this run), ``known_failed`` (failed in an earlier run
        with the same inputs and not retried: ``retry_failed=False``) or ``not_attempted``
        (the cluster was lost first).  ``retried``: assets that had failed before and were
        tried again by this run (whatever the outcome); ``images``: images written.
    assets : list of dict
        Per attempted or known-failed asset: ``asset``, ``path``, ``status``, ``seconds``,
        ``images``, ``errors`` (``image``, ``stage``, ``message``), ``retried``.
    wall_seconds : float
    assets_per_minute : float
        Assets converted by this run per minute of wall time.
    runner : str
    path : str
        Where the summary JSON was written.
    """

    counts: dict
    assets: list
    wall_seconds: float
    assets_per_minute: float
    runner: str
    path: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def failed(self):
        """Assets that failed in this run."""
        return [a for a in self.assets if a["status"] == "failed"]

    @property
    def exit_code(self):
        """:data:`EXIT_CLUSTER_LOST`, :data:`EXIT_FAILED` or :data:`EXIT_DONE`."""
        if self.counts["not_attempted"]:
            return EXIT_CLUSTER_LOST
        return EXIT_FAILED if self.counts["failed"] else EXIT_DONE

    def to_dict(self):
        """The summary document (without the per-asset list)."""
        return {"rtmesh_version": __version__, "counts": self.counts,
                "wall_seconds": round(self.wall_seconds, 3),
                "assets_per_minute": round(self.assets_per_minute, 2), "runner": self.runner,
                "exit_code": self.exit_code, **self.extra}

    def summary(self, max_lines=12):
        """A one-screen summary: counts, throughput, failures with reasons, slowest assets."""
        c = self.counts
        known = f", {c['known_failed']} known failures not retried" if c["known_failed"] else ""
        retried = f" ({c['retried']} retried)" if c["retried"] else ""
        lost = f", {c['not_attempted']} not attempted" if c["not_attempted"] else ""
        lines = [f"rtmesh batch: {c['assets']} assets: {c['done']} done, {c['skipped']} skipped, "
                 f"{c['failed']} failed{retried}{known}{lost}; {c['images']} images in "
                 f"{self.wall_seconds:.1f} s ({self.assets_per_minute:.1f} assets/min, {self.runner})"]
        failed = self.failed
        if failed:
            lines.append("failed:")
            for a in failed[:max_lines]:
                e = a["errors"][0]
                more = f" (+{len(a['errors']) - 1} more)" if len(a["errors"]) > 1 else ""
                lines.append(f"  {a['asset']}: {e['stage']}: {e['message']}{more}")
            if len(failed) > max_lines:
                lines.append(f"  ... and {len(failed) - max_lines} more (see the report)")
        timed = sorted((a for a in self.assets if a["seconds"] > 0),
                       key=lambda a: -a["seconds"])[:3]
        if timed:
            lines.append("slowest: " + ", ".join(f"{a['asset']} {a['seconds']:.2f} s" for a in timed))
        if self.path:
            lines.append(f"report: {self.path}")
        return "\n".join(lines)


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
    assets = discover(inputs)
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
        _remove_stale_temporaries(outdir)
        # the run that owns the folder now: tasks of an earlier run stop before writing
        _write_atomically(os.path.join(outdir, RUN_FILE), run + "\n")
        book = Books(ledger, outdir, opts, len(assets), progress_stream)
        try:
            jobs = plan(assets, outdir, opts, ledger, book, run)
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

                workers = opts.workers or _cores()
                used = min(workers, len(jobs))
                runner = f"{used} local worker{'s' if used > 1 else ''}"
                run_local(jobs, workers, book.on_image, book.on_job, time_limit=opts.time_limit,
                          memory_limit=_memory_limit(opts.memory_limit, workers))
        finally:
            book.close()
        if opts.contact_sheet:
            write_contact_sheets(outdir, book.sheet)
    report = book.report(time.perf_counter() - start, runner, run)
    report.path = os.path.join(outdir, SUMMARY_NAME)
    _write_atomically(report.path, json.dumps(report.to_dict(), indent=1) + "\n")
    return report


def _check_overrides(asset, opts):
    o = asset.overrides
    where = f"{asset.path}: "
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


def plan(assets, outdir, opts, ledger, book, run=""):
    """One job per asset with the images that are not finished and unchanged.

    An image is skipped when the ledger has it ``done`` with the same fingerprint, its
    inputs are unchanged and its files are there with the recorded size and checksum
    (size and time with ``trust_mtime``).  An image that failed before with the same
    fingerprint and inputs is a known failure: tried again with ``retry_failed``, else left.

    Returns
    -------
    list of AssetJob
        Skipped assets and known failures are entered in ``book`` directly.
    """
    jobs = []
    local_threads = opts.threads or max(1, _cores() // (opts.workers or _cores()))
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
                    if all(unchanged(o, os.path.join(outdir, o[0]), opts.trust_mtime)
                           for o in decode(entry[OUTPUTS])):
                        skipped.append(task)
                    else:
                        todo.append(task)
                elif opts.retry_failed:
                    todo.append(task)
                    retried = True
                else:
                    known.append(task)
            book.planned(asset, skipped, known, retried if todo else False, bool(todo))
            if todo:
                jobs.append(AssetJob(asset.name, asset.path, outdir, {**fields, "threads": threads},
                                     tuple(todo), opts.ground, run, run_file, opts.normalize,
                                     opts.asset_meta))
    return jobs


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
        suffixes += [CAMERA_SUFFIX] * (opts.camera_json and not extras) + extras
        # (a metadata file is written by the job that loads the asset: asking for it redoes them)
        extra = {k: v for k, v in (("normalize", opts.normalize), ("asset_meta", opts.asset_meta)) if v}
        views = [(view, image_fingerprint(fields, view.identity(), [f"*{x}" for x in suffixes], opts.ground,
                                          extra))
                 for view in views]
        settings = shared[cache_key] = (fields, views, suffixes)
    fields, views, suffixes = settings
    tasks = []
    for view, fingerprint in views:
        key = asset.name if len(views) == 1 else f"{asset.name}.{view.name}"
        tasks.append(ImageTask(key, view, tuple(f"{key}{x}" for x in suffixes), fingerprint))
    return asset, fields, tasks


class Books:
    """The batch's bookkeeping, in the submitting process: ledger rows, the JSON-lines
    report, counts and progress, one asset at a time.

    Parameters
    ----------
    ledger : Ledger
    outdir : str
    opts : BatchOptions
    total : int
        Assets in the batch.
    progress_file : file, optional
        Where ``jsonl`` progress goes (default stderr); closed with the books.
    """

    def __init__(self, ledger, outdir, opts, total, progress_file=None):
        self.ledger, self.outdir, self.opts, self.total = ledger, outdir, opts, total
        self.progress_file = progress_file
        self.counts = {"assets": total, "done": 0, "skipped": 0, "failed": 0, "known_failed": 0,
                       "retried": 0, "not_attempted": 0, "images": 0}
        self.assets, self.pending, self.finished_jobs = [], {}, 0
        self.sheet = []  # (key, files) of every finished image, for --contact-sheet
        self.check_content = opts.scheduler is not None
        self._report = open(os.path.join(outdir, REPORT_NAME), "w", encoding="utf-8")
        self.progress = None

    def planned(self, asset, skipped, known, retried, has_job):
        """Enter an asset as planned: its skipped images, known failures, and whether a job
        will run for it."""
        if self.opts.contact_sheet:
            self.sheet.extend((t.key, list(t.files)) for t in skipped)
        record = {"asset": asset.name, "path": asset.path, "status": None, "seconds": 0.0,
                  "retried": retried,
                  "images": [{"key": t.key, "status": "skipped", "files": list(t.files)}
                             for t in skipped]}
        for task in known:
            attempts, stage, message = self.ledger.failure(task.key)
            record["images"].append({"key": task.key, "status": "known-failed",
                                     "files": list(task.files), "stage": stage,
                                     "message": message, "attempts": attempts})
        self.counts["retried"] += bool(retried)
        if has_job:
            self.pending[asset.name] = record
        elif known:
            self._finish(record, "known_failed")
        else:
            self.counts["skipped"] += 1
            self._write_asset_files(record)

    def start_progress(self):
        done = self.counts["skipped"] + self.counts["known_failed"]
        mode = "none" if self.opts.quiet else self.opts.progress
        if mode == "jsonl":
            self.progress = JsonProgress(self.total, done, self.progress_file or sys.stderr)
        else:
            self.progress = BatchProgress(self.total, done, enabled=mode == "bar")

    def on_image(self, image):
        """Record one image's result (called as each image finishes or fails)."""
        record = self.pending.get(image.get("asset")) if "asset" in image else None
        if image["status"] == "done":
            problem = self._not_visible(image)
            if problem:
                image = {**image, "status": "failed", "stage": "storage", "outputs": [],
                         "message": f"output not visible to the submitting machine: {problem}"}
        self.ledger.record(image["key"], image.get("asset", ""), image["fingerprint"],
                           image["status"], inputs=image.get("inputs", ()),
                           outputs=image.get("outputs", ()), seconds=image["seconds"],
                           run=image.get("run", ""), stage=image.get("stage"),
                           message=image.get("message"))
        if self.opts.contact_sheet and image["status"] == "done":
            self.sheet.append((image["key"], image["files"]))
        if record is not None:
            record["images"].append({k: image[k] for k in ("key", "status", "files", "seconds",
                                                          "stage", "message") if k in image})

    def _not_visible(self, image):
        """Why the image's files do not match what the worker reported, or ""."""
        outputs = image.get("outputs") or []
        for entry in outputs:
            path = os.path.join(self.outdir, entry[0])
            try:
                size = os.stat(path).st_size
            except OSError:
                return f"{entry[0]} is missing"
            if size != entry[1]:
                return f"{entry[0]} has {size} bytes, the worker wrote {entry[1]}"
            if self.check_content and not unchanged(entry, path):
                return f"{entry[0]} differs from what the worker wrote"
            # record this machine's view of the file (its time, for --trust-mtime resumes)
            entry[2] = os.stat(path).st_mtime_ns
        if len(outputs) != len(image["files"]):
            return "the worker reported no file"
        return ""

    def on_job(self, result):
        """Close one asset (after its images): count it, commit, report, show progress."""
        record = self.pending.pop(result["asset"], None)
        if record is None:
            return
        self.finished_jobs += 1
        record["seconds"] = result["seconds"]
        failed = any(i["status"] == "failed" for i in record["images"])
        self.counts["images"] += sum(i["status"] == "done" for i in record["images"])
        self._finish(record, "failed" if failed else "done")

    def _write_asset_files(self, record):
        """The asset's dataset files and turntable movie, once all its images are there
        (done or skipped)."""
        images = record["images"]
        if not images or any(i["status"] not in ("done", "skipped") for i in images):
            return
        if self.opts.dataset:
            # by image key: the views of a set and the frames of a turntable in order
            write_dataset(self.opts.dataset, self.outdir, record["asset"], sorted(images, key=lambda i: i["key"]))
        frames = movie_frames(self.outdir, images)
        if self.opts.movie and len(frames) > 1 and all(".turn" in i["key"] for i in images):
            write_movie(os.path.join(self.outdir, f"{record['asset']}.turntable.{self.opts.movie}"), frames,
                        self.opts.movie)

    def _finish(self, record, status):
        record["status"] = status.replace("_", "-")
        record["errors"] = [{"image": i["key"], "stage": i.get("stage"), "message": i.get("message")}
                            for i in record["images"] if i["status"] in ("failed", "known-failed")]
        self.counts[status] += 1
        if status == "done":
            self._write_asset_files(record)
        self.ledger.commit()
        self.assets.append(record)
        self._report.write(json.dumps(record, separators=(",", ":")) + "\n")
        self._report.flush()
        if self.progress is not None:
            self.progress.update(record)

    def close(self):
        if self.progress is not None:
            self.progress.close()
        if self.progress_file is not None:
            self.progress_file.close()
        self._report.close()

    def report(self, wall_seconds, runner, run):
        per_minute = 60.0 * self.counts["done"] / wall_seconds if wall_seconds > 0 else 0.0
        extra = {"outdir": self.outdir, "run": run, "report": os.path.join(self.outdir, REPORT_NAME),
                 "started": time.strftime("%Y-%m-%dT%H:%M:%S%z",
                                          time.localtime(time.time() - wall_seconds))}
        return BatchReport(dict(self.counts), self.assets, wall_seconds, per_minute, runner,
                           extra=extra)


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


# half-written images (".NAME.XXXX.tmp.EXT") and camera files (".NAME.json.XXXX.tmp"), and
# the temporary files of the summary, the run file, storage probes and rtmesh 0.1's ledger
# compaction
_STALE = re.compile(r"^\.(.+\.tmp\.(png|exr|jpe?g)|.+\.(json|txt|webp|gif|png)\.[^.]+\.tmp|rtmesh-batch-.+\.tmp)$",
                    re.IGNORECASE)


def _remove_stale_temporaries(outdir):
    """Delete the temporary files a killed run left.

    Only called while this batch holds the folder's lock, so no live writer of this
    machine owns them (Dask tasks of a killed run stop before writing, see RUN_FILE).
    """
    for here, dirs, files in os.walk(outdir):
        for name in files:
            if _STALE.match(name):
                try:
                    os.unlink(os.path.join(here, name))
                except OSError:
                    pass  # harmless: it is hidden and never taken for an image


def _check_dask():
    try:
        import distributed  # noqa: F401
    except ImportError:
        from rtmesh.batch.dask_pool import DASK_MISSING

        raise InputError(DASK_MISSING) from None


def _write_atomically(path, text):
    """Write a small text file whole or not at all, with the usual permissions (umask)."""
    folder, name = os.path.split(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{name.lstrip('.')}.", suffix=".tmp", dir=folder)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)  # mkstemp makes 0600 files
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _cores():
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


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


class BatchProgress:
    """Assets done / total with an ETA, on stderr: a bar on a terminal, a line every few
    seconds in a log."""

    def __init__(self, total, skipped, enabled=True, stream=None, log_every=10.0):
        self.stream = stream or sys.stderr
        self.enabled = enabled and total > skipped
        self.tty = self.stream.isatty()
        self.total, self.done, self.failed, self.skipped = total, skipped, 0, skipped
        self.start = time.perf_counter()
        self.log_every, self.last_log = log_every, self.start
        self.shown = False

    def update(self, record):
        self.done += 1
        self.failed += record["status"] == "failed"
        if not self.enabled:
            return
        now = time.perf_counter()
        if not self.tty and now - self.last_log < self.log_every and self.done < self.total:
            return
        self.last_log = now
        elapsed = now - self.start
        ran = self.done - self.skipped
        eta = elapsed / ran * (self.total - self.done) if ran else 0.0
        width = 30
        filled = int(width * self.done / self.total)
        failed = f", {self.failed} failed" if self.failed else ""
        text = (f"[{'#' * filled}{'.' * (width - filled)}] {self.done}/{self.total} assets{failed}, "
                f"{_duration(elapsed)} elapsed, {_duration(eta)} left")
        if self.tty:
            self.stream.write("\r" + text + "\033[K")
            self.shown = True
        else:
            self.stream.write("rtmesh batch: " + text + "\n")
        self.stream.flush()

    def close(self):
        if self.shown:
            self.stream.write("\n")
            self.stream.flush()


class JsonProgress:
    """Machine-readable progress: one JSON line per finished asset (``--progress jsonl``).

    Each line: ``time`` (Unix seconds), ``asset``, ``status``, ``seconds``, ``images``
    (written), ``errors``, ``finished`` and ``total`` assets.  Written to ``stream``,
    flushed line by line for cluster logs.
    """

    def __init__(self, total, finished, stream):
        self.total, self.finished, self.stream = total, finished, stream

    def update(self, record):
        self.finished += 1
        line = {"time": round(time.time(), 3), "asset": record["asset"], "status": record["status"],
                "seconds": record["seconds"],
                "images": sum(i["status"] == "done" for i in record["images"]),
                "errors": record["errors"], "finished": self.finished, "total": self.total}
        self.stream.write(json.dumps(line, separators=(",", ":")) + "\n")
        self.stream.flush()

    def close(self):
        pass


def _duration(seconds):
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds}s"
    if seconds < 3600:
        return f"{seconds // 60}m{seconds % 60:02d}s"
    return f"{seconds // 3600}h{seconds // 60 % 60:02d}m"
