"""Scene build time for a mesh of a million triangles and more: load, normals, scene, BVH.

Writes an icosphere (``--subdivisions 8``: 1,310,720 triangles) to a temporary PLY file
without normals, then times, stage by stage, what ``rtmesh render mesh.ply`` does before
its first ray, in a process tuned as that command tunes its own
(:func:`rtmesh.core.runtime.tune_process`):

* ``load``: :func:`rtmesh.loaders.importers.load_trimesh`, of which ``trimesh.load`` is trimesh
  reading the PLY (with trimesh's processing, the vertex merge, where rtmesh leaves it to
  trimesh) and the rest rtmesh's own (:func:`rtmesh.loaders.mesh_processing.process`);
* ``parts``: :func:`rtmesh.loaders.trimesh_parts.parts_from_trimesh`, of which ``smooth normals`` is
  :func:`rtmesh.geometry.smoothing.smooth_vertex_normals` (normals split at creases) and the rest
  the world transform;
* ``scene``: :meth:`rtmesh.scene.model.Scene.from_parts` (flattening, degenerate-face filter,
  face normals, auto camera);
* ``integrator``: :class:`rtmesh.rendering.integrator.Integrator`, of which ``accel`` is the
  :class:`rtmesh.geometry.accel.Accel` the integrator builds (float32 copies, Embree scene and BVH,
  the float64 triangle table) and ``shading tables`` the per-face rows shading reads (:meth:`ShadingTables.build`).

The stages inside a stage are timed in the same run by wrapping the functions named above
(a sub-stage whose function is missing is left out).  To read Embree's share apart from
rtmesh's, Embree's own work is measured apart on the same arrays, as the Accel did it:

* with packet queries (:mod:`rtmesh.geometry.embree_packets`): ``embree scene``, the
  :class:`~rtmesh.geometry.embree_library.SharedScene` (padded float32 and uint32 copies, Embree's
  geometry over them, the commit that builds the BVH);
* with embreex's ``run()``: ``embree upload`` (embreex ``TriangleMesh``, which copies the
  arrays into Embree's own buffers) and ``embree BVH`` (the commit on the first query);

and ``total without Embree`` is the total less those.  ``RTMESH_EMBREE=run`` in the
environment makes the Accel (and so this benchmark) take the ``run()`` path.

Medians over ``--runs`` runs in one process, after a warm-up run.

Usage::

    python -m benchmarks.bench_build [--subdivisions 8] [--runs 5] [--no-write]
"""

import argparse
import contextlib
import datetime
import os
import tempfile
import time

import numpy as np
import trimesh
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

import rtmesh.loaders.trimesh_parts
import rtmesh.rendering.integrator
from benchmarks._lib import machine, publish
from rtmesh.core import runtime
from rtmesh.geometry import embree_library
from rtmesh.loaders.importers import load_trimesh
from rtmesh.loaders.trimesh_parts import parts_from_trimesh
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings
from rtmesh.rendering.shading_tables import ShadingTables
from rtmesh.scene.model import Scene

SECTION = "Scene build time, 1M+ triangles"
# (stage, sub-stage, where the sub-stage's function is looked up, its name there)
SUB_STAGES = (
    ("load", "trimesh.load", trimesh, "load"),
    ("parts", "smooth normals", rtmesh.loaders.trimesh_parts, "smooth_vertex_normals"),
    ("integrator", "accel", rtmesh.rendering.integrator, "Accel"),
    ("integrator", "shading tables", ShadingTables, "build"),
)
STAGES = ("load", "parts", "scene", "integrator")
# Embree's part, measured apart: the shared-buffer scene (packet path) or embreex's (run())
EMBREE = ("embree scene", "embree upload", "embree BVH")


@contextlib.contextmanager
def timed_calls(times):
    """Wrap the functions of :data:`SUB_STAGES` so that every call adds its seconds to
    ``times[sub-stage]``; the originals are put back on exit."""
    patched = []

    def timer(function, label):
        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                times[label] = times.get(label, 0.0) + time.perf_counter() - start
        return timed

    try:
        for _, label, owner, name in SUB_STAGES:
            function = getattr(owner, name, None)
            if function is not None:
                # a class attribute as found in the class (not bound), so it wraps as a method
                original = owner.__dict__[name] if isinstance(owner, type) else function
                setattr(owner, name, timer(function, label))
                patched.append((owner, name, original))
        yield
    finally:
        for owner, name, original in reversed(patched):
            setattr(owner, name, original)


