"""Render times of the bundled scenes, for this checkout against another revision.

Each scene of ``assets/`` (the showcase, the effects scenes, glass_edges, passes) is
rendered at its own settings by this checkout and by the revision given with ``--against``
(checked out once into a temporary git worktree and imported from there), in separate
processes, alternating between the two, ``--runs`` times each after a warm-up render that
compiles the kernels.  Each process is tuned as the ``rtmesh`` command tunes its own
(:func:`rtmesh.core.runtime.tune_process` where the revision has it; older revisions tuned
every process as they built a renderer).  Only the render is timed
(``stats.wall_seconds``: no start-up, no scene loading, no image writing), and at ``--scale``
1 the whole ``rtmesh render`` command too (``python -m rtmesh.cli`` from each tree, start-up
to exit: what a user waits for).  Prints a table of median times and speed-ups, and how far
apart the two images are: relative RMSE
(:func:`benchmarks._lib.relative_rmse`, RMSE over the other revision's mean; 0 for
bit-identical images) of the pixels and of 8 x 8 block means.

Usage::

    python -m benchmarks.bench_scenes [--against REV] [--runs 3] [--threads 2] [--scale 1.0]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._lib import ROOT, relative_rmse

SCENES = ["assets/showcase.toml", "assets/glass_edges.toml", "assets/passes.toml",
          *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "assets" / "effects").glob("*.toml"))]

# one render in a fresh process: JSON with the render time and a digest of the image
CHILD = r"""
import dataclasses, json, sys
import numpy as np
try:  # the layered layout, or the flat one of revisions before it
    from rtmesh.core import runtime
    from rtmesh.rendering.integrator import Integrator
except ImportError:
    from rtmesh.integrator import Integrator
    try:
        from rtmesh import runtime
    except ImportError:  # before the runtime module: building a renderer tuned the process
        runtime = None
if runtime is not None:
    runtime.tune_process()
from rtmesh.api import load_scene
path, threads, scale, image_path = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
scene, settings = load_scene(path)
settings = dataclasses.replace(settings, threads=threads, width=max(1, round(settings.width * scale)),
                               height=max(1, round(settings.height * scale)))
result = Integrator(scene, settings).render()
np.save(image_path, result.image)
print(json.dumps({"seconds": result.stats.wall_seconds}))
"""


def render_once(source, scene, threads, scale, image_path):
    """Render ``scene`` with the rtmesh found under ``source``, keeping the image in
    ``image_path`` (.npy); the render's seconds."""
    env = dict(os.environ, PYTHONPATH=str(source))
    done = subprocess.run([sys.executable, "-c", CHILD, str(ROOT / scene), str(threads), str(scale),
                           str(image_path)], env=env, capture_output=True, text=True, check=True, cwd=source)
    return json.loads(done.stdout.strip().splitlines()[-1])["seconds"]


def command_once(source, scene, threads, output):
    """Seconds of the whole ``rtmesh render`` command with the rtmesh under ``source``."""
    env = dict(os.environ, PYTHONPATH=str(source))
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "rtmesh.cli", "render", str(ROOT / scene), "-o", str(output), "--threads",
                    str(threads), "-q"], env=env, capture_output=True, check=True, cwd=source)
    return time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--against", default="4c3801c", help="git revision to compare with")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--scale", type=float, default=1.0, help="image size factor")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        other = Path(folder) / "other"
        subprocess.run(["git", "worktree", "add", "--detach", "-q", str(other), args.against], cwd=ROOT,
                       check=True)
        try:
            rows = []
            for scene in SCENES:
                times = {"this": [], "other": []}
                whole = {"this": [], "other": []}
                images = {key: Path(folder) / f"{key}.npy" for key in times}
                try:
                    for source, key in ((ROOT, "this"), (other, "other")):  # warm-up: compile, cache
                        render_once(source, scene, args.threads, args.scale, images[key])
                except subprocess.CalledProcessError as failed:  # a scene or key the revision lacks
                    why = (failed.stderr.strip().splitlines() or [f"exit status {failed.returncode}"])[-1]
                    rows.append(f"| {scene} | fails ({key}: {why[:80]}) | | | | | | | |")
                    print(rows[-1], flush=True)
                    continue
                this_image, other_image = np.load(images["this"]), np.load(images["other"])
                difference = (relative_rmse(this_image, other_image),
                              relative_rmse(this_image, other_image, block=8))
                for _ in range(args.runs):
                    for source, key in ((ROOT, "this"), (other, "other")):
                        times[key].append(render_once(source, scene, args.threads, args.scale, images[key]))
                        if args.scale == 1.0:
                            whole[key].append(command_once(source, scene, args.threads, Path(folder) / "out.png"))
                this, then = float(np.median(times["this"])), float(np.median(times["other"]))
                process = "| | | |"  # the three command columns, empty below scale 1
                if whole["this"]:
                    p_this, p_then = float(np.median(whole["this"])), float(np.median(whole["other"]))
                    process = f"| {p_then:.2f} | {p_this:.2f} | {p_then / p_this:.2f} |"
                rows.append(f"| {scene} | {1e3 * then:.0f} | {1e3 * this:.0f} | {then / this:.2f} {process} "
                            f"{difference[0]:.2g} | {difference[1]:.2g} |")
                print(rows[-1], flush=True)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(other)], cwd=ROOT, check=False)
    print()
    print(f"Render times, ms (medians of {args.runs}, {args.threads} threads, scale {args.scale}); "
          f"{args.against} against this checkout:")
    print("Whole command, s (medians; at scale 1 only): start-up, loading, render, writing, exit.")
    print(f"| scene | {args.against} render ms | this render ms | speed-up | {args.against} command s | "
          "this command s | speed-up | image difference (rel. RMSE) | of 8x8 block means |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
