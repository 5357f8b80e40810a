"""rtmesh beside its peers, on one scene, in one run: intersection, equal error, threads.

The scene of ``/work/shared/BENCH_NOTES.md``: an icosphere (5 subdivisions, radius 1,
centre (0, 0, 1), smooth vertex normals) on a 20 x 20 ground quad at z = 0, one point light
at (3, -3, 6), a 45 degree pinhole camera at (0, -4, 2.5) looking at (0, 0, 0.8), 512 x 512,
pure Lambert with albedo 0.7 everywhere (no specular, no ambient, no reflections).

1. **Intersection**: closest hits of the 512 x 512 pixel-centre camera rays, 1 thread:
   rtmesh ``Accel.intersect`` (float64 rays in, float64 hits out), raw embreex ``run()``
   on float32 rays, and trimesh's ray API (``intersects_first`` and
   ``intersects_location(multiple_hits=False)``, embreex-backed) on the same rays.
2. **Equal error**: rtmesh and Mitsuba 3 (``llvm_ad_rgb`` and ``scalar_rgb``, ``direct``
   integrator with one emitter sample and no BSDF sample per camera sample, stratified
   sampler, box filter) render the scene at rising spp; each image's relative RMSE against
   one reference (the mean of a high-spp rtmesh render and a high-spp Mitsuba llvm render)
   gives the time each needs to reach a set of errors (log-log interpolation between the
   measured spp).  The lighting models are matched: rtmesh's Lambert term is
   ``kd I cos / d^2``, Mitsuba's diffuse BSDF is ``albedo / pi``, so Mitsuba's point light
   gets the intensity ``pi I``.  Before anything is timed, the two references must agree.
   rtmesh with adaptive sampling (Sobol, ``--adaptive-spp`` samples in the first round,
   one render per ``--adaptive-targets`` value) is measured against the same reference and
   set beside Mitsuba's uniform renders; the 0.1 % level needs a sweep to 256 spp
   (``--spp 1,4,16,64,256``) for the uniform renders to reach it.
3. **Threads**: rtmesh at 1 and 2 threads on the same render.

rtmesh runs in a process tuned as the ``rtmesh`` command tunes its own
(:func:`rtmesh.core.runtime.tune_process`), and traces with Embree's packet queries unless
``RTMESH_EMBREE=run`` is set (embreex ``run()``, one ray at a time); the report says which.

Mitsuba runs in its own venv (``sh benchmarks/peers_setup.sh``; ``--venv``, default
``$RTMESH_PEERS_VENV`` or ``/tmp/peers-venv``), through ``benchmarks/peers_mitsuba.py``; it is
never a dependency of rtmesh.  Without the venv the Mitsuba rows are skipped.  Times are
medians of ``--runs`` runs, the ratios come from this one run.

Usage::

    python -m benchmarks.bench_peers [--runs 5] [--spp 1,4,16,64] [--reference-spp 1024]
                                     [--adaptive-targets 0.2,0.1,0.05,0.03,0.02] [--adaptive-spp 4]
                                     [--venv /tmp/peers-venv] [--no-write]
"""

import argparse
import datetime
import json
import os
import tempfile
import time

import numpy as np
import trimesh
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from benchmarks._lib import (ALBEDO, CAMERA, LIGHT_INTENSITY, LIGHT_POSITION, PEERS_VENV, machine, publish,
                             relative_rmse, run_peer, seconds, sphere_meshes, sphere_scene, write_ply)
from rtmesh.core import runtime
from rtmesh.geometry.accel import Accel
from rtmesh.geometry.embree_packets import GROUP, LANES
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import DEFAULT_MAX_SPP, RenderSettings

SECTION = "Against peers: trimesh, raw Embree, Mitsuba 3"
TARGETS = (0.02, 0.01, 0.005, 0.0025, 0.001)  # relative RMSE at which times are compared
ADAPTIVE_TARGETS = (0.2, 0.1, 0.05, 0.03, 0.02)  # rtmesh target_error values of the adaptive sweep
VARIANTS = ("llvm_ad_rgb", "scalar_rgb")


