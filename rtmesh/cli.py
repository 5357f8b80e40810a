"""Command line: ``rtmesh render`` and ``rtmesh batch``."""

import argparse
import contextlib
import importlib
import logging
import math
import os
import sys
import time
import traceback

from rtmesh import __version__
from rtmesh.api import load_scene
from rtmesh.batch.coco import annotate_render
from rtmesh.core import compile_ahead, runtime
from rtmesh.core.errors import OutputError, RtmeshError
from rtmesh.io.colour import TONEMAPS
from rtmesh.io.images import check_output_path, write_display_image
from rtmesh.io.passes import display_values
from rtmesh.rendering import memory
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import CAUSTICS, FRESNEL_MODES, INTEGRATORS, LIGHT_SAMPLERS, PASSES
from rtmesh.sampling.patterns import SAMPLERS
from rtmesh.scene.background import background_from_option
from rtmesh.scene.camera_json import camera_record, write_camera_json

# exit statuses (docs/LIMITS.md): a user error (bad file, bad setting, not enough memory for
# what was asked), an internal error (a bug: EX_SOFTWARE of sysexits.h), an interruption
EXIT_USER_ERROR = 2
EXIT_INTERNAL_ERROR = 70
EXIT_INTERRUPTED = 130
# set to 1 for the traceback of an internal error (as --debug does)
DEBUG_VARIABLE = "RTMESH_DEBUG"


class _Parser(argparse.ArgumentParser):
    """argparse with rtmesh's one-line errors: the message and where to find the usage,
    instead of argparse's usage block (exit status 2 as argparse's)."""

    def error(self, message):
        self.exit(EXIT_USER_ERROR, f"rtmesh: error: {message} (see {self.prog} --help)\n")


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {value}")
    return value


