#!/usr/bin/env python3
"""Batch conversion throughput: assets per minute with 1 worker, N local workers, and a
dask.distributed LocalCluster of N single-threaded worker processes.

    python -m benchmarks.bench_batch                   # >= 50 generated meshes + the real assets
    python -m benchmarks.bench_batch --count 80 --width 128 --height 128
    python -m benchmarks.bench_batch --ledger 1000000  # ledger cost of a no-op resume, 1M images
    python -m benchmarks.bench_batch --overhead 2000   # per-asset bookkeeping and resume checks

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
from types import SimpleNamespace

import numpy as np
import trimesh


import rtmesh

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


def synthetic_ledger(folder, n):
    """A ledger of ``n`` finished images (one per asset, as ``rtmesh batch`` writes them),
    filled through :class:`rtmesh.batch.ledger.Ledger` itself; returns the keys and seconds."""
    from rtmesh.batch.ledger import Ledger

    # 1000 folders of n / 1000 files, in the order a folder walk finds them
    keys = [f"library/group{i // max(1, n // 1000):03d}/asset{i:07d}.obj" for i in range(n)]
    digest = "0123456789abcdef0123456789abcdef"
    start = time.perf_counter()
    with Ledger(folder) as ledger:
        for i, key in enumerate(keys):
            ledger.record(key, key, "f" * 40, "done", inputs=[["", 12345, 1_700_000_000_000_000_000, digest]],
                          outputs=[[key + ".png", 23456, 1_700_000_000_000_000_000, digest]],
                          seconds=0.05, run="bench")
            if i % 10_000 == 9_999:
                ledger.commit()
    return keys, time.perf_counter() - start


def noop_resume_ledger_cost(folder, keys):
    """Seconds a no-op resume spends in the ledger: open it, fetch and decode the row of
    every image (what :func:`rtmesh.batch.plan` does before checking files), close it."""
    from rtmesh.batch.ledger import INPUTS, OUTPUTS, STATUS, Ledger, decode

    start = time.perf_counter()
    ledger = Ledger(folder)
    opened = time.perf_counter()
    done = 0
    for first in range(0, len(keys), 5000):  # as rtmesh.batch.plan asks
        found = ledger.lookup(keys[first:first + 5000])
        for entry in found.values():
            decode(entry[INPUTS])
            decode(entry[OUTPUTS])
            done += entry[STATUS] == "done"
    looked = time.perf_counter()
    ledger.close()
    end = time.perf_counter()
    assert done == len(keys)
    return {"open": opened - start, "lookup": looked - opened, "close": end - looked,
            "total": end - start}


def bookkeeping_cost(folder, n):
    """Milliseconds per asset the submitting process spends on a finished asset: checking
    its image (staged by the worker at a temporary name), its ledger row and commit,
    renaming the image into place, its report line (:class:`rtmesh.batch.Books`)."""
    from rtmesh.batch.books import Books
    from rtmesh.batch.identity import describe
    from rtmesh.batch.ledger import Ledger
    from rtmesh.batch.options import BatchOptions

    images = []
    for i in range(n):
        name = f"a{i:05d}.obj.png"
        staged = f".a{i:05d}.obj.bench_00.tmp.png"  # as rtmesh.io.atomic_files names it
        with open(os.path.join(folder, staged), "wb") as f:
            f.write(os.urandom(20_000))
        images.append({"asset": f"a{i:05d}.obj", "run": "bench", "key": f"a{i:05d}.obj",
                       "fingerprint": "f" * 40, "status": "done", "files": [name], "seconds": 0.05,
                       "inputs": [["", 1, 2, "x"], ["a.mtl", 1, 2, "y"]], "staged": [staged],
                       "outputs": [describe(os.path.join(folder, staged), name)]})
    with Ledger(folder) as ledger:
        books = Books(ledger, folder, BatchOptions(quiet=True), n)
        for image in images:
            books.planned(SimpleNamespace(name=image["asset"], path="/x/" + image["asset"]), [], [],
                          False, True)
        start = time.perf_counter()
        for image in images:
            books.on_image(image)
            books.on_job({"asset": image["asset"], "seconds": 0.05, "images": [image]})
        seconds = time.perf_counter() - start
        books.close()
    return 1000.0 * seconds / n


def resume_check_cost(src, out, n):
    """Milliseconds per asset of a no-op resume over ``n`` real assets (discovery, plan with
    file checks, bookkeeping), by content and with --trust-mtime."""
    result = {}
    for trust in (False, True):
        start = time.perf_counter()
        report = rtmesh.batch_convert([src], out, width=16, height=16, spp=1, quiet=True,
                                      trust_mtime=trust)
        assert report.counts["skipped"] == n, report.counts
        result[trust] = 1000.0 * (time.perf_counter() - start) / n
    return result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=56, help="generated meshes (default 56)")
    parser.add_argument("--width", type=int, default=256)
    parser.add_argument("--height", type=int, default=256)
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--workers", type=int, default=len(os.sched_getaffinity(0)),
                        help="N for the pool and the cluster (default: cores)")
    parser.add_argument("--no-dask", action="store_true", help="skip the LocalCluster run")
    parser.add_argument("--ledger", type=int, metavar="N",
                        help="only measure the ledger cost of a no-op resume over N images")
    parser.add_argument("--overhead", type=int, metavar="N",
                        help="only measure per-asset bookkeeping and no-op resume checks, N assets")
    args = parser.parse_args(argv)
    if args.ledger:
        with tempfile.TemporaryDirectory(prefix="rtmesh-bench-ledger-") as tmp:
            keys, fill = synthetic_ledger(tmp, args.ledger)
            size = os.path.getsize(os.path.join(tmp, "rtmesh-batch-ledger.sqlite"))
            cost = noop_resume_ledger_cost(tmp, keys)
        print(f"ledger of {args.ledger} images ({size / 1e6:.0f} MB, filled in {fill:.1f} s): "
              f"no-op resume {cost['total']:.2f} s (open {cost['open']:.3f}, look-up "
              f"{cost['lookup']:.2f}, close {cost['close']:.3f})")
        return 0
    if args.overhead:
        with tempfile.TemporaryDirectory(prefix="rtmesh-bench-overhead-") as tmp:
            ms = bookkeeping_cost(tmp, args.overhead)
            src, out = os.path.join(tmp, "src"), os.path.join(tmp, "out")
            os.makedirs(src)
            mesh = trimesh.creation.icosphere(subdivisions=1)
            for i in range(args.overhead):
                mesh.export(os.path.join(src, f"m{i:05d}.obj"))
            rtmesh.batch_convert([src], out, width=16, height=16, spp=1, quiet=True)
            resume = resume_check_cost(src, out, args.overhead)
        print(f"bookkeeping per finished asset: {ms:.3f} ms; no-op resume per asset: "
              f"{resume[False]:.3f} ms by content, {resume[True]:.3f} ms with --trust-mtime "
              f"({args.overhead} assets)")
        return 0
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