def time_to_error(spps, times, errors, target):
    """Seconds to reach ``target`` error, log-log interpolated between measured spp; None
    when the sweep does not bracket it."""
    for i in range(len(spps) - 1):
        e0, e1 = errors[i], errors[i + 1]
        if e0 >= target >= e1 and e0 > e1:
            w = np.log(e0 / target) / np.log(e0 / e1)
            return float(np.exp((1 - w) * np.log(times[i]) + w * np.log(times[i + 1])))
    return None


# ---------------------------------------------------------------- 1. intersection
def intersection(scene, width, height, runs):
    """Rays/s of the intersection APIs on the pixel-centre camera rays; and a hit check."""
    ys, xs = np.mgrid[0:height, 0:width]
    film_xy = np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], axis=1)
    origins, directions = scene.camera.generate_rays(film_xy, width, height)
    origins = np.ascontiguousarray(np.broadcast_to(origins, directions.shape))
    directions = np.ascontiguousarray(directions)
    o32, d32 = origins.astype(np.float32), directions.astype(np.float32)
    accel = Accel(scene.vertices, scene.faces)
    raw = rtcore_scene.EmbreeScene(robust=True)
    TriangleMesh(raw, accel.vertices32, accel.faces)
    raw.run(o32[:1], d32[:1], query="OCCLUDED")  # commit (BVH build) outside the clock
    mesh = trimesh.Trimesh(scene.vertices, scene.faces, process=False)
    intersector = type(mesh.ray).__module__ + "." + type(mesh.ray).__name__
    mesh.ray.intersects_first(o32[:1], d32[:1])  # builds its own Embree scene
    # same answers first: closest primitive per ray
    rt_prim = accel.intersect(origins, directions).prim
    tm_prim = mesh.ray.intersects_first(origins, directions)
    agree = float(np.mean(rt_prim == tm_prim))
    tasks = {
        "rtmesh Accel.intersect": lambda: accel.intersect(origins, directions),
        "raw embreex run()": lambda: raw.run(o32, d32, output=1),
        "trimesh intersects_first": lambda: mesh.ray.intersects_first(origins, directions),
        "trimesh intersects_location": lambda: mesh.ray.intersects_location(origins, directions,
                                                                            multiple_hits=False),
    }
    times = {name: [] for name in tasks}
    for _ in range(runs):
        for name, fn in tasks.items():
            times[name].append(seconds(fn))
    return ({name: float(np.median(t)) for name, t in times.items()}, len(origins), agree, intersector,
            accel.packets)


# ---------------------------------------------------------------- 2. equal error
def rtmesh_sweep(scene, width, height, spps, runs, threads=2):
    """Images and median times of rtmesh renders at each spp (after one warm-up each)."""
    out = {}
    for spp in spps:
        integrator = Integrator(scene, RenderSettings(width=width, height=height, spp=spp,
                                                      sampler="jittered", threads=threads, seed=0))
        integrator.render()
        times, image = [], None
        for _ in range(runs):
            start = time.perf_counter()
            image = integrator.render().image
            times.append(time.perf_counter() - start)
        out[spp] = (image, float(np.median(times)))
        print(f"rtmesh spp {spp}: median {out[spp][1]:.3f} s", flush=True)
    return out


