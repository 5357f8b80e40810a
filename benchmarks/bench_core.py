"""Core renderer vs raw Embree: how much the NumPy side of a render costs.

Builds the benchmark scene in code (an icosphere of 20480 smooth-shaded triangles on a
ground quad, one point light), renders it with rtmesh at 1 and 2 threads, and times raw
Embree on exactly the rays rtmesh traced (camera rays and shadow rays, recorded from the
render through the Accel), at 1 thread and at 2 threads splitting the rays: once as the
very packet queries rtmesh made (the same batches through
:func:`rtmesh.geometry.embree_packets.intersect_rays` and :func:`~rtmesh.geometry.embree_packets.occluded_rays`),
and once through embreex ``run()``, one ray at a time.
Prints a table and three ratios and writes them to ``docs/BENCHMARKS.md``:

* rtmesh 1 thread / its packet queries alone, 1 thread: the overhead of everything that is
  not tracing (target: <= 1.3);
* rtmesh 1 thread / raw embreex ``run()`` 1 thread: the former overhead ratio, against
  single-ray tracing;
* rtmesh 1 thread / rtmesh 2 threads: the thread speed-up (target: >= 1.8).

A fifth measurement shows what the machine gives two threads at all: two independent
1-thread renders run side by side on two threads (each its own Integrator, nothing shared
but the process), timed until both end.  ``2 x (1-thread time) / (side-by-side time)`` is
the most two threads can speed this work up on this machine at this time; on a shared
virtual machine it moves with the neighbours' load.

Timings are medians over ``--runs`` runs after a warm-up; the measurements are
interleaved run by run so that a noisy, shared machine slows them alike.  The process is
tuned as the ``rtmesh`` command tunes its own (:func:`rtmesh.core.runtime.tune_process`: kept
render threads, a short GIL switch interval while they run, glibc keeping freed memory).

Usage::

    python -m benchmarks.bench_core [--width 512] [--height 512] [--runs 7] [--no-write]
"""

import argparse
import datetime
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from benchmarks._lib import machine, publish, seconds, sphere_scene
from rtmesh.core import runtime
from rtmesh.geometry import embree_library, embree_packets
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings

SECTION = "Core renderer vs raw Embree"


class RayRecorder:
    """Wraps an Accel's queries during one render and keeps the float32 rays they traced.

    The arrays are rebuilt the way Accel builds them (gather the rows, round to float32,
    clamp ``t_max`` to the float32 range), so they are bit for bit the rays Embree saw.
    """

    def __init__(self, accel):
        self.accel = accel
        self.camera, self.shadow = [], []
        self.calls = []  # ("intersect", o, d) or ("occluded", o, d, t): each query as made

    def __enter__(self):
        accel, intersect, occluded = self.accel, self.accel.intersect, self.accel.occluded

        def recording_intersect(origins, directions, time=None):
            self.camera.append((np.asarray(origins, np.float32), np.asarray(directions, np.float32)))
            self.calls.append(("intersect", np.array(origins), np.array(directions)))
            return intersect(origins, directions, time)

        def recording_occluded(origins, directions, t_max, rows=None, time=None):
            pick = (lambda a: a) if rows is None else (lambda a: a[rows])
            t = np.minimum(pick(t_max), np.finfo(np.float32).max).astype(np.float32)
            self.shadow.append((pick(origins).astype(np.float32), pick(directions).astype(np.float32), t))
            self.calls.append(("occluded", np.array(origins), np.array(directions), np.array(t_max),
                               np.arange(len(t_max)) if rows is None else np.asarray(rows, np.int64)))
            return occluded(origins, directions, t_max, rows, time)

        accel.intersect, accel.occluded = recording_intersect, recording_occluded
        return self

    def __exit__(self, *exc):
        del self.accel.intersect, self.accel.occluded  # back to the class methods

    def batches(self):
        """All camera rays and all shadow rays as two contiguous batches."""
        cam = tuple(np.ascontiguousarray(np.concatenate(a)) for a in zip(*self.camera))
        sha = tuple(np.ascontiguousarray(np.concatenate(a)) for a in zip(*self.shadow))
        return cam, sha


