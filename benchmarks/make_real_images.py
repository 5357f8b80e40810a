"""Render every real mesh file to docs/images/real_<name>.png through the command line.

Usage, from the repository root::

    python -m benchmarks.make_real_images [FOLDER]    # default: ../shared/assets/real

Each file is rendered at 320x320, 16 samples per pixel, with its own materials and
textures, its glTF camera and lights where it has them, and otherwise the automatic framing
and the default light rig.  A file that cannot render is listed with the command's one-line
error (exit status 2) and gets no image.  The summary printed at the end is the table of
docs/MATERIALS.md ("Real files").
"""

import glob
import os
import subprocess
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
DEFAULT_FOLDER = os.path.join(ROOT, "..", "shared", "assets", "real")
MESHES = (".obj", ".glb", ".gltf", ".ply", ".stl", ".off")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    folder = argv[0] if argv else DEFAULT_FOLDER
    out_dir = os.path.join(ROOT, "docs", "images")
    env = dict(os.environ, PYTHONPATH=ROOT)
    rows = []
    for path in sorted(glob.glob(os.path.join(folder, "*"))):
        if not path.lower().endswith(MESHES):
            continue
        name = os.path.splitext(os.path.basename(path))[0]
        out = os.path.join(out_dir, f"real_{name}.png")
        proc = subprocess.run([sys.executable, "-m", "rtmesh.cli", "render", path, "-o", out,
                               "--width", "320", "--height", "320", "--spp", "16", "-q"],
                              capture_output=True, text=True, env=env)
        messages = [line.removeprefix("rtmesh: ") for line in proc.stderr.strip().splitlines()]
        status = "rendered" if proc.returncode == 0 else f"exit {proc.returncode}"
        rows.append((os.path.basename(path), status, "; ".join(messages) or "-"))
    print("| file | result | messages |")
    print("|---|---|---|")
    for row in rows:
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