def build_parser():
    parser = _Parser(prog="rtmesh", description="Ray trace triangle-mesh scenes.")
    parser.add_argument("--version", action="version", version=f"rtmesh {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help=f"show the traceback of an internal error (or set {DEBUG_VARIABLE}=1)")
    commands = parser.add_subparsers(dest="command", required=True)

    p = commands.add_parser("render", help="render a scene file or a mesh file to an image",
                            description="Render a .toml scene file or a mesh file (OBJ, glTF/GLB, "
                            "PLY, STL, OFF, USD; framed automatically and lit by a default light rig "
                            "unless the file has its own camera and lights).")
    p.add_argument("input", help="scene file (.toml) or mesh file")
    p.add_argument("-o", "--output", required=True,
                   help="output image: .exr (linear float, with passes) or .png/.jpg (8-bit sRGB)")
    p.add_argument("--width", type=_positive_int, help="image width in pixels")
    p.add_argument("--height", type=_positive_int, help="image height in pixels")
    p.add_argument("--spp", type=_positive_int, help="samples per pixel")
    p.add_argument("--sampler", choices=SAMPLERS,
                   help="sample pattern of every sampled dimension (default jittered; zsobol: blue-noise error)")
    p.add_argument("--target-error", type=_positive_float, metavar="E",
                   help="adaptive sampling: add samples in rounds until every pixel's estimated "
                   "error, standard error / sqrt(mean + 0.01), is <= E (e.g. 0.01); --spp is the "
                   "first round's")
    p.add_argument("--time-limit", type=_positive_float, metavar="SECONDS",
                   help="adaptive sampling: start no round that would end after this many seconds")
    p.add_argument("--max-spp", type=_positive_int, metavar="N",
                   help="adaptive sampling: at most N samples in any pixel (default 1024)")
    p.add_argument("--integrator", choices=INTEGRATORS,
                   help="light transport: whitted (Blinn-Phong, lights, mirrors and glass) or path (physically "
                   "based path tracing with global illumination); default: path for glTF/GLB files, the scene "
                   "file's [render] integrator (whitted when silent), whitted for other mesh files")
    p.add_argument("--max-depth", type=int,
                   help="whitted: reflection/refraction bounces (default 5); path: segments after the "
                   "camera ray, 1 = direct light only, -1 = unlimited (the default)")
    p.add_argument("--clamp", type=float, metavar="L",
                   help="path: largest value a contribution after the first bounce may add (0 = off)")
    p.add_argument("--caustics", choices=CAUSTICS,
                   help="path: photon passes for caustics; auto (the default) when a small or delta light can "
                   "reach a mirror or smooth glass")
    p.add_argument("--light-sampler", choices=LIGHT_SAMPLERS,
                   help="path: choose the light of each light sample by its power (the default) or by its "
                   "importance at the shading point (a light tree: many or nearby emitters)")
    p.add_argument("--photons", type=_positive_int, help="path: photons a caustic photon pass traces "
                   "(default: a quarter of the pixel count, 16384 to 1048576)")
    p.add_argument("--seed", type=int, help="random seed (same seed, same image)")
    p.add_argument("--threads", type=_positive_int, help="worker threads (default: all cores)")
    p.add_argument("--ao-samples", type=int, help="ambient-occlusion rays per hit (0 = off)")
    p.add_argument("--ao-distance", type=float, help="ambient-occlusion reach, scene units")
    p.add_argument("--light-samples", type=_positive_int,
                   help="whitted: shadow rays per hit and area light (soft shadows; default 4); path: "
                   "light samples at a path's first vertex (default 1)")
    p.add_argument("--passes", type=_names(PASSES),
                   help="extra outputs (EXR layers), comma-separated: " + ", ".join(PASSES))
    p.add_argument("--background", metavar="BG",
                   help="what misses see, overriding the scene's: transparent (RGBA output), a "
                   "linear colour (g or r,g,b), or an equirectangular .exr/.hdr environment image")
    p.add_argument("--pass-png", action="store_true",
                   help="also write each pass as OUTPUT_<pass>.png (normals as 0.5 + 0.5 n, depth "
                   "normalised, ids as distinct colours)")
    p.add_argument("--fresnel", choices=FRESNEL_MODES, help="Fresnel model for dielectrics")
    p.add_argument("--exposure", type=float, help="exposure in stops for 8-bit output")
    p.add_argument("--tonemap", choices=TONEMAPS, help="tone-mapping operator for 8-bit output")
    p.add_argument("--dither", action=argparse.BooleanOptionalAction,
                   help="blue-noise dithering when quantising to 8-bit PNG/JPEG (no bands in smooth "
                   "gradients; default: a scene file's [render] dither, else round to nearest)")
    p.add_argument("--memory-limit", type=_bytes, metavar="SIZE",
                   help="refuse a render whose estimated memory exceeds SIZE, e.g. 4G; 0 = no check "
                   "(default: the memory available)")
    p.add_argument("--camera-json", metavar="PATH",
                   help="also write the camera (intrinsics K, poses in OpenCV and OpenGL conventions) as JSON")
    p.add_argument("--denoise", action="store_true", default=None,
                   help="denoise with Intel Open Image Denoise (needs rtmesh[denoise])")
    p.add_argument("--annotations", metavar="PATH",
                   help="also write COCO instance annotations (masks, boxes, amodal boxes, visible "
                   "fractions, poses) as JSON (docs/DATASETS.md)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    _add_debug_flag(p)
    _add_batch_parser(commands)
    p = commands.add_parser(
        "compile", help="compile the renderer's kernels for this machine now",
        description="Compile every kernel of the renderer for this machine into numba's disk cache "
        "(next to the package, or NUMBA_CACHE_DIR), as the first render after an install does: "
        "for a container image's build step or a cluster node's setup, so that the first render "
        "starts at once. Compiles nothing that is cached already.")
    _add_debug_flag(p)
    return parser


def _names(allowed):
    """argparse type for a comma-separated list of names among ``allowed``."""
    def parse(text):
        names = tuple(n.strip() for n in text.split(",") if n.strip())
        for name in names:
            if name not in allowed:
                raise argparse.ArgumentTypeError(f"unknown {name!r} (available: {', '.join(allowed)})")
        return names
    return parse


def _positive_float(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text}")
    return value


def _non_negative_float(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text}")
    return value


def _views_option(names):
    """argparse type for ``--views``: fixed view names, or one view set (``fibonacci:N``...)
    checked whole here, so a bad spec stops the command before anything is written."""
    def parse(text):
        from rtmesh.batch.view_sets import is_view_set, view_set

        if not is_view_set(text.strip()):
            return names(text)
        try:
            view_set(text.strip())
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix("views: ")) from None
        return (text.strip(),)
    return parse


def _elevation(text):
    from rtmesh.batch.view_sets import parse_elevation

    try:
        return parse_elevation(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("elevation: ")) from None


def _bytes(text):
    """A memory size: ``4G``, ``512M``, ``2.5GiB``, a plain number of bytes, or 0 (off)."""
    units = {"": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}
    t = text.strip().upper().removesuffix("IB").removesuffix("B")
    unit = t[-1:] if t[-1:] in units else ""
    try:
        value = float(t[:-1] if unit else t)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a size like 4G or 512M, got {text!r}") from None
    size = value * units[unit]
    # (0 turns the check off; a fraction of a byte would too, by rounding down)
    if not (math.isfinite(size) and (size == 0 or 1 <= size < 2**63)):
        raise argparse.ArgumentTypeError(f"expected 0 or a size from 1 byte to 8 EiB, got {text!r}")
    return int(size)


def _add_batch_parser(commands):
    from rtmesh.batch.normalize import NORMALIZE_MODES
    from rtmesh.batch.options import FORMATS, PROGRESS_MODES
    from rtmesh.batch.jobs import VIEWS

    p = commands.add_parser(
        "batch", help="render many mesh files (folders, manifests) to images, resumably",
        description="Render every mesh file named by INPUTS into OUTDIR, mirroring the input "
        "tree. INPUTS are mesh files, folders (searched recursively) or manifests (.txt: one "
        "path per line; .csv: a 'path' column plus optional width, height, spp, views, "
        "turntable, formats, passes, seed). Re-running the same command skips finished images "
        "whose inputs, settings and files are unchanged (OUTDIR/rtmesh-batch-ledger.sqlite); "
        "OUTDIR/rtmesh-batch-summary.json and rtmesh-batch-report.jsonl say what the run did. "
        "Exit status: 0 all done, 1 some assets failed, 2 bad invocation, 3 cluster lost "
        "(resume to continue). See docs/BATCH.md.")
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="mesh file, folder or manifest")
    p.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="output folder")
    p.add_argument("--width", type=_positive_int, default=256, help="image width (default 256)")
    p.add_argument("--height", type=_positive_int, default=256, help="image height (default 256)")
    p.add_argument("--spp", type=_positive_int, default=4, help="samples per pixel (default 4)")
    p.add_argument("--views", type=_views_option(_names(tuple(VIEWS))), default=("iso",),
                   help="comma-separated fixed views: " + ", ".join(VIEWS) + " (default iso); or a view "
                   "set: fibonacci:N (evenly spread), random:N (seeded, uniform), rings:E1,E2,...xK "
                   "(K azimuths at each elevation, degrees)")
    p.add_argument("--elevation", type=_elevation, default=(-90.0, 90.0), metavar="MIN,MAX",
                   help="elevation band of random:N views, degrees (default -90,90; a negative MIN needs "
                   "the = form: --elevation=-10,60)")
    p.add_argument("--radius-jitter", type=_non_negative_float, default=0.0, metavar="J",
                   help="view sets: camera distance times a seeded factor in [1, 1+J] (default 0)")
    p.add_argument("--turntable", type=_positive_int, metavar="N",
                   help="N frames orbiting each asset (instead of --views)")
    p.add_argument("--formats", type=_names(FORMATS), default=("png",),
                   help="comma-separated output formats: " + ", ".join(FORMATS) + " (default png)")
    p.add_argument("--passes", type=_names(PASSES), default=(), help="extra EXR passes: " + ", ".join(PASSES))
    p.add_argument("--ground", action="store_true", help="a ground plane under each asset (shadow)")
    p.add_argument("--camera-json", action="store_true",
                   help="write each image's camera (K, OpenCV/OpenGL poses, near/far, normalisation) "
                   "next to it as IMAGE-KEY.camera.json (docs/CAMERAS.md)")
    p.add_argument("--normalize", choices=NORMALIZE_MODES,
                   help="centre each asset and scale it to a unit cube (longest side 1) or unit "
                   "sphere (bounding radius 1) first")
    p.add_argument("--dataset", choices=("nerfstudio", "colmap", "bop"),
                   help="write each asset's dataset files: nerfstudio ASSET.transforms.json (with "
                   "depth/mask PNGs for --passes depth,alpha), COLMAP ASSET.colmap/*.txt or a BOP "
                   "scene ASSET.bop/; implies --camera-json (docs/BATCH.md, docs/DATASETS.md)")
    p.add_argument("--units", choices=("m", "cm", "mm"), default="m",
                   help="the assets' units, for --dataset bop's millimetres (default m)")
    p.add_argument("--movie", choices=("webp", "gif", "mp4"),
                   help="with --turntable: each asset's frames as ASSET.turntable.webp|gif|mp4 "
                   "(mp4 needs rtmesh[movie])")
    p.add_argument("--contact-sheet", action="store_true",
                   help="one grid image of all thumbnails with names per output folder "
                   "(rtmesh-contact-sheet.png)")
    p.add_argument("--annotations", action="store_true",
                   help="COCO instance annotations: KEY.coco.json per image, merged into "
                   "annotations.coco.json per output folder (docs/DATASETS.md)")
    p.add_argument("--flow", action="store_true",
                   help="optical flow between each asset's ordered views: flow_forward and "
                   "flow_backward EXR layers (X, Y, valid) per view; needs exr among the formats")
    p.add_argument("--flow-format", choices=("exr", "flo"), default="exr",
                   help="flo: also Middlebury KEY.flow_forward.flo / .flow_backward.flo files")
    p.add_argument("--asset-meta", action="store_true",
                   help="write ASSET.meta.json per asset: triangle/vertex counts, bounds, materials, "
                   "textures found and missing, load warnings")
    p.add_argument("--ortho", action="store_true",
                   help="orthographic cameras for the fixed views (front/top/side CAD views)")
    p.add_argument("--seed", type=int, default=0, help="random seed")
    p.add_argument("--integrator", choices=INTEGRATORS,
                   help="light transport: whitted or path (path tracing); default: path for glTF/GLB, "
                   "whitted for other files")
    p.add_argument("--max-depth", type=int,
                   help="whitted: reflection/refraction bounces (default 5); path: segments after the "
                   "camera ray (default -1, unlimited)")
    p.add_argument("--exposure", type=float, default=0.0, help="exposure in stops for 8-bit output")
    p.add_argument("--tonemap", choices=TONEMAPS, default="reinhard", help="tone mapping for 8-bit output")
    p.add_argument("--dither", action="store_true",
                   help="blue-noise dithering when quantising to 8-bit PNG/JPEG (no bands in smooth "
                   "gradients; default: round to nearest)")
    p.add_argument("--workers", type=_positive_int, help="local worker processes (default: all cores)")
    p.add_argument("--threads", type=_positive_int,
                   help="render threads per asset (default: cores / workers locally, 1 on Dask)")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="run on a dask.distributed cluster (pip install rtmesh[distributed])")
    p.add_argument("--time-limit", type=_positive_float, default=600.0, metavar="SECONDS",
                   help="seconds one asset may take before it is stopped (default 600)")
    p.add_argument("--memory-limit", type=_bytes, metavar="SIZE",
                   help="address space per local worker, e.g. 4G; 0 = off (default: RAM / workers)")
    p.add_argument("--force", action="store_true", help="redo every image, ignoring the ledger")
    p.add_argument("--trust-mtime", action="store_true",
                   help="compare inputs and finished images by size and modification time, not "
                   "content (faster resume)")
    failed = p.add_mutually_exclusive_group()
    failed.add_argument("--retry-failed", dest="retry_failed", action="store_true", default=True,
                        help="try assets that failed in an earlier run once more (default)")
    failed.add_argument("--skip-failed", dest="retry_failed", action="store_false",
                        help="leave assets that failed in an earlier run with the same inputs "
                        "(counted as known failures)")
    p.add_argument("--progress", choices=PROGRESS_MODES, default="bar",
                   help="bar (default), jsonl (one JSON line per finished asset) or none")
    p.add_argument("--progress-file", metavar="FILE",
                   help="append --progress jsonl lines to FILE instead of stderr")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    _add_debug_flag(p)


