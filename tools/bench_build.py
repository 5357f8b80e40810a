"""Scene build time for a mesh of a million triangles and more: load, normals, scene, BVH.

Writes an icosphere (``--subdivisions 8``: 1,310,720 triangles) to a temporary PLY file
without normals, then times, stage by stage, what ``rtmesh render mesh.ply`` does before
its first ray:

* ``load``: trimesh reads the PLY (:func:`rtmesh.importers.load_trimesh`);
* ``parts``: smooth vertex normals split at creases, world transform
  (:func:`rtmesh.importers.parts_from_trimesh`);
* ``scene``: flattening, degenerate-face filter, face normals, auto camera
  (:meth:`rtmesh.scene.Scene.from_parts`);
* ``integrator``: :class:`rtmesh.integrator.Integrator`, of which ``accel`` is the
  :class:`rtmesh.accel.Accel` (float32 copy, triangle table, Embree upload and BVH build)
  and, measured apart on the same arrays, ``embree upload`` (embreex ``TriangleMesh``) and
  ``embree BVH`` (the commit on the first query).

Medians over ``--runs`` runs in one process.

Usage::

    python tools/bench_build.py [--subdivisions 8] [--runs 5] [--no-write]
"""

import argparse
import datetime
import os
import sys
import tempfile
import time

import numpy as np
import trimesh
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_core import machine, write_section  # noqa: E402

from rtmesh.accel import Accel  # noqa: E402
from rtmesh.importers import load_trimesh, parts_from_trimesh  # noqa: E402
from rtmesh.integrator import Integrator  # noqa: E402
from rtmesh.scene import Scene  # noqa: E402
from rtmesh.settings import RenderSettings  # noqa: E402

SECTION = "Scene build time, 1M+ triangles"
STAGES = ("load", "parts", "scene", "integrator", "accel", "embree upload", "embree BVH")


def build_once(path):
    """Time every stage once; returns a dict of seconds."""
    times = {}
    clock = time.perf_counter()

    def lap(name):
        nonlocal clock
        now = time.perf_counter()
        times[name] = now - clock
        clock = now

    obj = load_trimesh(path)
    lap("load")
    parts, materials = parts_from_trimesh(obj, "mesh")
    lap("parts")
    scene = Scene.from_parts(parts, materials, source=path)
    lap("scene")
    integrator = Integrator(scene, RenderSettings(width=64, height=64, spp=1))
    lap("integrator")
    vertices = scene.vertices - integrator.shift
    Accel(vertices, scene.faces)
    lap("accel")
    vertices32 = np.ascontiguousarray(vertices, dtype=np.float32)
    faces32 = np.ascontiguousarray(scene.faces, dtype=np.int32)
    lap("float32 copies")
    embree = rtcore_scene.EmbreeScene(robust=True)
    TriangleMesh(embree, vertices32, faces32)
    lap("embree upload")
    embree.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), query="OCCLUDED")
    lap("embree BVH")
    del times["float32 copies"]
    return times, len(scene.faces)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--subdivisions", type=int, default=8)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--no-write", action="store_true", help="print only; leave docs/BENCHMARKS.md alone")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "icosphere.ply")
        trimesh.creation.icosphere(subdivisions=args.subdivisions).export(path)
        size_mb = os.path.getsize(path) / 1e6
        build_once(path)  # warm-up: imports, first-touch of the allocator
        runs = []
        for _ in range(args.runs):
            times, n_faces = build_once(path)
            runs.append(times)
            print(", ".join(f"{k} {v:.2f}" for k, v in times.items()), flush=True)
    median = {k: float(np.median([r[k] for r in runs])) for k in STAGES}
    total = sum(median[k] for k in ("load", "parts", "scene", "integrator"))
    rows = [f"| {k} | {median[k]:.2f} | {100 * median[k] / total:.0f} % |" for k in ("load", "parts", "scene", "integrator")]
    rows.append(f"| **load + scene + BVH** | **{total:.2f}** | 100 % |")
    rows += [f"| ({k}, measured apart) | {median[k]:.2f} | {100 * median[k] / total:.0f} % |"
             for k in ("accel", "embree upload", "embree BVH")]
    command = "python tools/bench_build.py"
    if args.subdivisions != 8 or args.runs != 5:
        command += f" --subdivisions {args.subdivisions} --runs {args.runs}"
    text = "\n".join([
        f"## {SECTION}",
        "",
        f"Command: `{command}`",
        "",
        f"- Machine: {machine()}, shared with other jobs",
        f"- Date: {datetime.date.today().isoformat()}",
        f"- Mesh: icosphere of {args.subdivisions} subdivisions, {n_faces} triangles, written by "
        f"trimesh to a {size_mb:.0f} MB binary PLY without normals (so rtmesh computes smooth "
        "normals, split at creases)",
        f"- Median seconds of {args.runs} runs in one process after a warm-up",
        "",
        "| stage | seconds | share |",
        "|---|---:|---:|",
        *rows,
        "",
    ])
    print(text)
    if not args.no_write:
        write_section(text, SECTION)


if __name__ == "__main__":
    main()
