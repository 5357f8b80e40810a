"""Denoised low-sample renders against more samples: error and time at the two operating
points of a glTF asset under the studio environment.

    python -m benchmarks.bench_denoise [ASSET] [--size 160] [--reference-spp 4096] [--runs 3]

(default asset: Duck.glb of ../shared/assets/real).  Renders a reference (``--reference-spp``,
its own seed, cached in /tmp by asset, size and spp), then, ``--runs`` times each and
alternating, ``--denoised-spp`` samples with ``denoise`` on (Open Image Denoise through the
``denoise`` extra, guided by the albedo and normal passes) and each of the ``--plain-spp``
sample counts without, and prints the median wall time and the RMSE of each against the
reference (linear radiance over every pixel and channel; also relative to the reference's
mean, :func:`benchmarks._lib.relative_rmse`).

Denoising is biased: its error does not go to zero with more samples, and the render's own
error estimate describes the noisy image it started from; the RMSE against the reference is
the measure here.
"""

import argparse
import dataclasses
import os
import statistics
import time

import numpy as np

from benchmarks._lib import relative_rmse
from rtmesh.api import load_scene
from rtmesh.rendering.integrator import Integrator

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
DEFAULT_ASSET = os.path.join(ROOT, "..", "shared", "assets", "real", "Duck.glb")


def render(scene, settings):
    """``(image, wall seconds)`` of one render."""
    start = time.perf_counter()
    image = Integrator(scene, settings).render().image
    return image, time.perf_counter() - start


def reference(scene, settings, path):
    """The reference image, rendered once and kept at ``path``."""
    if os.path.exists(path):
        return np.load(path)
    image, seconds = render(scene, dataclasses.replace(settings, seed=settings.seed + 1000, sampler="sobol"))
    np.save(path, image)
    print(f"reference: {settings.spp} spp in {seconds:.1f} s -> {path}")
    return image


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("asset", nargs="?", default=DEFAULT_ASSET)
    parser.add_argument("--size", type=int, default=160)
    parser.add_argument("--reference-spp", type=int, default=4096)
    parser.add_argument("--denoised-spp", type=int, default=16)
    parser.add_argument("--plain-spp", default="64",
                        help="comma-separated sample counts of the renders without denoising (e.g. 16,32,64)")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args(argv)
    scene, settings = load_scene(args.asset, width=args.size, height=args.size, threads=args.threads,
                                 sampler="jittered")
    name = os.path.splitext(os.path.basename(args.asset))[0]
    ref = reference(scene, dataclasses.replace(settings, spp=args.reference_spp),
                    f"/tmp/rtmesh-denoise-ref-{name}-{args.size}-{args.reference_spp}.npy")
    cases = {"denoised": dataclasses.replace(settings, spp=args.denoised_spp, denoise=True)}
    for spp in (int(v) for v in args.plain_spp.split(",")):
        cases[f"plain {spp}"] = dataclasses.replace(settings, spp=spp)
    times = {k: [] for k in cases}
    errors = {}
    render(scene, cases["denoised"])  # compile and load the denoiser before timing
    for _ in range(args.runs):
        for key, case in cases.items():
            image, seconds = render(scene, case)
            times[key].append(seconds)
            errors[key] = (float(np.sqrt(np.mean((image.astype(np.float64) - ref) ** 2))),
                           relative_rmse(image, ref))
    print(f"{name} {args.size}x{args.size}, {args.threads} threads, reference {args.reference_spp} spp")
    print("| render | spp | median s (runs) | RMSE | rel. RMSE |")
    print("|---|---|---|---|---|")
    for key, case in cases.items():
        runs = ", ".join(f"{t:.2f}" for t in times[key])
        print(f"| {key} | {case.spp} | {statistics.median(times[key]):.2f} ({runs}) | {errors[key][0]:.5f} | "
              f"{errors[key][1]:.4f} |")


if __name__ == "__main__":
    main()
