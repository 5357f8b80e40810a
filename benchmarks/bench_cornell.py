"""rtmesh's path integrator against the Mitsuba 3 references of the Cornell box.

Renders ``assets/cornell_box.toml`` under ``integrator = "path"`` at 128 x 128 (``--spp``,
2 threads, the scene file's ``light_samples``: 4 next-event estimates at a path's first
vertex), with ``max_depth`` -1 (global illumination) and 1 (direct light only), and
compares each with its Mitsuba 3 reference (``tests/data/cornell_mitsuba_128.exr`` and
``cornell_mitsuba_128_direct.exr``, 32768 spp; tests/data/README.md says how they were made):
the ratio of the image means per channel, and the relative RMSE
(:func:`benchmarks._lib.relative_rmse`) of the pixels and of 8 x 8 block means, the issue's
measure (its targets: image mean within 1 %, blocks within 2 %).  Writes a side-by-side PNG
of the global-illumination image (rtmesh | Mitsuba | signed difference) and publishes the
section in docs/BENCHMARKS.md.

Usage, from the repository root::

    python -m benchmarks.bench_cornell [--spp 256] [--png docs/images/cornell_path_vs_mitsuba.png] [--no-write]
"""

import argparse
import dataclasses
import datetime
import os
import sys

import numpy as np

from benchmarks._lib import ROOT, machine, publish, relative_rmse, rtmesh_commit, write_side_by_side
from rtmesh.io.images import read_image
from rtmesh.loaders.scene_file import read_scene_file
from rtmesh.rendering.integrator import Integrator

SECTION = "Cornell box: the path integrator against Mitsuba 3"
SCENE = ROOT / "assets" / "cornell_box.toml"
DATA = ROOT / "tests" / "data"
CASES = (("global illumination", -1, "cornell_mitsuba_128.exr"),
         ("direct light only", 1, "cornell_mitsuba_128_direct.exr"))


def compare(image, reference):
    """Per-channel mean ratios, pixel and 8 x 8 block relative RMSE of ``image`` against ``reference``."""
    image, reference = np.asarray(image, np.float64), np.asarray(reference, np.float64)
    return {"mean_ratio": image.reshape(-1, 3).mean(axis=0) / reference.reshape(-1, 3).mean(axis=0),
            "image_mean_ratio": float(image.mean() / reference.mean()),
            "pixels": relative_rmse(image, reference),
            "blocks": relative_rmse(image, reference, block=8)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--png", default=str(ROOT / "docs" / "images" / "cornell_path_vs_mitsuba.png"))
    parser.add_argument("--no-write", action="store_true", help="print only; leave docs/BENCHMARKS.md alone")
    args = parser.parse_args(argv)
    scene, settings = read_scene_file(SCENE)
    at_start = machine()
    rows, images, light_samples = [], {}, set()
    for name, max_depth, reference_file in CASES:
        reference, _ = read_image(DATA / reference_file)
        case = dataclasses.replace(settings, width=128, height=128, spp=args.spp, integrator="path",
                                   max_depth=max_depth, threads=args.threads)
        light_samples.add(case.light_samples)
        result = Integrator(scene, case).render()
        image = result.image[..., :3]
        images[name] = (image, reference)
        c = compare(image, reference)
        ratios = ", ".join(f"{r:.4f}" for r in c["mean_ratio"])
        rows.append(f"| {name} (max_depth {max_depth}) | {ratios} | {c['image_mean_ratio']:.4f} | "
                    f"{c['pixels']:.2%} | {c['blocks']:.2%} | {result.stats.wall_seconds:.1f} |")
        print(rows[-1], flush=True)
    image, reference = images[CASES[0][0]]
    png, link = os.path.relpath(args.png, ROOT), os.path.relpath(args.png, ROOT / "docs")
    note = write_side_by_side(args.png, image, {"path": reference})
    print(note)
    text = "\n".join([
        f"## {SECTION}",
        "",
        f"Command: `python -m benchmarks.bench_cornell --spp {args.spp}`, rtmesh {rtmesh_commit(ROOT / 'rtmesh')}; "
        f"{datetime.date.today().isoformat()}; {at_start}",
        "",
        f"`assets/cornell_box.toml` under `integrator = \"path\"`, 128 x 128, {args.spp} spp, {args.threads} "
        f"threads, `light_samples` {' and '.join(str(n) for n in sorted(light_samples))} (the scene file's: "
        "next-event estimates at a path's first vertex; Mitsuba's `path` takes one), against Mitsuba 3.9.1 "
        "`path` at 32768 spp on the same triangles (tests/data/README.md; "
        "Mitsuba's `max_depth` is rtmesh's + 1). Relative RMSE: over the reference's mean; 8 x 8 block "
        "means are the issue's measure (targets: image mean within 1 %, blocks within 2 %). The "
        "references' own error is 0.10 % (global) and 0.13 % (direct) in 8 x 8 blocks.",
        "",
        "| render | mean ratio R, G, B | image mean ratio | rel. RMSE, pixels | rel. RMSE, 8 x 8 blocks | render s |",
        "|---|---|---:|---:|---:|---:|",
        *rows,
        "",
        f"![rtmesh path | Mitsuba 3 path | (rtmesh - Mitsuba) / mean, +-50 %]({link})",
        "",
        f"`{png}`: rtmesh | Mitsuba | signed difference over the image mean (red: rtmesh brighter; "
        "full colour at +-50 %); PBR Neutral tone mapping.",
        "",
    ])
    publish(text, SECTION, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
