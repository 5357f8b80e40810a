"""The options of a batch: what ``rtmesh batch`` and :func:`rtmesh.batch_convert` accept, checked
before anything runs (one line naming the option, exit 2).
"""


from dataclasses import dataclass

from rtmesh.batch.bop import UNITS
from rtmesh.batch.datasets import DATASETS
from rtmesh.batch.flow import FLOW_FORMATS
from rtmesh.batch.inputs import InputError
from rtmesh.batch.movies import MOVIE_FORMATS, require_mp4
from rtmesh.batch.normalize import NORMALIZE_MODES
from rtmesh.batch.view_sets import MAX_VIEWS, is_view_set, parse_elevation, view_set
from rtmesh.batch.jobs import VIEWS
from rtmesh.rendering.settings import PASSES, RenderSettings

FORMATS = ("png", "exr", "jpg")


PROGRESS_MODES = ("bar", "jsonl", "none")


# address space a local worker needs to start (imports, thread stacks, the BLAS buffers)
MIN_MEMORY_LIMIT = 1 << 30
# the longest time limit of an asset: about 116 days (waits of longer overflow the clocks)
MAX_TIME_LIMIT = 1e7


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
    seed, max_depth, integrator, exposure, tonemap, dither
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
    annotations : bool
        Write COCO instance annotations: a fragment ``<image key>.coco.json`` per image
        and, at the end of each run, ``annotations.coco.json`` per output folder merging
        every finished image's (:mod:`rtmesh.batch.coco`).
    units : str
        ``m``, ``cm`` or ``mm``: the scene units, for ``--dataset bop``'s millimetres.
    flow : bool
        Optical flow between each asset's ordered views: ``flow_forward`` and
        ``flow_backward`` layers in each view's EXR (:mod:`rtmesh.batch.flow`); needs
        ``exr`` among the formats.
    flow_format : str
        ``exr`` (the layers alone) or ``flo`` (also Middlebury ``.flo`` files per view).
    asset_meta : bool
        Write ``<asset>.meta.json`` per asset a job loads: counts, bounds, materials,
        textures found and missing, load warnings (:mod:`rtmesh.batch.asset_meta`).
    dataset : str
        ``""``, ``nerfstudio``, ``colmap`` or ``bop``: write each finished asset's dataset files
        (:mod:`rtmesh.batch.datasets`); implies ``camera_json``.  ``nerfstudio`` takes
        ``ortho`` (``ORTHOPHOTO``), ``colmap`` does not.  ``bop``: the BOP scene layout
        (:mod:`rtmesh.batch.bop`), perspective views with PNG or JPEG images.  With ``nerfstudio``, the
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
    max_depth: int | None = None
    integrator: str | None = None
    exposure: float = 0.0
    tonemap: str = "reinhard"
    dither: bool = False
    ground: bool = False
    camera_json: bool = False
    normalize: str = ""
    ortho: bool = False
    dataset: str = ""
    asset_meta: bool = False
    annotations: bool = False
    units: str = "m"
    flow: bool = False
    flow_format: str = "exr"
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
            if self.movie == "mp4":
                require_mp4()  # before any job: one line naming the extra
        if self.dataset:
            check_names("dataset", (self.dataset,), DATASETS)
            if self.ortho and self.dataset in ("colmap", "bop"):
                raise InputError(f"dataset: {self.dataset} describes perspective cameras: leave out --ortho")
            if self.dataset == "bop" and not {"png", "jpg"} & set(self.formats):
                raise InputError("dataset: bop's rgb images are PNG or JPEG: add png to the formats")
        check_names("units", (self.units,), tuple(UNITS))
        if not self.views and not self.turntable:
            raise InputError("views: give at least one view (or a turntable)")
        if not self.formats:
            raise InputError("formats: give at least one output format")
        check_passes(self.passes, self.formats)
        check_names("flow format", (self.flow_format,), FLOW_FORMATS)
        if self.flow_format != "exr" and not self.flow:
            raise InputError(f"flow format: {self.flow_format} files hold the flow of --flow: add --flow")
        if self.flow and "exr" not in self.formats:
            raise InputError("flow: the flow passes are written to EXR files: add exr to the formats")
        for name in ("workers", "threads"):
            value = getattr(self, name)
            if value is not None and value < 1:
                raise InputError(f"{name}: must be >= 1, got {value}")
        if not 0 <= self.turntable <= MAX_VIEWS:
            raise InputError(f"turntable: must be from 0 to {MAX_VIEWS} frames, got {self.turntable}")
        if self.time_limit is not None and not 0 < self.time_limit <= MAX_TIME_LIMIT:
            # (NaN fails too; an unbounded wait overflows the clocks it is given to)
            raise InputError(f"time limit: must be > 0 and at most {MAX_TIME_LIMIT:g} seconds, got {self.time_limit}")
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
        fields = {**pick, "passes": tuple(overrides.get("passes", self.passes)),
                  "max_depth": self.max_depth, "exposure": self.exposure, "tonemap": self.tonemap,
                  "threads": self.threads}
        if self.dither is not False:
            # only when asked: the fingerprints of images written before the option stay theirs
            fields["dither"] = self.dither
        if self.integrator is not None:
            # unset, each asset takes its file's default (rtmesh.loaders.importers.default_integrator)
            fields["integrator"] = self.integrator
        return fields


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
