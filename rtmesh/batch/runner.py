"""Batch conversion: render whole asset collections, locally or on a Dask cluster.

>>> import rtmesh
>>> report = rtmesh.batch_convert(["models/"], "thumbs/", width=128, height=128)  # doctest: +SKIP
>>> report.counts  # doctest: +SKIP
{'assets': 50, 'done': 49, 'skipped': 0, 'failed': 1, 'images': 50}

The pieces, one job each:

- :mod:`rtmesh.batch.inputs` finds the assets (files, folders, manifests) and names them;
- this module plans one job per asset (its views and output files, minus those the ledger
  says are finished), runs them, and writes the report;
- :mod:`rtmesh.batch.worker` converts one asset inside a worker;
- :mod:`rtmesh.batch.pool` runs the jobs on local processes or a Dask cluster;
- :mod:`rtmesh.batch.ledger` remembers finished images so a re-run resumes.
"""

import dataclasses
import hashlib
import json
import os
import re
import sys
import tempfile
import time
from dataclasses import dataclass, field

from rtmesh import __version__
from rtmesh.batch.inputs import InputError, discover
from rtmesh.batch.ledger import Ledger
from rtmesh.batch.pool import run_dask, run_local
from rtmesh.batch.worker import VIEWS, AssetJob, ImageTask, fixed_view, turntable_views
from rtmesh.core.errors import OutputError
from rtmesh.loaders.importers import MESH_EXTENSIONS
from rtmesh.rendering.settings import PASSES, RenderSettings

FORMATS = ("png", "exr", "jpg")
REPORT_NAME = "rtmesh-batch-report.json"


@dataclass
class BatchOptions:
    """How to convert a batch; per-asset CSV columns override the render fields.

    Attributes
    ----------
    width, height, spp : int
        Image size and samples per pixel (a quick thumbnail by default).
    views : tuple of str
        Fixed views (``iso``, ``front``, ``back``, ``left``, ``right``, ``top``,
        ``bottom``), each auto-framed on the asset's bounding sphere.
    turntable : int
        If > 0, that many frames orbiting the asset instead of ``views``.
    formats : tuple of str
        ``png``, ``exr`` (linear float, with passes), ``jpg``; one render, written in each.
    passes : tuple of str
        Extra EXR channels (``ao``).
    seed, max_depth, exposure, tonemap
        As for ``rtmesh render``.
    ground : bool
        Put a grey ground plane under each asset, catching its shadow.
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
        out between the workers (at least 2 GiB each); 0 turns the guard off.
    force : bool
        Redo every image, ignoring the ledger.
    quiet : bool
        No progress bar (the summary is :meth:`BatchReport.summary`, printed by the command).
    """

    width: int = 256
    height: int = 256
    spp: int = 4
    views: tuple = ("iso",)
    turntable: int = 0
    formats: tuple = ("png",)
    passes: tuple = ()
    seed: int = 0
    max_depth: int = 5
    exposure: float = 0.0
    tonemap: str = "reinhard"
    ground: bool = False
    workers: int | None = None
    threads: int | None = None
    scheduler: object = None
    time_limit: float | None = 600.0
    memory_limit: int | None = None
    force: bool = False
    quiet: bool = False

    def validate(self):
        """Raise InputError naming the first bad option."""
        check_names("views", self.views, VIEWS)
        check_names("formats", self.formats, FORMATS)
        check_names("passes", self.passes, PASSES)
        if not self.views and not self.turntable:
            raise InputError("views: give at least one view (or a turntable)")
        if not self.formats:
            raise InputError("formats: give at least one output format")
        for name in ("workers", "threads"):
            value = getattr(self, name)
            if value is not None and value < 1:
                raise InputError(f"{name}: must be >= 1, got {value}")
        if self.turntable < 0:
            raise InputError(f"turntable: must be >= 0, got {self.turntable}")
        if self.time_limit is not None and self.time_limit <= 0:
            raise InputError(f"time limit: must be > 0 seconds, got {self.time_limit}")
        try:
            RenderSettings(**self.render_fields({})).validate()
        except ValueError as exc:
            raise InputError(str(exc)) from None
        return self

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