def _add_debug_flag(p):
    """``--debug`` after a command as well as before it (``rtmesh render --debug ...``)."""
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                   help=f"show the traceback of an internal error (or set {DEBUG_VARIABLE}=1)")


class ProgressBar:
    """A one-line progress bar on stderr, shown only once a render has run for a moment."""

    def __init__(self, enabled, delay=0.5, stream=sys.stderr):
        self.enabled, self.delay, self.stream = enabled, delay, stream
        self.start = time.perf_counter()
        self.shown = False

    def __call__(self, done, total):
        elapsed = time.perf_counter() - self.start
        if not self.enabled or (elapsed < self.delay and not self.shown):
            return
        self.shown = True
        width = 30
        filled = int(width * done / total)
        eta = elapsed / done * (total - done) if done else 0.0
        self.stream.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {100 * done // total:3d}% "
                          f"{elapsed:6.1f}s elapsed, {eta:5.1f}s left")
        self.stream.flush()

    def close(self):
        if self.shown:
            self.stream.write("\n")
            self.stream.flush()


class _FirstCompile(logging.Handler):
    """Writes :data:`rtmesh.core.compile_ahead.FIRST_RUN_NOTE` once, at the first kernel
    group a render compiles."""

    def __init__(self, stream):
        super().__init__(logging.INFO)
        self.stream, self.told = stream, False

    def emit(self, record):
        if record.levelno >= logging.WARNING:  # what the command shows anyway
            logging.getLogger().handle(record)
        elif not self.told:
            self.told = True
            self.stream.write(compile_ahead.FIRST_RUN_NOTE + "\n")
            self.stream.flush()


