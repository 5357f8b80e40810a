"""Render assets/passes.toml with every output pass and write docs/images/passes_*.png.

Run from the repository root: ``python -m benchmarks.make_pass_images`` (about a second).
"""

import os
import subprocess
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
PASSES = "depth,normal,albedo,position,object_id,material_id,alpha,ao"


def main():
    out = os.path.join(ROOT, "docs", "images", "passes.png")
    env = dict(os.environ, PYTHONPATH=ROOT)
    subprocess.run([sys.executable, "-m", "rtmesh.cli", "render", os.path.join(ROOT, "assets", "passes.toml"),
                    "-o", out, "--passes", PASSES, "--pass-png", "-q"], check=True, env=env)


if __name__ == "__main__":
    main()