@dataclass
class BatchReport:
    """What a batch did; also written as JSON to ``OUTDIR/rtmesh-batch-report.json``.

    Attributes
    ----------
    counts : dict of str to int
        ``assets``, ``done``, ``skipped`` (finished by an earlier run), ``failed``, and
        ``images`` written by this run.
    assets : list of dict
        Per asset: ``asset``, ``path``, ``status``, ``seconds``, ``images``, ``errors``
        (``image``, ``stage``, ``message``).
    wall_seconds : float
    assets_per_minute : float
        Assets converted by this run per minute of wall time.
    path : str
        Where the JSON report was written.
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
        """Assets with at least one failed image."""
        return [a for a in self.assets if a["status"] == "failed"]

    def to_dict(self):
        return {"rtmesh_version": __version__, "counts": self.counts,
                "wall_seconds": round(self.wall_seconds, 3),
                "assets_per_minute": round(self.assets_per_minute, 2), "runner": self.runner,
                **self.extra, "assets": self.assets}

    def summary(self, max_lines=12):
        """A one-screen summary: counts, throughput, failures with reasons, slowest assets."""
        c = self.counts
        lines = [f"rtmesh batch: {c['assets']} assets: {c['done']} done, {c['skipped']} skipped, "
                 f"{c['failed']} failed; {c['images']} images in {self.wall_seconds:.1f} s "
                 f"({self.assets_per_minute:.1f} assets/min, {self.runner})"]
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
        ``OUTDIR/<relative path>.<ext>`` for one view, ``OUTDIR/<relative path>.<view>.<ext>``
        for several (``chairs/oak.obj.png``, ``chairs/oak.obj.turn007.png``).
    **options
        Fields of :class:`BatchOptions`.

    Returns
    -------
    BatchReport
        Failed assets are in the report; they do not raise.

    Raises
    ------
    RtmeshError
        Bad inputs or options, no asset found, an unwritable output folder, Dask missing or
        unreachable: raised before any job runs.
    """
    opts = BatchOptions(**options).validate()
    if isinstance(inputs, (str, os.PathLike)):
        inputs = [inputs]
    start = time.perf_counter()
    assets = discover(inputs)
    if not assets:
        raise InputError(f"no mesh files ({', '.join(MESH_EXTENSIONS)}) found in "
                         f"{', '.join(map(os.fspath, inputs)) or '(no inputs)'}")
    outdir = os.path.abspath(os.fspath(outdir))
    _make_output_folder(outdir)
    if opts.scheduler is not None:
        _check_dask()
    with Ledger(outdir) as ledger:
        _remove_stale_temporaries(outdir)
        jobs, records = plan(assets, outdir, opts, ledger)
        progress = BatchProgress(len(assets), len(assets) - len(jobs), enabled=not opts.quiet)

        def on_image(image):
            extra = {"stage": image["stage"], "message": image["message"]} if image["status"] == "failed" else {}
            ledger.record(image["key"], image["fingerprint"], image["status"], files=image["files"],
                          seconds=image["seconds"], **extra)

        def on_job(result):
            record = records[result["asset"]]
            record["seconds"] = result["seconds"]
            record["images"].extend(result["images"])
            progress.update(failed=any(i["status"] == "failed" for i in result["images"]))

        try:
            if opts.scheduler is not None:
                runner = "dask"
                run_dask(jobs, opts.scheduler, on_image, on_job, time_limit=opts.time_limit)
            else:
                workers = opts.workers or _cores()
                used = min(workers, max(1, len(jobs)))
                runner = f"{used} local worker{'s' if used > 1 else ''}"
                run_local(jobs, workers, on_image, on_job, time_limit=opts.time_limit,
                          memory_limit=_memory_limit(opts.memory_limit, workers))
        finally:
            progress.close()
    report = _report(records, time.perf_counter() - start, runner, outdir, opts)
    report.path = os.path.join(outdir, REPORT_NAME)
    _write_json_atomically(report.path, report.to_dict())
    return report


