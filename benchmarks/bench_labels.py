"""What --annotations and --flow add to a batch's time (docs/BENCHMARKS.md).

Renders the bundled bunny from N Fibonacci views, PNG + EXR, one local worker, from
scratch, with and without the label options, best of R runs each.

    python -m benchmarks.bench_labels [--views 12] [--size 256] [--spp 4] [--repeats 2]
"""

import argparse
import os
import shutil
import tempfile
import time

import rtmesh

MODES = {"plain": {}, "annotations": {"annotations": True}, "flow": {"flow": True},
         "annotations + flow": {"annotations": True, "flow": True}}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=12)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    folder = tempfile.mkdtemp(prefix="rtmesh-bench-labels-")
    try:
        src = os.path.join(folder, "src")
        os.makedirs(src)
        shutil.copy(os.path.join(os.path.dirname(__file__), "..", "assets", "meshes", "bunny.ply"), src)
        best = {}
        for _ in range(args.repeats):
            for mode, options in MODES.items():
                start = time.perf_counter()
                report = rtmesh.batch_convert([src], os.path.join(folder, "out"), workers=1,
                                              width=args.size, height=args.size, spp=args.spp,
                                              views=(f"fibonacci:{args.views}",), formats=("png", "exr"),
                                              force=True, progress="none", **options)
                assert report.exit_code == 0
                seconds = time.perf_counter() - start
                best[mode] = min(best.get(mode, seconds), seconds)
        print(f"| options | wall time (best of {args.repeats}) | added |")
        print("|---|---:|---:|")
        for mode, seconds in best.items():
            print(f"| {mode} | {seconds:.2f} s | {100 * (seconds / best['plain'] - 1):+.1f} % |")
    finally:
        shutil.rmtree(folder)


if __name__ == "__main__":
    main()
