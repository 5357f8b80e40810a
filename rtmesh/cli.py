"""Command line: ``rtmesh render``."""

import argparse
import logging
import sys
import time

from . import __version__
from .api import load_scene
from .errors import RtmeshError
from .film import TONEMAPS
from .image_io import check_output_path, write_image
from .integrator import Integrator
from .sampling import SAMPLERS
from .settings import FRESNEL_MODES, PASSES

EXIT_USER_ERROR = 2


def _passes(text):
    names = tuple(p.strip() for p in text.split(",") if p.strip())
    for name in names:
        if name not in PASSES:
            raise argparse.ArgumentTypeError(f"unknown pass {name!r} (available: {', '.join(PASSES)})")
    return names


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {value}")
    return value


def build_parser():
    parser = argparse.ArgumentParser(prog="rtmesh", description="Ray trace triangle-mesh scenes.")
    parser.add_argument("--version", action="version", version=f"rtmesh {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)

    p = commands.add_parser("render", help="render a scene file or a mesh file to an image",
                            description="Render a .toml scene file or a mesh file (OBJ, glTF/GLB, "
                            "PLY, STL, OFF; framed automatically and lit by a default light rig).")
    p.add_argument("input", help="scene file (.toml) or mesh file")
    p.add_argument("-o", "--output", required=True,
                   help="output image: .exr (linear float, with passes) or .png/.jpg (8-bit sRGB)")
    p.add_argument("--width", type=_positive_int, help="image width in pixels")
    p.add_argument("--height", type=_positive_int, help="image height in pixels")
    p.add_argument("--spp", type=_positive_int, help="samples per pixel")
    p.add_argument("--sampler", choices=SAMPLERS, help="pixel sample pattern (default jittered)")
    p.add_argument("--max-depth", type=int, help="reflection/refraction bounces")
    p.add_argument("--seed", type=int, help="random seed (same seed, same image)")
    p.add_argument("--threads", type=_positive_int, help="worker threads (default: all cores)")
    p.add_argument("--ao-samples", type=int, help="ambient-occlusion rays per hit (0 = off)")
    p.add_argument("--ao-distance", type=float, help="ambient-occlusion reach, scene units")
    p.add_argument("--passes", type=_passes, help="extra EXR passes, comma-separated: " + ", ".join(PASSES))
    p.add_argument("--fresnel", choices=FRESNEL_MODES, help="Fresnel model for dielectrics")
    p.add_argument("--exposure", type=float, help="exposure in stops for 8-bit output")
    p.add_argument("--tonemap", choices=TONEMAPS, help="tone-mapping operator for 8-bit output")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    return parser


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


def cmd_render(args):
    check_output_path(args.output)
    overrides = {
        "width": args.width, "height": args.height, "spp": args.spp, "sampler": args.sampler,
        "max_depth": args.max_depth, "seed": args.seed, "threads": args.threads,
        "ao_samples": args.ao_samples, "ao_distance": args.ao_distance, "passes": args.passes,
        "fresnel": args.fresnel, "exposure": args.exposure, "tonemap": args.tonemap,
    }
    scene, settings = load_scene(args.input, **overrides)
    bar = ProgressBar(enabled=not args.quiet and sys.stderr.isatty())
    try:
        result = Integrator(scene, settings).render(progress=bar)
    finally:
        bar.close()
    write_image(args.output, result.image, result.passes, settings.exposure, settings.tonemap)
    st = result.stats
    error = "" if st.relative_error != st.relative_error else f", est. rel. error {st.relative_error:.3g}"
    print(f"{args.output}: {settings.width}x{settings.height}, {settings.spp} spp, "
          f"{st.total_rays / 1e6:.2f} M rays ({st.rays_per_second / 1e6:.2f} M rays/s), "
          f"{st.wall_seconds:.2f} s, {st.threads} threads{error}")
    return 0


def main(argv=None):
    """Entry point of the ``rtmesh`` command; returns the exit status."""
    logging.basicConfig(format="rtmesh: warning: %(message)s", level=logging.WARNING)
    # trimesh reports recoverable oddities of files at warning level; ours are enough
    logging.getLogger("trimesh").setLevel(logging.ERROR)
    args = build_parser().parse_args(argv)
    try:
        if args.command == "render":
            return cmd_render(args)
    except RtmeshError as exc:
        print(f"rtmesh: error: {exc}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("rtmesh: interrupted; no image written", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