def raw_embree_runner(accel, camera_rays, shadow_rays, threads):
    """A function that traces the recorded rays with bare embreex ``run()`` calls.

    A separate Embree scene is built from the same float32 triangles (robust mode, like
    Accel).  With several threads each traces a contiguous share of both ray sets.
    """
    scene = rtcore_scene.EmbreeScene(robust=True)
    TriangleMesh(scene, accel.vertices32, accel.faces)
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), query="OCCLUDED")
    (co, cd), (so, sd, st) = camera_rays, shadow_rays
    cam_parts = np.array_split(np.arange(len(co)), threads)
    sha_parts = np.array_split(np.arange(len(so)), threads)
    shares = [(co[c[0]:c[-1] + 1], cd[c[0]:c[-1] + 1], so[s[0]:s[-1] + 1], sd[s[0]:s[-1] + 1],
               st[s[0]:s[-1] + 1]) for c, s in zip(cam_parts, sha_parts)]

    def trace(share):
        o, d, o_s, d_s, t_s = share
        scene.run(o, d, output=1)
        scene.run(o_s, d_s, dists=t_s.copy(), query="OCCLUDED")  # run() overwrites dists

    if threads == 1:
        def run():
            trace(shares[0])
    else:
        pool = ThreadPoolExecutor(max_workers=threads)

        def run():
            list(pool.map(trace, shares))
    return run


def packet_runner(accel, calls, threads):
    """A function that makes the recorded queries again, straight through the packet
    kernels on the render's own Embree scene (with several threads, the calls are dealt
    out in turn)."""
    library = embree_library.packet_library()
    flags = embree_packets.RTC_RAY_QUERY_FLAG_COHERENT
    handle = accel._shared.handle
    intersect_rays, occluded_rays = embree_packets.query_kernels()

    def trace(share):
        for call in share:
            if call[0] == "intersect":
                intersect_rays(library.intersect, handle, *embree_packets.closest_rays(call[1], call[2]), flags,
                               accel._face_offset)
            else:
                occluded_rays(library.occluded, handle, *embree_packets.shadow_rays(call[1], call[2], call[3]),
                              call[4], flags)

    shares = [calls[i::threads] for i in range(threads)]
    if threads == 1:
        return lambda: trace(shares[0])
    pool = ThreadPoolExecutor(max_workers=threads)
    return lambda: list(pool.map(trace, shares))