def rtmesh_adaptive_sweep(scene, width, height, targets, spp, runs, threads=2):
    """Images, median times and mean samples per pixel of adaptive rtmesh renders.

    Parameters
    ----------
    scene : rtmesh.scene.model.Scene
    width, height : int
        Image size in pixels.
    targets : list of float
        ``target_error`` of each render (rtmesh's estimated display error per pixel, see
        :class:`rtmesh.rendering.settings.RenderSettings`), one render setting per value.
    spp : int
        Samples per pixel of the first round.
    runs : int
        Timed renders per setting, after one warm-up.
    threads : int, optional

    Returns
    -------
    dict of float to tuple
        ``target -> (image, median seconds, mean spp)``; the sampler is Sobol, whose
        prefixes stay stratified across rounds (see :mod:`rtmesh.rendering.adaptive`), and no time
        limit is set, so every run of a setting takes the same samples.
    """
    out = {}
    for target in targets:
        integrator = Integrator(scene, RenderSettings(width=width, height=height, spp=spp, sampler="sobol",
                                                      threads=threads, seed=0, target_error=target))
        integrator.render()
        times, result = [], None
        for _ in range(runs):
            start = time.perf_counter()
            result = integrator.render()
            times.append(time.perf_counter() - start)
        out[target] = (result.image, float(np.median(times)), result.stats.mean_spp)
        print(f"rtmesh adaptive target_error {target:g}: median {out[target][1]:.3f} s, "
              f"{out[target][2]:.1f} spp on average", flush=True)
    return out


def throughput_rows(spps, runs, pixels):
    """Markdown rows of millions of camera samples per second, one per renderer.

    Parameters
    ----------
    spps : list of int
    runs : dict of str to dict
        ``renderer -> {spp: (image, median seconds)}``.
    pixels : int
        Pixels in the image.

    Returns
    -------
    list of str
    """
    return [f"| {name} | " + " | ".join(f"{pixels * spp / r[spp][1] / 1e6:.1f}" for spp in spps) + " |"
            for name, r in runs.items()]


def mitsuba_sweep(venv, spec_path, variant, spps, runs, reference_spp, folder):
    """Run the worker (``benchmarks/peers_mitsuba.py``) in the peers venv; images, median
    times and version (or None: no venv, or the worker failed)."""
    out_path = os.path.join(folder, f"{variant}.npz")
    args = [spec_path, variant, out_path, "--spp", ",".join(map(str, spps)), "--runs", runs]
    if reference_spp:
        args += ["--reference-spp", reference_spp]
    done = run_peer("peers_mitsuba", args, os.path.join(folder, "home"), venv)
    if done is None:
        return None
    if done.returncode != 0:
        print(f"bench_peers: Mitsuba {variant} failed: {done.stderr.strip().splitlines()[-1:]}")
        return None
    print(done.stdout, end="")
    data = np.load(out_path)
    sweep = {spp: (data[f"image_{spp}"], float(np.median(data[f"times_{spp}"]))) for spp in spps}
    return {"sweep": sweep, "version": str(data["version"]),
            "reference": data["reference"] if "reference" in data else None}


def write_mitsuba_scene(meshes, width, height, folder):
    """The scene description the Mitsuba worker reads (JSON beside one PLY per mesh);
    returns its path."""
    spec = {"width": width, "height": height, "albedo": ALBEDO, "camera": CAMERA,
            "light_position": LIGHT_POSITION, "mitsuba_intensity": np.pi * LIGHT_INTENSITY,
            "meshes": {}}
    for name, (v, f, n) in meshes.items():
        path = os.path.join(folder, f"{name}.ply")
        write_ply(path, v, f, n)
        spec["meshes"][name] = path
    spec_path = os.path.join(folder, "scene.json")
    with open(spec_path, "w") as fh:
        json.dump(spec, fh)
    return spec_path


