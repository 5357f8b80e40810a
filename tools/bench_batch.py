#!/usr/bin/env python3
"""Batch conversion throughput: assets per minute with 1 worker, N local workers, and a
dask.distributed LocalCluster of N single-threaded worker processes.

    python tools/bench_batch.py                   # >= 50 generated meshes + the real assets
    python tools/bench_batch.py --count 80 --width 128 --height 128

The meshes are generated with trimesh.creation into a temporary folder (spheres, boxes,
cylinders, capsules, tori, cones of varied tessellation, written as OBJ, PLY, STL and GLB),
plus copies of the renderable meshes in ../shared/assets/real when that folder exists.
Every configuration converts the same folder from scratch (``force``) with the batch
defaults (256 x 256, 4 spp, one ``iso`` view, PNG); wall time includes starting the worker
processes, not starting the cluster (which ``--scheduler`` expects to be running).
Prints a Markdown table.
"""

import argparse
import os
import platform
import shutil
import sys
import tempfile
import time

import numpy as np
import trimesh

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import rtmesh  # noqa: E402

REAL_ASSETS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared",
                           "assets", "real")
FORMATS = ("obj", "ply", "stl", "glb")


def generated_meshes(count, seed=0):
    """``count`` varied meshes: shape, tessellation, proportions and rotation all drawn."""
    rng = np.random.default_rng(seed)
    makers = [
        lambda: trimesh.creation.icosphere(subdivisions=int(rng.integers(1, 6))),
        lambda: trimesh.creation.box(extents=rng.uniform(0.3, 2.0, 3)),
        lambda: trimesh.creation.cylinder(radius=rng.uniform(0.2, 1.0), height=rng.uniform(0.5, 3.0),
                                          sections=int(rng.integers(8, 256))),
        lambda: trimesh.creation.capsule(radius=rng.uniform(0.2, 0.8), height=rng.uniform(0.5, 2.0),
                                         count=[int(rng.integers(8, 96))] * 2),
        lambda: trimesh.creation.torus(major_radius=1.0, minor_radius=rng.uniform(0.1, 0.5),
                                       major_sections=int(rng.integers(16, 160)),
                                       minor_sections=int(rng.integers(8, 64))),
        lambda: trimesh.creation.cone(radius=rng.uniform(0.3, 1.0), height=rng.uniform(0.5, 2.0),
                                      sections=int(rng.integers(8, 128))),
    ]
    for i in range(count):
        mesh = makers[i % len(makers)]()
        angles = rng.uniform(0, 2 * np.pi, 3)
        mesh.apply_transform(trimesh.transformations.euler_matrix(*angles))
        yield f"{type_name(i, len(makers))}_{i:03d}.{FORMATS[i % len(FORMATS)]}", mesh


def type_name(i, kinds):
    return ("sphere", "box", "cylinder", "capsule", "torus", "cone")[i % kinds]


def make_collection(folder, count):
    faces = []
    for name, mesh in generated_meshes(count):
        sub = os.path.join(folder, "generated", name.split("_")[0])
        os.makedirs(sub, exist_ok=True)
        mesh.export(os.path.join(sub, name))
        faces.append(len(mesh.faces))
    real = 0
    if os.path.isdir(REAL_ASSETS):
        # the whole folder, so each asset keeps its companions (MTL files, textures); the
        # one file with no triangles is left out: this measures conversions, not failures
        target = os.path.join(folder, "real")
        shutil.copytree(REAL_ASSETS, target, ignore=shutil.ignore_patterns("empty.obj"))
        real = sum(os.path.splitext(n)[1].lower() in rtmesh.loaders.importers.MESH_EXTENSIONS
                   for n in os.listdir(target))
    return faces, real


def cpu_name():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=56, help="generated meshes (default 56)")
    parser.add_argument("--width", type=int, default=256)
    parser.add_argument("--height", type=int, default=256)
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--workers", type=int, default=len(os.sched_getaffinity(0)),
                        help="N for the pool and the cluster (default: cores)")
    parser.add_argument("--no-dask", action="store_true", help="skip the LocalCluster run")
    args = parser.parse_args(argv)
    settings = dict(width=args.width, height=args.height, spp=args.spp, quiet=True, force=True)

    with tempfile.TemporaryDirectory(prefix="rtmesh-bench-batch-") as tmp:
        src = os.path.join(tmp, "assets")
        faces, real = make_collection(src, args.count)
        print(f"# {len(faces)} generated meshes ({min(faces)}-{max(faces)} triangles) + {real} "
              f"real assets; {args.width}x{args.height}, {args.spp} spp; {cpu_name()}, "
              f"{len(os.sched_getaffinity(0))} cores, Python {platform.python_version()}, "
              f"{time.strftime('%Y-%m-%d')}", file=sys.stderr)
        rows = []

        def run(label, **options):
            out = os.path.join(tmp, "out-" + label.split()[0])
            report = rtmesh.batch_convert([src], out, **settings, **options)
            c = report.counts
            rows.append((label, c["assets"], c["done"], c["failed"], report.wall_seconds,
                         60.0 * c["done"] / report.wall_seconds))
            print(f"{label}: {report.wall_seconds:.1f} s", file=sys.stderr)

        run("1 local worker", workers=1)
        run(f"{args.workers} local workers", workers=args.workers)
        if not args.no_dask:
            from distributed import Client, LocalCluster

            start = time.perf_counter()
            with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                              dashboard_address=None, silence_logs=50) as cluster, Client(cluster):
                startup = time.perf_counter() - start
                run(f"dask LocalCluster ({args.workers} workers x 1 thread)",
                    scheduler=cluster.scheduler_address)
            print(f"(cluster start-up, not counted: {startup:.1f} s)", file=sys.stderr)

    print("| runner | assets | done | failed | wall time | assets / min |")
    print("|---|---:|---:|---:|---:|---:|")
    for label, assets, done, failed, seconds, per_minute in rows:
        print(f"| {label} | {assets} | {done} | {failed} | {seconds:.1f} s | {per_minute:.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