def command(args):
    """The command line that reproduces this run (non-default options only)."""
    words = ["python -m benchmarks.bench_core"]
    for name, default in (("width", 512), ("height", 512), ("runs", 7)):
        if getattr(args, name) != default:
            words.append(f"--{name} {getattr(args, name)}")
    return " ".join(words)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--width", type=int, default=512)
    parser.add_argument("--height", type=int, default=512)
    parser.add_argument("--runs", type=int, default=7, help="timed runs per measurement (>= 5 advised)")
    parser.add_argument("--no-write", action="store_true", help="print only; leave docs/BENCHMARKS.md alone")
    args = parser.parse_args()
    # measure rtmesh as the rtmesh command runs it: in a process tuned for rendering
    runtime.tune_process()

    scene = sphere_scene(peer=False)
    integrators = {
        threads: Integrator(scene, RenderSettings(width=args.width, height=args.height, spp=1,
                                                  sampler="regular", threads=threads))
        for threads in (1, 2)
    }
    # the rays are recorded from a render on the general path (the fused direct-lighting
    # stage traces its packets inside one kernel, out of the recorder's reach): the same camera
    # and shadow rays, though its shadow packets are fuller (lit rows compacted) than the fused
    # stage's (the lit lanes of each camera packet), so the replay slightly flatters Embree
    one = Integrator(scene, integrators[1].settings)
    one.direct_stage = None
    with RayRecorder(one.accel) as recorder:
        reference = one.render()
    one = integrators[1]
    camera_rays, shadow_rays = recorder.batches()
    assert len(camera_rays[0]) == args.width * args.height
    assert len(shadow_rays[0]) == reference.stats.rays["shadow"]
    raw = {threads: raw_embree_runner(recorder.accel, camera_rays, shadow_rays, threads) for threads in (1, 2)}
    packets = {threads: packet_runner(recorder.accel, recorder.calls, threads) for threads in (1, 2)} \
        if one.accel.packets else {}

    pair_pool = ThreadPoolExecutor(max_workers=2)
    pair = [integrators[1], Integrator(scene, integrators[1].settings)]

    def side_by_side():
        # the switch interval of a multi-threaded render, so that only the sharing differs
        with runtime.gil_handoff(2):
            list(pair_pool.map(lambda integrator: integrator.render(), pair))

    measurements = {
        "rtmesh, 1 thread": lambda: integrators[1].render(),
        "rtmesh, 2 threads": lambda: integrators[2].render(),
        "raw embreex run(), 1 thread": raw[1],
        "raw embreex run(), 2 threads": raw[2],
        "two 1-thread renders side by side": side_by_side,
    }
    if packets:
        measurements["rtmesh's packet queries alone, 1 thread"] = packets[1]
        measurements["rtmesh's packet queries alone, 2 threads"] = packets[2]
    for fn in measurements.values():  # warm-up
        fn()
    times = {name: [] for name in measurements}
    stages = []
    for _ in range(args.runs):
        for name, fn in measurements.items():
            times[name].append(seconds(fn))
        stages.append(integrators[1].render().stats.stage_seconds)
    median = {name: float(np.median(t)) for name, t in times.items()}
    best = {name: float(np.min(t)) for name, t in times.items()}
    stage_median = {k: float(np.median([s[k] for s in stages])) for k in stages[0]}

    n_cam, n_shadow = len(camera_rays[0]), len(shadow_rays[0])
    overhead = median["rtmesh, 1 thread"] / median["raw embreex run(), 1 thread"]
    packet_key = "rtmesh's packet queries alone, 1 thread"
    packet_overhead = median["rtmesh, 1 thread"] / median[packet_key] if packets else float("nan")
    speedup = median["rtmesh, 1 thread"] / median["rtmesh, 2 threads"]
    # the same ratios within each interleaved run: their spread shows how much a shared
    # machine's speed moved during the measurement
    t = {name: np.array(v) for name, v in times.items()}
    per_run = {
        "overhead": t["rtmesh, 1 thread"] / t["raw embreex run(), 1 thread"],
        "speedup": t["rtmesh, 1 thread"] / t["rtmesh, 2 threads"],
        "embree speedup": t["raw embreex run(), 1 thread"] / t["raw embreex run(), 2 threads"],
        "capacity": 2 * t["rtmesh, 1 thread"] / t["two 1-thread renders side by side"],
        "packet overhead": t["rtmesh, 1 thread"] / t[packet_key] if packets else np.full(args.runs, np.nan),
    }
    capacity = 2 * median["rtmesh, 1 thread"] / median["two 1-thread renders side by side"]
    spread = {k: f"{np.median(v):.2f} ({v.min():.2f}-{v.max():.2f})" for k, v in per_run.items()}
    rays_per_run = {name: (2 if name.startswith("two") else 1) * (n_cam + n_shadow) for name in median}
    rows = [f"| {name} | {1e3 * t:.1f} | {1e3 * best[name]:.1f} | {rays_per_run[name] / t / 1e6:.2f} |"
            for name, t in median.items()]
    stage_text = ", ".join(f"{k} {1e3 * v:.1f}" for k, v in stage_median.items() if v > 0)
    text = "\n".join([
        f"## {SECTION}",
        "",
        f"Command: `{command(args)}`",
        "",
        f"- Machine: {machine()}",
        f"- Date: {datetime.date.today().isoformat()}",
        f"- Scene: icosphere (5 subdivisions, 20480 smooth triangles) on a 2-triangle ground quad, "
        f"one point light, {args.width}x{args.height}, 1 spp (regular sampler), max depth 5 "
        f"(no reflective materials, so only camera and shadow rays)",
        f"- Rays: {n_cam} camera + {n_shadow} shadow; raw Embree traces exactly these "
        f"(recorded from the render): as rtmesh's packet queries (the same batches; 2 threads take "
        f"every other batch) and through embreex run() (2 threads each take half)",
        f"- Median of {args.runs} runs after a warm-up, the measurements interleaved",
        "",
        "| measurement | median ms | best ms | Mrays/s (median) |",
        "|---|---:|---:|---:|",
        *rows,
        "",
        f"- Tracing: {f'Embree packets of {embree_packets.LANES} rays, {embree_packets.GROUP}-wide queries (coherent)' if packets else 'embreex run() (packets unavailable)'}; "
        f"{'the fused direct-lighting stage' if one.direct_stage is not None else 'the general wavefront'} renders",
        f"- rtmesh 1 thread / its packet queries alone, 1 thread: **{packet_overhead:.2f}** (target <= 1.3); "
        f"per run {spread['packet overhead']}",
        f"- rtmesh 1 thread / raw embreex run() 1 thread (the former ratio): **{overhead:.2f}**; "
        f"from best times {best['rtmesh, 1 thread'] / best['raw embreex run(), 1 thread']:.2f}",
        f"- rtmesh 1 thread / rtmesh 2 threads: **{speedup:.2f}** (target >= 1.85); "
        f"raw Embree 1 / 2 threads: {median['raw embreex run(), 1 thread'] / median['raw embreex run(), 2 threads']:.2f}",
        f"- What the machine gives two threads: two independent 1-thread renders side by side ran "
        f"{capacity:.2f}x the throughput of one (2 x 1-thread time / side-by-side time); rtmesh's "
        f"2-thread speed-up is {speedup / capacity:.2f} of that",
        f"- Per-run ratios, median (range) over the {args.runs} interleaved runs: rtmesh / raw Embree "
        f"{spread['overhead']}; rtmesh 2-thread speed-up {spread['speedup']}; raw Embree 2-thread "
        f"speed-up {spread['embree speedup']}; side-by-side throughput {spread['capacity']}",
        f"- rtmesh 1-thread stage times, ms: {stage_text}",
        "",
    ])
    publish(text, SECTION, write=not args.no_write)


if __name__ == "__main__":
    main()