def equal_error(meshes, scene, args, folder):
    """The equal-error study; returns the markdown lines and a dict of key numbers."""
    spec_path = write_mitsuba_scene(meshes, args.width, args.height, folder)
    if not os.path.exists(os.path.join(args.venv, "bin", "python")):
        return [f"Mitsuba skipped: no venv at {args.venv} (run `sh benchmarks/peers_setup.sh`)."], {}

    # references first: the two renderers must agree before anything is timed
    llvm = mitsuba_sweep(args.venv, spec_path, "llvm_ad_rgb", args.spp, args.runs, args.reference_spp, folder)
    if llvm is None or llvm["reference"] is None:
        return ["Mitsuba llvm_ad_rgb failed to run; see the tool's output."], {}
    rt_reference = Integrator(scene, RenderSettings(width=args.width, height=args.height,
                                                    spp=args.reference_spp, sampler="jittered",
                                                    threads=2, seed=1)).render().image
    mi_reference = llvm["reference"]
    mean_difference = float(abs(rt_reference.mean() - mi_reference.mean()) / mi_reference.mean())
    reference_rmse = relative_rmse(rt_reference, mi_reference)
    reference = 0.5 * (rt_reference.astype(np.float64) + mi_reference)
    if mean_difference > 0.01:
        raise SystemExit(f"bench_peers: rtmesh and Mitsuba disagree: mean differs by {mean_difference:.2%}")

    runs = {"rtmesh (2 threads)": rtmesh_sweep(scene, args.width, args.height, args.spp, args.runs),
            "Mitsuba llvm_ad_rgb": llvm["sweep"]}
    scalar = mitsuba_sweep(args.venv, spec_path, "scalar_rgb", args.spp, args.runs, 0, folder)
    if scalar is not None:
        runs["Mitsuba scalar_rgb"] = scalar["sweep"]
    errors = {name: [relative_rmse(r[spp][0], reference) for spp in args.spp] for name, r in runs.items()}
    times = {name: [r[spp][1] for spp in args.spp] for name, r in runs.items()}

    lines = [f"Mitsuba {llvm['version']} in `{args.venv}`; reference: mean of rtmesh at "
             f"{args.reference_spp} spp (seed 1) and Mitsuba llvm_ad_rgb at {args.reference_spp} spp.",
             f"The two references agree: mean radiance differs by {mean_difference:.3%}, relative "
             f"RMSE between them {reference_rmse:.3%} (what is left is mostly their own noise).",
             "", "| renderer | " + " | ".join(f"{s} spp: s / rel. RMSE" for s in args.spp) + " |",
             "|---|" + "---:|" * len(args.spp)]
    for name in runs:
        cells = [f"{t:.3f} / {e:.2%}" for t, e in zip(times[name], errors[name])]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += ["", "Camera samples per second (millions), from the same medians:", "",
              "| renderer | " + " | ".join(f"{s} spp" for s in args.spp) + " |",
              "|---|" + "---:|" * len(args.spp),
              *throughput_rows(args.spp, runs, args.width * args.height)]
    lines += ["", "Time to reach a relative RMSE (log-log interpolated; ratio = other / rtmesh):", "",
              "| rel. RMSE | " + " | ".join(runs) + " | " +
              " | ".join(f"{name} / rtmesh" for name in list(runs)[1:]) + " |",
              "|---:|" + "---:|" * (2 * len(runs) - 1)]
    key = {}
    for target in TARGETS:
        t = {name: time_to_error(args.spp, times[name], errors[name], target) for name in runs}
        base = t["rtmesh (2 threads)"]
        cells = [f"{v:.3f} s" if v else "n/a" for v in t.values()]
        ratios = []
        for name in list(runs)[1:]:
            ratio = t[name] / base if t[name] and base else None
            ratios.append(f"{ratio:.2f}" if ratio else "n/a")
            key[(name, target)] = ratio
        lines.append(f"| {100 * target:g}% | " + " | ".join(cells) + " | " + " | ".join(ratios) + " |")
    key["mean_difference"], key["reference_rmse"] = mean_difference, reference_rmse

    # rtmesh with adaptive sampling, against the same reference, beside Mitsuba's uniform renders
    adaptive = rtmesh_adaptive_sweep(scene, args.width, args.height, args.adaptive_targets,
                                     args.adaptive_spp, args.runs)
    adaptive_errors = [relative_rmse(adaptive[target][0], reference) for target in args.adaptive_targets]
    adaptive_times = [adaptive[target][1] for target in args.adaptive_targets]
    lines += ["", f"rtmesh with adaptive sampling (2 threads, Sobol, {args.adaptive_spp} spp in the first "
              f"round, `max_spp` {DEFAULT_MAX_SPP}, one render per `target_error`; Mitsuba's `direct` has no "
              "adaptive sampling and stays uniform):", "",
              "| target_error | mean spp | s | rel. RMSE | M samples/s |", "|---:|---:|---:|---:|---:|"]
    for target, error in zip(args.adaptive_targets, adaptive_errors):
        _, render_seconds, mean_spp = adaptive[target]
        lines.append(f"| {target:g} | {mean_spp:.1f} | {render_seconds:.3f} | {error:.3%} | "
                     f"{args.width * args.height * mean_spp / render_seconds / 1e6:.1f} |")

    # the direction: rtmesh's time over Mitsuba llvm's, at equal error
    lines += ["", "Equal-error time ratios the other way round (rtmesh / Mitsuba llvm_ad_rgb; "
              "below 1 rtmesh is faster):", "",
              "| rel. RMSE | rtmesh uniform / llvm | rtmesh adaptive / llvm | rtmesh adaptive (s) |",
              "|---:|---:|---:|---:|"]
    for target in TARGETS:
        llvm_time = time_to_error(args.spp, times["Mitsuba llvm_ad_rgb"], errors["Mitsuba llvm_ad_rgb"], target)
        uniform_time = time_to_error(args.spp, times["rtmesh (2 threads)"], errors["rtmesh (2 threads)"], target)
        adaptive_time = time_to_error(args.adaptive_targets, adaptive_times, adaptive_errors, target)
        cells = [uniform_time / llvm_time if uniform_time and llvm_time else None,
                 adaptive_time / llvm_time if adaptive_time and llvm_time else None]
        key[("rtmesh uniform / llvm", target)], key[("rtmesh adaptive / llvm", target)] = cells
        lines.append(f"| {100 * target:g}% | " + " | ".join(f"{c:.2f}" if c else "n/a" for c in cells) +
                     f" | {f'{adaptive_time:.3f}' if adaptive_time else 'n/a'} |")
    return lines, key