def plan(assets, outdir, opts, ledger):
    """One job per asset with the images the ledger does not have yet.

    Returns
    -------
    jobs : list of AssetJob
    records : dict of str to dict
        Per asset name, the report record to fill in (finished images already listed as
        skipped).
    """
    jobs, records, used = [], {}, set()
    local_threads = opts.threads or max(1, _cores() // (opts.workers or _cores()))
    for asset in assets:
        o = asset.overrides
        check_names("views", o.get("views", ()), VIEWS)
        check_names("formats", o.get("formats", ()), FORMATS)
        check_names("passes", o.get("passes", ()), PASSES)
        fields = opts.render_fields(o)
        fields["threads"] = opts.threads or (1 if opts.scheduler is not None else local_threads)
        frames = o.get("turntable", opts.turntable)
        views = turntable_views(frames) if frames else [fixed_view(v) for v in o.get("views", opts.views)]
        formats = o.get("formats", opts.formats)
        stem = _unique_stem(asset, used)
        source = _file_identity(asset.path)
        tasks, skipped = [], []
        for view in views:
            key = stem if len(views) == 1 else f"{stem}.{view.name}"
            files = tuple(f"{key}.{fmt}" for fmt in formats)
            # threads never change the image, so they are not part of the fingerprint
            identity = {"source": source, "settings": {**fields, "threads": None},
                        "view": dataclasses.asdict(view), "files": files, "ground": opts.ground}
            fingerprint = hashlib.sha1(json.dumps(identity, sort_keys=True).encode()).hexdigest()
            task = ImageTask(key, view, files, fingerprint)
            if not opts.force and ledger.is_done(key, fingerprint):
                skipped.append({"key": key, "status": "skipped", "files": list(files), "seconds": 0.0})
            else:
                tasks.append(task)
        records[asset.name] = {"asset": asset.name, "path": asset.path, "seconds": 0.0,
                               "images": skipped}
        if tasks:
            jobs.append(AssetJob(asset.name, asset.path, outdir, fields, tuple(tasks), opts.ground))
    return jobs, records


def _unique_stem(asset, used):
    """The asset's output stem; on a case-insensitive clash a short hash of its path keeps
    names apart (distinct paths already give distinct names on case-sensitive systems)."""
    stem = asset.name
    if stem.lower() in used:
        stem = f"{stem}-{hashlib.sha1(asset.path.encode()).hexdigest()[:8]}"
    used.add(stem.lower())
    return stem


def _file_identity(path):
    """What identifies an input's content cheaply: its path, size and modification time."""
    try:
        st = os.stat(path)
        return [path, st.st_size, st.st_mtime_ns]
    except OSError:
        return [path, None, None]


def _report(records, wall_seconds, runner, outdir, opts):
    assets, counts = [], {"assets": len(records), "done": 0, "skipped": 0, "failed": 0, "images": 0}
    for record in records.values():
        images = record["images"]
        errors = [{"image": i["key"], "stage": i["stage"], "message": i["message"]}
                  for i in images if i["status"] == "failed"]
        if errors:
            status = "failed"
        elif images and all(i["status"] == "skipped" for i in images):
            status = "skipped"
        else:
            status = "done"
        counts[status] += 1
        counts["images"] += sum(i["status"] == "done" for i in images)
        assets.append({**record, "status": status, "errors": errors})
    per_minute = 60.0 * counts["done"] / wall_seconds if wall_seconds > 0 else 0.0
    extra = {"outdir": outdir, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z",
                                                        time.localtime(time.time() - wall_seconds))}
    return BatchReport(counts, assets, wall_seconds, per_minute, runner, extra=extra)


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


def _remove_stale_temporaries(outdir):
    """Delete half-written images a killed run left (hidden ``.NAME.XXXX.tmp.EXT`` files).

    Only called while this batch holds the folder's lock, so no live writer owns them.
    """
    pattern = re.compile(r"^\..+\.tmp\.(png|exr|jpe?g)$", re.IGNORECASE)
    for here, dirs, files in os.walk(outdir):
        for name in files:
            if pattern.match(name):
                try:
                    os.unlink(os.path.join(here, name))
                except OSError:
                    pass  # harmless: it is hidden and never taken for an image


def _check_dask():
    try:
        import distributed  # noqa: F401
    except ImportError:
        from rtmesh.batch.pool import DASK_MISSING

        raise InputError(DASK_MISSING) from None


def _write_json_atomically(path, document):
    folder = os.path.dirname(path)
    fd, tmp = tempfile.mkstemp(prefix=".rtmesh-batch-report.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(document, f, indent=1)
            f.write("\n")
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

    def update(self, failed=False):
        self.done += 1
        self.failed += failed
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


def _duration(seconds):
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds}s"
    if seconds < 3600:
        return f"{seconds // 60}m{seconds % 60:02d}s"
    return f"{seconds // 3600}h{seconds // 60 % 60:02d}m"