def build_once(path):
    """Time every stage once; returns a dict of seconds and the scene's face count."""
    times = {}
    clock = time.perf_counter()

    def lap(name):
        nonlocal clock
        now = time.perf_counter()
        times[name] = now - clock
        clock = now

    with timed_calls(times):
        clock = time.perf_counter()
        obj = load_trimesh(path)
        lap("load")
        parts, materials = parts_from_trimesh(obj, "mesh")
        lap("parts")
        scene = Scene.from_parts(parts, materials, source=path)
        lap("scene")
        integrator = Integrator(scene, RenderSettings(width=64, height=64, spp=1))
        lap("integrator")
    # Embree's own work, apart, on the arrays the Accel traced, the way it built its scene
    vertices = scene.vertices - integrator.shift
    faces32 = np.ascontiguousarray(scene.faces, dtype=np.int32)
    packets = getattr(integrator.accel, "packets", False)
    del integrator, scene, parts, obj
    clock = time.perf_counter()
    if packets:
        embree_library.SharedScene(embree_library.packet_library(), vertices, faces32).close()
        lap("embree scene")
    else:
        vertices32 = np.ascontiguousarray(vertices, dtype=np.float32)
        clock = time.perf_counter()
        embree = rtcore_scene.EmbreeScene(robust=True)
        TriangleMesh(embree, vertices32, faces32)
        lap("embree upload")
        embree.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), query="OCCLUDED")
        lap("embree BVH")
    times["total"] = sum(times[k] for k in STAGES)
    times["total without Embree"] = times["total"] - sum(times.get(k, 0.0) for k in EMBREE)
    for stage, label, _, _ in SUB_STAGES:
        if label in times:
            times[f"{stage} rest"] = times[stage] - sum(times[sub] for st, sub, _, _ in SUB_STAGES
                                                        if st == stage and sub in times)
    return times, len(faces32)


def table(median):
    """Markdown rows of the breakdown: stages, their parts, the total, Embree apart."""
    total = median["total"]

    def row(label, key, bold=False):
        seconds, share = f"{median[key]:.2f}", f"{100 * median[key] / total:.0f} %"
        if bold:
            label, seconds, share = f"**{label}**", f"**{seconds}**", f"**{share}**"
        return f"| {label} | {seconds} | {share} |"

    rows = []
    for stage in STAGES:
        rows.append(row(stage, stage))
        subs = [label for st, label, _, _ in SUB_STAGES if st == stage and label in median]
        rows += [row(f"- {label}", label) for label in subs]
        if subs:
            rows.append(row("- rest", f"{stage} rest"))
    rows.append(row("load + scene + BVH", "total", bold=True))
    rows += [row(f"({key}, measured apart)", key) for key in EMBREE if key in median]
    rows.append(row("total without Embree", "total without Embree"))
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--subdivisions", type=int, default=8)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--no-write", action="store_true", help="print only; leave docs/BENCHMARKS.md alone")
    args = parser.parse_args()
    # measure as the rtmesh command runs: in a process tuned for rendering
    runtime.tune_process()
    load_average = machine()

    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "icosphere.ply")
        trimesh.creation.icosphere(subdivisions=args.subdivisions).export(path)
        size_mb = os.path.getsize(path) / 1e6
        build_once(path)  # warm-up: imports, compiled kernels, first-touch of the allocator
        runs = []
        packets = embree_library.packet_library() is not None
        for _ in range(args.runs):
            times, n_faces = build_once(path)
            runs.append(times)
            print(", ".join(f"{k} {v:.2f}" for k, v in times.items()), flush=True)
    median = {k: float(np.median([r[k] for r in runs])) for k in runs[0]}
    command = "python -m benchmarks.bench_build"
    if args.subdivisions != 8 or args.runs != 5:
        command += f" --subdivisions {args.subdivisions} --runs {args.runs}"
    text = "\n".join([
        f"## {SECTION}",
        "",
        f"Command: `{command}`",
        "",
        f"- Machine: {load_average}, shared with other jobs",
        f"- Date: {datetime.date.today().isoformat()}",
        f"- Mesh: icosphere of {args.subdivisions} subdivisions, {n_faces} triangles, written by "
        f"trimesh to a {size_mb:.0f} MB binary PLY without normals (so rtmesh computes smooth "
        "normals, split at creases)",
        f"- Median seconds of {args.runs} runs in one process after a warm-up; \"- \" rows are "
        "parts of the stage above them, timed in the same runs",
        f"- Embree path: {'packet queries, scene over shared buffers' if packets else 'embreex run()'}",
        "",
        "| stage | seconds | share |",
        "|---|---:|---:|",
        *table(median),
        "",
    ])
    publish(text, SECTION, write=not args.no_write)


if __name__ == "__main__":
    main()