# ---------------------------------------------------------------- 3. threads
def thread_scaling(scene, width, height, spp, runs):
    """Median seconds of the same rtmesh render at 1 and 2 threads, interleaved."""
    integrators = {t: Integrator(scene, RenderSettings(width=width, height=height, spp=spp,
                                                       sampler="jittered", threads=t))
                   for t in (1, 2)}
    for integrator in integrators.values():
        integrator.render()
    times = {t: [] for t in integrators}
    for _ in range(runs):
        for t, integrator in integrators.items():
            times[t].append(seconds(integrator.render))
    return {t: float(np.median(v)) for t, v in times.items()}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--width", type=int, default=512)
    parser.add_argument("--height", type=int, default=512)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--spp", default="1,4,16,64", help="spp sweep (squares: Mitsuba's stratified sampler)")
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--thread-spp", type=int, default=16)
    parser.add_argument("--adaptive-targets", default=",".join(map(str, ADAPTIVE_TARGETS)),
                        help="target_error values of rtmesh's adaptive renders, decreasing")
    parser.add_argument("--adaptive-spp", type=int, default=4, help="first-round spp of the adaptive renders")
    parser.add_argument("--venv", default=PEERS_VENV, help="the peers' venv (benchmarks/peers_setup.sh)")
    parser.add_argument("--no-write", action="store_true", help="print only; leave docs/BENCHMARKS.md alone")
    args = parser.parse_args()
    args.spp = [int(s) for s in args.spp.split(",")]
    args.adaptive_targets = [float(s) for s in args.adaptive_targets.split(",")]
    # measure rtmesh as the rtmesh command runs it: in a process tuned for rendering
    runtime.tune_process()
    machine_at_start = machine()  # its load average is the one before the measurements

    meshes = sphere_meshes()
    scene = sphere_scene(meshes)
    hits, n_rays, agree, intersector, packets = intersection(scene, args.width, args.height, args.runs)
    print(hits, flush=True)
    with tempfile.TemporaryDirectory() as folder:
        error_lines, key = equal_error(meshes, scene, args, folder)
    threads = thread_scaling(scene, args.width, args.height, args.thread_spp, args.runs)

    rtmesh_rate = n_rays / hits["rtmesh Accel.intersect"]
    rows = [f"| {name} | {1e3 * t:.1f} | {n_rays / t / 1e6:.2f} | {rtmesh_rate / (n_rays / t):.2f} |"
            for name, t in hits.items()]
    words = ["python -m benchmarks.bench_peers"]
    defaults = {"width": 512, "height": 512, "runs": 5, "reference_spp": 1024, "thread_spp": 16,
                "adaptive_spp": 4, "venv": PEERS_VENV}
    for name, default in defaults.items():
        if getattr(args, name) != default:
            words.append(f"--{name.replace('_', '-')} {getattr(args, name)}")
    if args.spp != [1, 4, 16, 64]:
        words.append("--spp " + ",".join(map(str, args.spp)))
    if args.adaptive_targets != list(ADAPTIVE_TARGETS):
        words.append("--adaptive-targets " + ",".join(f"{t:g}" for t in args.adaptive_targets))
    tracing = (f"Embree packets of {LANES} rays, {GROUP}-wide queries (the CPU's native width)" if packets else
               "embreex `run()`, one ray at a time" +
               (" (`RTMESH_EMBREE=run`)" if os.environ.get("RTMESH_EMBREE", "").strip().lower() == "run" else ""))
    text = "\n".join([
        f"## {SECTION}",
        "",
        "Commands: `sh benchmarks/peers_setup.sh` (once: Mitsuba in its own venv, LLVM 19 from apt), "
        f"then `{' '.join(words)}`",
        "",
        f"- Machine: {machine_at_start}, {os.getloadavg()[0]:.1f} at the end; shared with other "
        "jobs while measuring (expect 10-20 % noise "
        "on absolute times; the ratios come from one run, measurements interleaved where they "
        "run in one process)",
        f"- Date: {datetime.date.today().isoformat()}; medians of {args.runs} runs after a warm-up",
        f"- Scene: icosphere (5 subdivisions, 20480 smooth triangles, radius 1) on a 20 x 20 "
        f"ground quad, point light at (3, -3, 6), {args.width}x{args.height}, Lambert albedo "
        f"{ALBEDO}; rtmesh intensity {LIGHT_INTENSITY:g} W/sr with kd I cos / d^2, Mitsuba "
        f"intensity pi x {LIGHT_INTENSITY:g} with its albedo / pi diffuse BSDF",
        f"- rtmesh traces with {tracing}, in a process tuned as the `rtmesh` command tunes its own",
        "",
        f"### Intersection only: {n_rays} pixel-centre camera rays, closest hit, 1 thread",
        "",
        f"trimesh's ray object is `{intersector}`; rtmesh and trimesh agree on the hit "
        f"triangle of {agree:.2%} of the rays.",
        "",
        "| API | median ms | Mrays/s | time / rtmesh |",
        "|---|---:|---:|---:|",
        *rows,
        "",
        "### Time to equal error: rtmesh vs Mitsuba 3 `direct`",
        "",
        "Both at 2 threads, stratified (jittered) pixel samples, box filter, seed 0; Mitsuba's "
        "`direct` with `emitter_samples=1, bsdf_samples=0` (a BSDF sample cannot hit a point "
        "light: it would only cost rays).  Times are whole renders (Mitsuba: `mi.render` plus "
        "the copy to NumPy; rtmesh: `Integrator.render`), scene loading excluded.",
        "",
        *error_lines,
        "",
        f"### Thread scaling: rtmesh, {args.width}x{args.height} at {args.thread_spp} spp",
        "",
        "| threads | median s | speed-up |",
        "|---:|---:|---:|",
        f"| 1 | {threads[1]:.3f} | 1.00 |",
        f"| 2 | {threads[2]:.3f} | {threads[1] / threads[2]:.2f} |",
        "",
    ])
    publish(text, SECTION, write=not args.no_write)


if __name__ == "__main__":
    main()
