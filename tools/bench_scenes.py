"""Render times of the bundled scenes, for this checkout against another revision.

Each scene of ``assets/`` (the showcase, the effects scenes, glass_edges, passes) is
rendered at its own settings by this checkout and by the revision given with ``--against``
(checked out once into a temporary git worktree and imported from there), in separate
processes, alternating between the two, ``--runs`` times each after a warm-up render that
compiles the kernels.  Only the render is timed (``stats.wall_seconds``: no start-up, no
scene loading, no image writing).  Prints a table of median times and speed-ups, and
whether the two images are bit-identical.

Usage::

    python tools/bench_scenes.py [--against REV] [--runs 3] [--threads 2] [--scale 1.0]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SCENES = ["assets/showcase.toml", "assets/glass_edges.toml", "assets/passes.toml",
          *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "assets" / "effects").glob("*.toml"))]

# one render in a fresh process: JSON with the render time and a digest of the image
CHILD = r"""
import hashlib, json, sys
from rtmesh.api import load_scene
from rtmesh.integrator import Integrator
import dataclasses
path, threads, scale = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
scene, settings = load_scene(path)
settings = dataclasses.replace(settings, threads=threads, width=max(1, round(settings.width * scale)),
                               height=max(1, round(settings.height * scale)))
result = Integrator(scene, settings).render()
print(json.dumps({"seconds": result.stats.wall_seconds,
                  "digest": hashlib.sha256(result.image.tobytes()).hexdigest()}))
"""


def render_once(source, scene, threads, scale):
    """Render ``scene`` with the rtmesh found under ``source``; (seconds, image digest)."""
    env = dict(os.environ, PYTHONPATH=str(source))
    done = subprocess.run([sys.executable, "-c", CHILD, str(ROOT / scene), str(threads), str(scale)],
                          env=env, capture_output=True, text=True, check=True, cwd=source)
    out = json.loads(done.stdout.strip().splitlines()[-1])
    return out["seconds"], out["digest"]


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
                digests = {}
                for source, key in ((ROOT, "this"), (other, "other")):  # warm-up: compile, cache
                    digests[key] = render_once(source, scene, args.threads, args.scale)[1]
                for _ in range(args.runs):
                    for source, key in ((ROOT, "this"), (other, "other")):
                        times[key].append(render_once(source, scene, args.threads, args.scale)[0])
                this, then = float(np.median(times["this"])), float(np.median(times["other"]))
                same = "yes" if digests["this"] == digests["other"] else "no"
                rows.append(f"| {scene} | {1e3 * then:.0f} | {1e3 * this:.0f} | {then / this:.2f} | {same} |")
                print(rows[-1], flush=True)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(other)], cwd=ROOT, check=False)
    print()
    print(f"Render times, ms (medians of {args.runs}, {args.threads} threads, scale {args.scale}); "
          f"{args.against} against this checkout:")
    print(f"| scene | {args.against} | this | speed-up | same image |")
    print("|---|---:|---:|---:|---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
