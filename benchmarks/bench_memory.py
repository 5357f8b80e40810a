"""Peak memory of a render as resolution x spp rise: bounded by the chunk size, not the image.

A render holds the film (per-pixel sums: 56 bytes per pixel, plus the 12-byte float32
image for a render without adaptive rounds, which fills it as chunks are added: the only
part that has to grow with the resolution) and, while chunks are rendered, the temporaries
of one chunk per thread.  This tool renders the benchmark scene of ``benchmarks/bench_core.py``
(:func:`benchmarks._lib.sphere_scene`) at rising resolution x spp, each point in a fresh
process, and reports

* ``film``: bytes of the film's arrays;
* ``chunk phase``: tracemalloc's peak (NumPy reports its buffers to tracemalloc) from the
  start of the render to the last chunk added to the film, minus the film: everything
  the chunks in flight hold.  It must stay flat as resolution x spp grows;
* ``finish phase``: the peak while the image, the error estimate and the passes are formed
  from the film, minus the film (an adaptive render's float32 image is made here, 12
  bytes per pixel);
* ``peak RSS``: the process's maximum resident set size (``ru_maxrss``), and how much it
  grew during the render.

Usage::

    python -m benchmarks.bench_memory [--points 512x512x1,3840x2160x64] [--threads 2] [--no-write]

The default grid ends with 3840 x 2160 at 64 spp (530 M samples: minutes on two cores).
"""

import argparse
import datetime
import json
import os
import resource
import subprocess
import sys
import time
import tracemalloc

from benchmarks._lib import ROOT, machine, publish, sphere_scene
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings

SECTION = "Peak memory against resolution x spp"
DEFAULT_POINTS = "512x512x1,512x512x16,1920x1080x4,3840x2160x1,3840x2160x4,3840x2160x16,3840x2160x64"


def film_bytes(film):
    """Bytes held by a Film (:attr:`rtmesh.rendering.film.Film.nbytes`)."""
    return film.nbytes


def traced_render(integrator, progress_delay=0.0):
    """Render under tracemalloc and split the peak memory into film, chunk and finish phases.

    Parameters
    ----------
    integrator : Integrator
    progress_delay : float
        Seconds the progress callback sleeps after each chunk, in s: a slow consumer, under
        which chunk results would pile up if the integrator did not bound them.

    Returns
    -------
    dict
        ``film``, ``chunk_phase``, ``finish_phase`` (bytes) and ``result`` (RenderResult).
    """
    was_tracing = tracemalloc.is_tracing()
    if not was_tracing:
        tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    chunk_peak = []

    def progress(done, total):
        if done == total:
            chunk_peak.append(tracemalloc.get_traced_memory()[1])
            tracemalloc.reset_peak()
        elif progress_delay:
            time.sleep(progress_delay)

    try:
        result = integrator.render(progress)
        finish_peak = tracemalloc.get_traced_memory()[1]
    finally:
        if not was_tracing:
            tracemalloc.stop()
    film = film_bytes(result.film)
    return {"film": film, "chunk_phase": chunk_peak[0] - base - film,
            "finish_phase": finish_peak - base - film, "result": result}


def current_rss():
    """Resident set size of this process now, bytes (Linux)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def measure_point(width, height, spp, threads, chunk_samples):
    """One grid point, in this process (meant to be a fresh one); a dict of numbers."""
    integrator = Integrator(sphere_scene(peer=False), RenderSettings(
        width=width, height=height, spp=spp, sampler="jittered", threads=threads,
        chunk_samples=chunk_samples))
    rss_before = current_rss()
    start = time.perf_counter()
    traced = traced_render(integrator)
    seconds = time.perf_counter() - start
    peak_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # KiB on Linux
    return {"width": width, "height": height, "spp": spp, "seconds": seconds,
            "film": traced["film"], "chunk_phase": traced["chunk_phase"],
            "finish_phase": traced["finish_phase"], "rss_before": rss_before,
            "peak_rss": peak_rss}


def parse_points(text):
    """``"WxHxSPP,..."`` -> list of (width, height, spp)."""
    points = []
    for item in text.split(","):
        try:
            w, h, spp = (int(x) for x in item.lower().split("x"))
        except ValueError:
            raise SystemExit(f"bench_memory: bad point {item!r}; expected WIDTHxHEIGHTxSPP")
        points.append((w, h, spp))
    return points


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", default=DEFAULT_POINTS, help="WIDTHxHEIGHTxSPP,... (each in a fresh process)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--chunk-samples", type=int, default=RenderSettings.chunk_samples)
    parser.add_argument("--one", action="store_true", help=argparse.SUPPRESS)  # child process
    parser.add_argument("--no-write", action="store_true", help="print only; leave docs/BENCHMARKS.md alone")
    args = parser.parse_args()
    points = parse_points(args.points)
    if args.one:
        print(json.dumps(measure_point(*points[0], args.threads, args.chunk_samples)))
        return

    mb = 1e-6
    rows = []
    for w, h, spp in points:
        child = subprocess.run([sys.executable, "-m", "benchmarks.bench_memory", "--one",
                                "--points", f"{w}x{h}x{spp}", "--threads", str(args.threads),
                                "--chunk-samples", str(args.chunk_samples)],
                               capture_output=True, text=True, check=True, cwd=ROOT)
        r = json.loads(child.stdout.strip().splitlines()[-1])
        row = (f"| {w}x{h} | {spp} | {w * h * spp / 1e6:.1f} | {r['seconds']:.1f} | {r['film'] * mb:.0f} "
               f"| {r['film'] / (w * h):.0f} | {r['chunk_phase'] * mb:.1f} | {r['finish_phase'] * mb:.1f} "
               f"| {r['peak_rss'] * mb:.0f} | {(r['peak_rss'] - r['rss_before']) * mb:.0f} |")
        print(row, flush=True)
        rows.append(row)

    command = "python -m benchmarks.bench_memory"
    if args.points != DEFAULT_POINTS:
        command += f" --points {args.points}"
    if args.threads != 2:
        command += f" --threads {args.threads}"
    text = "\n".join([
        f"## {SECTION}",
        "",
        f"Command: `{command}`",
        "",
        f"- Machine: {machine()}, shared with other jobs (timings are indicative only)",
        f"- Date: {datetime.date.today().isoformat()}",
        f"- Scene: the core benchmark scene (icosphere of 20480 smooth triangles on a ground quad, "
        f"one point light), jittered sampler, {args.threads} threads, chunk_samples "
        f"{args.chunk_samples}; every point in a fresh process, under tracemalloc",
        "- chunk phase: tracemalloc peak up to the last chunk on the film, minus the film; "
        "finish phase: peak while the image and error estimate are formed, minus the film; "
        "RSS growth: peak RSS minus RSS before the render",
        "",
        "| image | spp | M samples | seconds | film MB | film B/pixel | chunk phase MB "
        "| finish phase MB | peak RSS MB | RSS growth MB |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        *rows,
        "",
    ])
    publish(text, SECTION, write=not args.no_write)


if __name__ == "__main__":
    main()
