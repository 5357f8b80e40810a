"""First-run compile time: `rtmesh render` from an empty numba cache, then again.

Each run makes a new folder for numba's disk cache (``NUMBA_CACHE_DIR``), renders a scene
twice with the command line (a new process each time) and reports the wall time of both
and their difference, the time spent compiling.  With several source trees (worktrees of
other commits) the trees alternate run by run, so that they share the machine's state.

    python -m benchmarks.bench_first_run --runs 3
    python -m benchmarks.bench_first_run --runs 3 --tree /path/to/old/worktree --tree .
    python -m benchmarks.bench_first_run --api      # rtmesh.render(): no compile helper

Prints one line per run and the medians; the README reports the figures.
"""

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
SCENES = (os.path.join(ROOT, "assets", "showcase.toml"), os.path.join(ROOT, "assets", "meshes", "bunny.ply"))

# the command line (with its compile helper) as its console script runs it (cli.command;
# trees before it had main only), or the Python API (without)
COMMAND = ("import sys; sys.argv[1:] = ['render', sys.argv[1], '-o', sys.argv[2], '-q']; from rtmesh import cli; "
           "cli.command() if hasattr(cli, 'command') else sys.exit(cli.main())")
API = "import sys, rtmesh; rtmesh.render(sys.argv[1])"


def render_twice(tree, scene, code, output):
    """Wall seconds of a render from an empty cache and of the one after it."""
    cache = tempfile.mkdtemp(prefix="rtmesh-first-run-")
    env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=tree)
    walls = []
    try:
        for _ in range(2):
            start = time.perf_counter()
            subprocess.run([sys.executable, "-c", code, scene, output], env=env, cwd=tempfile.gettempdir(),
                           stdout=subprocess.DEVNULL, check=True)
            walls.append(time.perf_counter() - start)
    finally:
        shutil.rmtree(cache, ignore_errors=True)
    return walls


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--scene", action="append", help="scene or mesh file (default: showcase and bunny)")
    parser.add_argument("--tree", action="append", help="source tree to import rtmesh from (default: this one)")
    parser.add_argument("--api", action="store_true", help="render through rtmesh.render(), without the helper")
    args = parser.parse_args()
    trees = [os.path.abspath(t) for t in (args.tree or [ROOT])]
    code = API if args.api else COMMAND
    with tempfile.TemporaryDirectory() as folder:
        output = os.path.join(folder, "first_run.png")
        for scene in [os.path.abspath(s) for s in args.scene or SCENES]:
            results = {tree: [] for tree in trees}
            for _ in range(args.runs):
                for tree in trees:
                    first, after = render_twice(tree, scene, code, output)
                    results[tree].append((first, after))
                    print(f"{os.path.basename(scene)} {tree}: first {first:.2f} s, after {after:.2f} s, "
                          f"compile {first - after:.2f} s", flush=True)
            for tree, walls in results.items():
                print(f"median {os.path.basename(scene)} {tree}: first {statistics.median(w[0] for w in walls):.2f} s, "
                      f"after {statistics.median(w[1] for w in walls):.2f} s, "
                      f"compile {statistics.median(w[0] - w[1] for w in walls):.2f} s")


if __name__ == "__main__":
    main()