@contextlib.contextmanager
def first_run_note(stream, enabled=True):
    """Within the block, tell the user at ``stream`` in one line when the render first
    compiles kernels (:meth:`rtmesh.core.compile_ahead.KernelGroup.prepare` logs each group
    it compiles), so that the first render after an install, silent for a minute or so
    before the progress bar, does not look hung.  Nothing when ``enabled`` is False, and
    nothing once the kernels are cached.  The module's logger takes INFO records within the
    block, to this note only (its warnings still reach the command's handler); its level
    and propagation are restored after.
    """
    if not enabled:
        yield
        return
    logger = compile_ahead.log
    handler, level, propagate = _FirstCompile(stream), logger.level, logger.propagate
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
        logger.propagate = propagate


def _pass_png_path(output, name):
    """``out.exr`` -> ``out_depth.png``: where ``--pass-png`` writes a pass."""
    return f"{os.path.splitext(output)[0]}_{name}.png"


class _HeldRecords(logging.Handler):
    """The records of warnings and worse, kept (:func:`_load_warnings_held`)."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.records = []

    def emit(self, record):
        self.records.append(record)


@contextlib.contextmanager
def _load_warnings_held(path):
    """``rtmesh render``'s load and scene build: their warnings are shown once it has
    succeeded; when it fails a user sees one line, the error with the first warning, which
    often says why (``m.obj: nothing to render (...); while loading: object 'm.obj': dropped 3
    zero-area faces``).  The command owns its process: the root logger's handlers (its
    ``logging.basicConfig``) are set aside meanwhile and put back after."""
    root = logging.getLogger()
    handlers, held = root.handlers[:], _HeldRecords()
    root.handlers = [held]
    try:
        yield
    except RtmeshError as exc:
        root.handlers = handlers
        if not held.records:
            raise
        first = " ".join(held.records[0].getMessage().split())
        for prefix in (f"{path}: ", f"{os.path.basename(path)}: "):
            first = first.removeprefix(prefix)
        more = len(held.records) - 1
        raise RtmeshError(f"{_one_line(exc)}; while loading: {first}"
                          + (f" (and {more} more warning{'s' if more > 1 else ''})" if more else "")) from exc
    finally:
        root.handlers = handlers
    for record in held.records:
        root.handle(record)


def _check_outputs(args):
    """Every file ``rtmesh render`` writes can be written, before the render: the image, the
    camera and annotation files and the pass PNGs, none a folder, none the input or another
    of them (each would replace the other)."""
    check_output_path(args.output)
    outputs = [(args.output, "image")]
    for path, what in ((args.camera_json, "camera"), (args.annotations, "annotations")):
        if path:
            if not os.path.isdir(os.path.dirname(os.path.abspath(path))):
                raise OutputError(f"{path}: no such folder for the {what} file")
            if os.path.isdir(path):
                raise OutputError(f"{path}: is a folder, not a name for the {what} file")
            outputs.append((path, f"{what} file"))
    if args.pass_png:
        for name in args.passes or ():
            check_output_path(_pass_png_path(args.output, name))
            outputs.append((_pass_png_path(args.output, name), f"{name} pass PNG"))
    seen = {os.path.realpath(args.input): "input"}
    for path, what in outputs:
        other = seen.setdefault(os.path.realpath(path), what)
        if other != what:
            raise OutputError(f"{path}: the {what} would replace the {other}")


def cmd_render(args):
    _check_outputs(args)
    overrides = {
        "width": args.width, "height": args.height, "spp": args.spp, "sampler": args.sampler,
        "max_depth": args.max_depth, "seed": args.seed, "threads": args.threads,
        "ao_samples": args.ao_samples, "ao_distance": args.ao_distance, "passes": args.passes,
        "light_samples": args.light_samples, "target_error": args.target_error,
        "time_limit": args.time_limit, "max_spp": args.max_spp,
        "fresnel": args.fresnel, "exposure": args.exposure, "tonemap": args.tonemap,
        "denoise": args.denoise, "integrator": args.integrator, "clamp": args.clamp,
        "caustics": args.caustics, "photons": args.photons, "dither": args.dither,
        "light_sampler": args.light_sampler,
    }
    background = None if args.background is None else background_from_option(args.background)
    # the command owns its process: tune it for rendering (allocator, GIL, kept threads)
    runtime.tune_process()
    # on a first run, a second process compiles kernels alongside this one; a user at a
    # terminal is told why the render takes a while to start
    interactive = not args.quiet and sys.stderr.isatty()
    with first_run_note(sys.stderr, enabled=interactive), compile_ahead.helper():
        # the memory check runs on the settings before any mesh is read, and the loaders
        # check what a file would take before they take it (and the integrator what
        # flattening instances would)
        with memory.loading_limit(args.memory_limit), _load_warnings_held(args.input):
            scene, settings = load_scene(args.input, lambda s: memory.check(s, args.memory_limit), **overrides)
            if background is not None:
                scene.background = background
            integrator = Integrator(scene, settings)
        bar = ProgressBar(enabled=interactive)
        try:
            result = integrator.render(progress=bar)
        finally:
            bar.close()
    result.write(args.output)  # by the settings: exposure, tone map, dither
    if args.camera_json:
        write_camera_json(args.camera_json, camera_record(scene.camera, settings.width, settings.height,
                                                          scene.bounds))
    if args.annotations:
        record = camera_record(scene.camera, settings.width, settings.height, scene.bounds)
        annotate_render(args.annotations, integrator, result, os.path.basename(args.output), record)
    if args.pass_png:
        coverage = result.passes.get("alpha", result.alpha)
        coverage = None if coverage is None else coverage[:, :, 0]
        for name, values in result.passes.items():
            display, srgb = display_values(name, values, coverage)
            write_display_image(_pass_png_path(args.output, name), display, srgb)
    _print_result(summary_line(args.output, settings, result.stats))
    return 0


def _print_result(line):
    """Print a command's result line to stdout.  A reader that has gone away (``| head``) is
    not an error: the command's work is finished and written; stdout then goes to the null
    device, so that nothing fails flushing it again."""
    try:
        print(line)
        sys.stdout.flush()
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


def summary_line(output, settings, st):
    """The line a render prints: size, samples, rays, time, threads, estimated error, and
    for an adaptive render its rounds and why it stopped; under the path integrator also
    its rays by kind (active rays only, no idle packet lanes) and samples per second."""
    error = "" if st.relative_error != st.relative_error else f", est. rel. error {st.relative_error:.3g}"
    samples = f"{settings.spp} spp"
    adaptive = ""
    if settings.adaptive:
        samples = f"{st.mean_spp:.1f} spp mean"
        shown = [f"{r.pixels}px/{r.error:.3g}" for r in st.rounds]
        if len(shown) > 6:  # a long tail of small rounds: the first and the last
            shown = shown[:3] + ["..."] + shown[-2:]
        rounds = " ".join(shown)
        stop = {"target": "target reached", "time_limit": "time limit",
                "max_spp": "max spp reached"}.get(st.stop_reason, st.stop_reason)
        adaptive = f"; {len(st.rounds)} rounds (pixels/est. error: {rounds}), stopped: {stop}"
    path = ""
    if settings.integrator == "path":
        kinds = " / ".join(f"{st.rays[kind] / 1e6:.2f} {kind}" for kind in ("camera", "bounce", "shadow"))
        rate = st.samples / st.wall_seconds / 1e6 if st.wall_seconds > 0 else 0.0
        path = f"; path: M rays {kinds}, {rate:.2f} M samples/s"
        if st.photon_passes:
            path += (f"; caustics: {st.photon_passes} photon passes of {st.photons} photons "
                     f"({st.photons_stored / st.photon_passes:.0f} stored a pass), {st.photon_seconds:.2f} s")
    return (f"{output}: {settings.width}x{settings.height}, {samples}, "
            f"{st.total_rays / 1e6:.2f} M rays ({st.rays_per_second / 1e6:.2f} M rays/s), "
            f"{st.wall_seconds:.2f} s, {st.threads} threads{error}{adaptive}{path}")


# the modules that declare the renderer's kernel groups (importing one registers its group)
_KERNEL_GROUP_MODULES = ("rtmesh.geometry.build_kernels", "rtmesh.rendering.direct_stage",
                         "rtmesh.rendering.path_signatures", "rtmesh.rendering.caustics",
                         "rtmesh.geometry.embree_packets")


def cmd_compile(args):
    """Compile every kernel group the cache lacks (the render's helper process beside)."""
    for module in _KERNEL_GROUP_MODULES:
        importlib.import_module(module)
    every = compile_ahead.groups()
    missing = [group for group in every if not group.cached()]
    start = time.perf_counter()
    if missing and sys.stderr.isatty():
        print(compile_ahead.FIRST_RUN_NOTE, file=sys.stderr, flush=True)
    with compile_ahead.helper():
        for group in missing:
            group.compile_ahead()
        for group in missing:
            group.prepare()
    if missing:
        _print_result(f"rtmesh: {len(missing)} of {len(every)} kernel groups compiled for this machine in "
                      f"{time.perf_counter() - start:.0f} s")
    else:
        _print_result(f"rtmesh: all {len(every)} kernel groups are compiled for this machine already")
    return 0


def cmd_batch(args):
    from rtmesh.batch.runner import batch_convert

    report = batch_convert(
        args.inputs, args.output, width=args.width, height=args.height, spp=args.spp,
        views=args.views, elevation=args.elevation, radius_jitter=args.radius_jitter,
        turntable=args.turntable or 0, formats=args.formats, passes=args.passes,
        ground=args.ground, camera_json=args.camera_json, normalize=args.normalize or "",
        ortho=args.ortho, dataset=args.dataset or "", asset_meta=args.asset_meta,
        annotations=args.annotations, flow=args.flow, flow_format=args.flow_format, units=args.units,
        movie=args.movie or "", contact_sheet=args.contact_sheet, seed=args.seed, max_depth=args.max_depth,
        integrator=args.integrator,
        exposure=args.exposure, tonemap=args.tonemap, dither=args.dither, workers=args.workers, threads=args.threads,
        scheduler=args.scheduler, time_limit=args.time_limit, memory_limit=args.memory_limit,
        force=args.force, trust_mtime=args.trust_mtime, retry_failed=args.retry_failed,
        progress=args.progress, progress_file=args.progress_file, quiet=args.quiet)
    lost = report.counts["not_attempted"]
    if lost:
        print(f"rtmesh: cluster lost: {lost} assets not attempted, resume to continue",
              file=sys.stderr)
    _print_result(report.summary())  # a reader gone away (| head): the batch is finished and recorded
    return report.exit_code


def main(argv=None):
    """Entry point of the ``rtmesh`` command; returns the exit status.

    Every failure ends in one line on stderr and an exit status (docs/LIMITS.md): a user
    error (:class:`RtmeshError`, or memory running out for what was asked) 2, an
    interruption 130, anything else is an internal error, 70, whose traceback
    ``--debug`` or ``RTMESH_DEBUG=1`` shows.  Outputs are written atomically, so no
    failure leaves a partial image.
    """
    logging.basicConfig(format="rtmesh: warning: %(message)s", level=logging.WARNING)
    # trimesh reports recoverable oddities of files at warning level; ours are enough
    logging.getLogger("trimesh").setLevel(logging.ERROR)
    args = build_parser().parse_args(argv)
    try:
        if args.command == "render":
            return cmd_render(args)
        if args.command == "batch":
            return cmd_batch(args)
        if args.command == "compile":
            return cmd_compile(args)
    except RtmeshError as exc:
        print(f"rtmesh: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        if args.command == "batch":
            print("rtmesh: interrupted; finished images are kept: run the same command to resume",
                  file=sys.stderr)
        else:
            print("rtmesh: interrupted; no image written", file=sys.stderr)
        return EXIT_INTERRUPTED
    except MemoryError:
        # what the memory estimate (rtmesh.rendering.memory) did not foresee: still the size asked for
        print("rtmesh: error: out of memory; no image written (ask for fewer pixels, samples "
              "or passes, or a smaller chunk_samples)", file=sys.stderr)
        return EXIT_USER_ERROR
    except Exception as exc:  # a bug: one line unless asked for the traceback
        if args.debug or os.environ.get(DEBUG_VARIABLE, "") not in ("", "0"):
            traceback.print_exc()
        print(f"rtmesh: internal error: {type(exc).__name__}: {_one_line(exc)} (run with --debug "
              f"or {DEBUG_VARIABLE}=1 for the traceback)", file=sys.stderr)
        return EXIT_INTERNAL_ERROR
    return 0


def _one_line(exc):
    """An exception's message on one line (first line, or its type when it has none)."""
    lines = str(exc).strip().splitlines()
    return lines[0] if lines else type(exc).__name__


def command():
    """The ``rtmesh`` program (its console script, and ``python -m rtmesh.cli``): :func:`main`,
    then the process ends with its exit status without tearing down the interpreter
    (:func:`rtmesh.core.runtime.end_process`): when :func:`main` returns, the command's
    images and files are closed and in place, its worker and helper processes stopped, a
    Dask client closed."""
    runtime.end_process(main())


if __name__ == "__main__":
    command()
