"""Equal-error time: rtmesh's path integrator against Mitsuba 3 ``path`` on the Duck (issue 27).

What is rendered
----------------
The scene of benchmarks/bench_pbr_peers.py's ``duck-env-*`` cases, built by its functions:

- geometry: the triangles and vertex normals of ``Duck.glb`` (``../shared/assets/real/``),
  centred on its bounding box and scaled so its largest half-extent is 1; Mitsuba reads the
  triangles and normals rtmesh built from the file (a float32 PLY);
- material: ONE glTF ``pbrMetallicRoughness`` material of bench_pbr_peers' set written into
  the GLB rtmesh reads (default ``dielectric``: metallic 0, base colour (0.8, 0.298, 0.2) as
  the file stores it, roughness 0.3; ``--material``, ``--roughness``); Mitsuba renders the
  same BRDF, the glTF Appendix B model written as a Mitsuba BSDF in Python
  (benchmarks/peers_mitsuba_pbr.py ``GltfBSDF``: traced into Mitsuba's LLVM kernels, it renders
  as fast as Mitsuba's ``principled``, 0.24-0.26 s for both at 16 spp here, so no stand-in is
  needed).  The Duck's own textured material is not used;
- light: ``rtmesh/scene/studio.exr`` as the only light: rtmesh ``lights = []``,
  ``[environment] ambient = 0``, ``[background]`` the exr with ``lighting = true``; Mitsuba an
  ``envmap`` of the same radiance function (bench_pbr_peers ``mitsuba_environment_image``,
  rotated +90 degrees about +Y), ``hide_emitters = false``: the background is seen in both;
- camera: bench_pbr_peers' (from (0, 0.6, 3.6) toward the origin, +Y up, 36 degree vertical
  field of view), ``--size`` 256 x 256, box filter (each sample counts in its own pixel);
- transport: one indirect bounce, rtmesh ``[render] integrator = "path"``, ``max_depth = 2``
  (segments after the camera ray), Mitsuba ``path`` with ``max_depth = 3``;
- threads: 2 for both (``threads = 2``; Dr.Jit ``set_thread_count(2)``);
- samplers: rtmesh ``jittered`` (its default) and ``sobol`` (``--samplers``); Mitsuba
  ``stratified`` and ``independent`` (its default) (``--mitsuba-samplers``).

Error and time
--------------
Each configuration renders the image with two seeds A and B (rtmesh 1 and 2, Mitsuba 1 and 2)
at each of ``--spp`` (default 16 and 64 samples a pixel).  The error of one render is

    e = RMSE(A - B) / sqrt(2) / mean((A + B) / 2)

over every pixel and channel of the 256 x 256 image, the duck and the background (the
headline; the column "object" gives the same over the pixels fully covered by the duck,
bench_pbr_peers ``object_mask``, divided by their own mean).  Times are wall-clock seconds of
one render call, scene loading and process start-up excluded (rtmesh: ``rtmesh.render`` on a
loaded scene, its ``Integrator`` construction included, ~0.03 s; Mitsuba: ``mi.render`` plus
the copy of the image to NumPy, in a worker process that stays up, benchmarks/peers_mitsuba_equal_error.py).
Before the clock runs, every configuration renders once at each spp level (Mitsuba compiles
its kernels then, rtmesh loads its compiled ones); then ``--runs`` rounds each render both
seeds of every configuration, rtmesh and Mitsuba alternating render by render (the machine
is shared: load drifts hit both alike); the time of a configuration at an spp level is the
median of its ``runs x 2`` renders.

Extrapolation (:func:`time_to_error`): the error follows ``e = c spp^-k`` through the
measured levels (least squares in log-log; exactly through two levels), ``k`` is reported
(0.5 for independent samples; more where a sampler stratifies); the time follows
``t = a + b spp`` (least squares, ``a >= 0``: a render's fixed cost and its cost per sample).
The spp a target error needs, ``(c / e)^(1/k)``, may be fractional and lie outside the
measured levels (extrapolated).  Ratios are rtmesh / Mitsuba seconds at 8, 4 and 2 % (issue
27's target: the worst of the three <= 0.5); the headline pairs each renderer's faster
sampler at 2 %, and every pairing is in the table.

Usage::

    python -m benchmarks.bench_equal_error [--spp 16,64] [--runs 3] [--threads 2] [--size 256]
        [--material dielectric] [--roughness 0.3] [--samplers jittered,sobol]
        [--mitsuba-samplers stratified,independent] [--variant llvm_ad_rgb]
        [--venv /tmp/peers-venv] [--no-write]

Mitsuba runs in its own venv (``sh benchmarks/peers_setup.sh``; ``--venv``, default
``$RTMESH_PEERS_VENV`` or ``/tmp/peers-venv``).  ``--no-write`` prints the section only;
otherwise it replaces its section of docs/BENCHMARKS.md.
"""

import argparse
import datetime
import json
import math
import os
import sys
import tempfile
import time
import types

import numpy as np

import rtmesh
from benchmarks import bench_pbr_peers as pbr
from benchmarks._lib import PEERS_VENV, machine, publish, relative_rmse, rtmesh_commit, start_peer
from rtmesh.core import runtime

SECTION = "Equal-error time against Mitsuba 3 `path`: the Duck under the studio map"
TARGETS = (0.08, 0.04, 0.02)
RTMESH_SEEDS = (1, 2)
MITSUBA_SEEDS = (1, 2)
# Mitsuba samplers that round the sample count up to a square (with a warning)
SQUARE_SAMPLERS = {"stratified", "multijitter"}
MAX_DEPTH = 2  # rtmesh: segments after the camera ray; Mitsuba's max_depth is this + 1


# how to read the tables, for docs/BENCHMARKS.md (what the code and first runs showed; the
# numbers of a run are in its tables)
NOTES = (
    "How to read it:",
    "",
    "- Both renderers render the same expected image: the image means agree to about 0.1 % "
    "(column `image mean`).",
    "- rtmesh's samplers make no difference under `path`: `jittered` and `sobol` give the same errors "
    "and the exponent k = 0.50 of independent samples. The path kernel draws its light choice, light "
    "point, lobe, BSDF direction and roulette numbers from `rtmesh.sampling.hashing.uniform` of the "
    "sample's key and a dimension (rtmesh/rendering/path_kernel.py); the sampler places only the pixel "
    "position. Mitsuba's `independent` sampler (nothing stratified) is in the same situation and its "
    "errors match rtmesh's within 5 % at equal spp; its `stratified` sampler stratifies every dimension (k near "
    "0.6 between 16 and 64 spp) and needs 3-4.5x fewer samples for 8-2 %.",
    "- So the table splits the gap in two: `rtmesh / Mitsuba independent` is the cost of a sample "
    "(equal noise per sample; rtmesh's `M samples/s` against Mitsuba's), `Mitsuba independent / "
    "stratified` (the ratio of their rows) what stratified sample dimensions win. Issue 27's 0.5x "
    "needs both: per-sample cost at or below Mitsuba's and stratified (or low-discrepancy) light and "
    "BSDF dimensions in the path kernel.",
    "- The noise is direct light (next-event estimation of the map and BSDF sampling, MIS): with "
    "`max_depth = 1` (direct light only) rtmesh's error at 16 spp was 22.3 % against 22.4 % with one "
    "bounce (Mitsuba stratified 12.9 % against 13.7 %). rtmesh's `light_samples` (4) does not apply to "
    "the environment under `path`: 1 and 4 give the same image.",
    "- The rtmesh fixed cost `a` of the time fit is noise of the shared machine: a 1-spp render takes "
    "0.13-0.19 s, time grows in proportion to spp; the extrapolation to 2 % (about 2000 spp for rtmesh) "
    "rests on the cost per sample.",
)


# ---------------------------------------------------------------- the numbers
def seed_error(a, b, mask=None):
    """Relative RMSE of one render from two renders of different seeds.

    ``RMSE(a - b) / sqrt(2) / mean((a + b) / 2)``, over ``mask``'s pixels (all when None) and
    the channels: the noise of one render, relative to the image's mean.
    """
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    mean_image = 0.5 * (a + b)
    mean = float(mean_image.mean() if mask is None else mean_image[mask].mean())
    return relative_rmse(a, b, mask=mask, mean=mean) / math.sqrt(2.0)


def power_law(spps, errors):
    """Fit ``error = c spp^-k`` by least squares in log-log.

    Returns
    -------
    c, k : float
        ``k`` is 0.5 for independent samples.
    """
    x, y = np.log(np.asarray(spps, np.float64)), np.log(np.asarray(errors, np.float64))
    if len(x) < 2 or np.ptp(x) == 0:
        raise ValueError("the error's exponent needs two or more distinct spp levels")
    slope, intercept = np.polyfit(x, y, 1)
    return float(math.exp(intercept)), float(-slope)


def cost_line(spps, seconds):
    """Fit ``seconds = a + b spp`` by least squares with ``a >= 0``.

    Returns
    -------
    a, b : float
        Fixed seconds of a render and seconds per sample a pixel.
    """
    s, t = np.asarray(spps, np.float64), np.asarray(seconds, np.float64)
    if len(s) >= 2 and np.ptp(s) > 0:
        b, a = np.polyfit(s, t, 1)
        if a >= 0.0 and b > 0.0:
            return float(a), float(b)
    # no fixed cost (or one spp level): time proportional to spp
    return 0.0, float(np.sum(s * t) / np.sum(s * s))


def time_to_error(spps, seconds, errors, target):
    """Seconds and spp to reach a relative error, extrapolated from measured spp levels.

    Parameters
    ----------
    spps, seconds, errors : sequences of float
        Per measured level: samples a pixel, seconds of one render, its relative error.
    target : float
        Relative error to reach.

    Returns
    -------
    dict
        ``spp`` (fractional: ``(c / target)^(1/k)``), ``seconds`` (``a + b spp``),
        ``exponent`` (``k``), ``extrapolated`` (True when ``spp`` lies outside the levels);
        see :func:`power_law` and :func:`cost_line`.
    """
    c, k = power_law(spps, errors)
    if k <= 0.0:
        raise ValueError(f"the error does not fall with spp (exponent {k:.3f})")
    spp = (c / target) ** (1.0 / k)
    a, b = cost_line(spps, seconds)
    return {"spp": spp, "seconds": a + b * spp, "exponent": k,
            "extrapolated": not min(spps) <= spp <= max(spps)}


# ---------------------------------------------------------------- the renderers
class Mitsuba:
    """The Mitsuba worker process (benchmarks/peers_mitsuba_equal_error.py), kept up between renders."""

    def __init__(self, job_path, args, folder):
        self.folder = folder
        self.process = start_peer("peers_mitsuba_equal_error", [job_path, args.variant, args.threads],
                                  os.path.join(folder, "home"), args.venv)
        if self.process is None:
            raise SystemExit(f"bench_equal_error: no Mitsuba venv at {args.venv} (sh benchmarks/peers_setup.sh)")
        self.version = self.answer("ready")[0]

    def answer(self, word):
        """The words after ``word`` on the worker's next line starting with it (Mitsuba's own
        log lines, which it prints on stdout, are passed to stderr)."""
        for line in self.process.stdout:
            words = line.split()
            if words and words[0] == word:
                return words[1:]
            print(f"  Mitsuba: {line.rstrip()}", file=sys.stderr, flush=True)
        raise SystemExit(f"bench_equal_error: the Mitsuba worker ended (exit status {self.process.wait()})")

    def render(self, sampler, spp, seed):
        out = os.path.join(self.folder, "mitsuba.npy")
        self.process.stdin.write(f"{sampler} {spp} {seed} {out}\n")
        return float(self.answer("done")[0]), np.load(out)

    def close(self):
        self.process.stdin.close()
        self.process.wait()


def rtmesh_render(scene, settings, sampler, spp, seed, threads):
    """Seconds of one rtmesh render on a loaded scene, and its image."""
    start = time.perf_counter()
    image = rtmesh.render(scene, settings, spp=spp, seed=seed, threads=threads, sampler=sampler).image
    return time.perf_counter() - start, np.asarray(image)


def measure(configs, spps, runs):
    """Warm up, then time every configuration, alternating them render by render.

    Parameters
    ----------
    configs : dict of str to (callable, seeds)
        ``render(spp, seed) -> (seconds, image)`` and the two seeds, by name.

    Returns
    -------
    dict of str to dict of int to dict
        Per configuration and spp: ``times`` (every timed render) and ``images`` (by seed,
        from the first round).
    """
    results = {name: {spp: {"times": [], "images": {}} for spp in spps} for name in configs}
    for spp in spps:
        for name, (render, seeds) in configs.items():
            seconds, _ = render(spp, 0)  # warm-up: kernels compiled or loaded, memory touched
            print(f"  warm-up {name} {spp} spp: {seconds:.2f} s", flush=True)
        for run in range(runs):
            for i in range(2):
                for name, (render, seeds) in configs.items():
                    seconds, image = render(spp, seeds[i])
                    results[name][spp]["times"].append(seconds)
                    if run == 0:
                        results[name][spp]["images"][seeds[i]] = image
                    print(f"  {name} {spp} spp seed {seeds[i]}: {seconds:.3f} s", flush=True)
    return results


# ---------------------------------------------------------------- the report
def summarise(results, spps, seeds_of, mask, pixels):
    """Per configuration: the levels' median seconds and errors, and the times to each target."""
    rows = {}
    for name, levels in results.items():
        a, b = seeds_of[name]
        level_rows = []
        for spp in spps:
            images = levels[spp]["images"]
            level_rows.append({"spp": spp, "seconds": float(np.median(levels[spp]["times"])),
                               "error": seed_error(images[a], images[b]),
                               "object_error": seed_error(images[a], images[b], mask),
                               "mean": float(0.5 * (images[a].mean() + images[b].mean()))})
        for r in level_rows:
            r["msamples_per_s"] = r["spp"] * pixels / r["seconds"] / 1e6
        fit = {t: time_to_error(spps, [r["seconds"] for r in level_rows], [r["error"] for r in level_rows], t)
               for t in TARGETS}
        rows[name] = {"levels": level_rows, "targets": fit}
    return rows


def report(rows, rt_names, mi_names, args, context):
    """The BENCHMARKS.md section."""
    lines = [f"## {SECTION}", "",
             f"Command: `{context['command']}` (Mitsuba in its own venv, `sh benchmarks/peers_setup.sh`); "
             "the scene, the error and the extrapolation are in the script's docstring.", "",
             f"- Date {context['date']}; rtmesh {context['rtmesh']}, Mitsuba {context['mitsuba']} "
             f"`{args.variant}`; {context['machine']}",
             f"- /proc/loadavg at the start `{context['load_start']}`, at the end `{context['load_end']}` "
             f"(2 cores shared with other jobs; {context['wall']:.0f} s in all)",
             f"- Duck.glb (unit half-extent), glTF material `{args.material}` roughness {args.roughness:g} "
             f"(Mitsuba: the same BRDF, `GltfBSDF`), studio.exr the only light, {args.size} x {args.size}, "
             f"box filter, {args.threads} threads; rtmesh `path` max_depth {MAX_DEPTH}, Mitsuba `path` "
             f"max_depth {MAX_DEPTH + 1}; seeds rtmesh {RTMESH_SEEDS}, Mitsuba {MITSUBA_SEEDS}; times are "
             f"medians of {args.runs} x 2 renders, alternating renderers",
             "- error = RMSE(A - B) / sqrt(2) / mean, over all pixels (duck and background); `object`: over "
             f"the {context['object_pixels']} pixels fully on the duck, over their mean",
             "",
             "Measured:", "",
             "| renderer, sampler | spp | s (median) | M samples/s | error | object error | image mean |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for name, row in rows.items():
        for r in row["levels"]:
            lines.append(f"| {name} | {r['spp']} | {r['seconds']:.3f} | {r['msamples_per_s']:.2f} | "
                         f"{r['error']:.2%} | {r['object_error']:.2%} | {r['mean']:.4f} |")
    lines += ["", "Time to reach each error (spp from the fitted `error = c spp^-k`, seconds from "
              "`a + b spp`; `*`: outside the measured spp):", "",
              "| renderer, sampler | k | " + " | ".join(f"{t:.0%}: spp / s" for t in TARGETS) + " |",
              "|---|---:|" + "---:|" * len(TARGETS)]
    for name, row in rows.items():
        cells = [f"{f['spp']:.0f}{'*' if f['extrapolated'] else ''} / {f['seconds']:.2f}"
                 for f in row["targets"].values()]
        lines.append(f"| {name} | {row['targets'][TARGETS[0]]['exponent']:.2f} | " + " | ".join(cells) + " |")
    lines += ["", "rtmesh / Mitsuba seconds at equal error (issue 27's target: worst <= 0.5):", "",
              "| rtmesh | Mitsuba | " + " | ".join(f"{t:.0%}" for t in TARGETS) + " | worst |",
              "|---|---|" + "---:|" * (len(TARGETS) + 1)]
    for rt in rt_names:
        for mi_name in mi_names:
            ratios = [rows[rt]["targets"][t]["seconds"] / rows[mi_name]["targets"][t]["seconds"] for t in TARGETS]
            lines.append(f"| {rt} | {mi_name} | " + " | ".join(f"{x:.2f}" for x in ratios)
                         + f" | **{max(ratios):.2f}** |")
    best_rt = min(rt_names, key=lambda n: rows[n]["targets"][TARGETS[-1]]["seconds"])
    best_mi = min(mi_names, key=lambda n: rows[n]["targets"][TARGETS[-1]]["seconds"])
    worst = max(rows[best_rt]["targets"][t]["seconds"] / rows[best_mi]["targets"][t]["seconds"] for t in TARGETS)
    lines += ["", f"Headline (each renderer's faster sampler at 2 %: {best_rt} against {best_mi}): worst ratio "
              f"**{worst:.2f}** (target <= 0.5).", "", *NOTES, ""]
    return "\n".join(lines), worst


# ---------------------------------------------------------------- main
def loadavg():
    """/proc/loadavg's first three numbers, or '?'."""
    try:
        with open("/proc/loadavg") as f:
            return " ".join(f.read().split()[:3])
    except OSError:
        return "?"


def parse_list(text, kind=str):
    return [kind(x.strip()) for x in text.split(",") if x.strip()]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spp", default="16,64", help="comma-separated spp levels (two or more)")
    parser.add_argument("--runs", type=int, default=3, help="rounds of timed renders (each renders both seeds)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--size", type=int, default=256, help="image width and height")
    parser.add_argument("--material", default="dielectric", choices=sorted(pbr.MATERIALS))
    parser.add_argument("--roughness", type=float, default=0.3)
    parser.add_argument("--samplers", default="jittered,sobol", help="rtmesh samplers")
    parser.add_argument("--mitsuba-samplers", default="stratified,independent", help="Mitsuba sampler plugins")
    parser.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant")
    parser.add_argument("--venv", default=PEERS_VENV, help="the peers' venv (benchmarks/peers_setup.sh)")
    parser.add_argument("--no-write", action="store_true", help="print only; leave docs/BENCHMARKS.md alone")
    args = parser.parse_args(argv)
    spps = sorted(set(parse_list(args.spp, int)))
    if len(spps) < 2 or spps[0] < 1:
        parser.error("--spp needs two or more positive levels")
    rt_samplers, mi_samplers = parse_list(args.samplers), parse_list(args.mitsuba_samplers)
    if set(mi_samplers) & SQUARE_SAMPLERS and any(math.isqrt(s) ** 2 != s for s in spps):
        parser.error(f"Mitsuba's {', '.join(sorted(set(mi_samplers) & SQUARE_SAMPLERS))} sampler rounds spp up "
                     "to a square: give square --spp levels (e.g. 16,64)")
    load_start, machine_start, started = loadavg(), machine(), time.perf_counter()
    runtime.tune_process()

    case = pbr.Case(f"duck-env-{args.material}-r{args.roughness:g}", "duck", "env", args.material,
                    args.roughness, ("gltf",))
    with tempfile.TemporaryDirectory(prefix="rtmesh-equal-error-") as folder:
        options = types.SimpleNamespace(size=args.size, spp=spps[0], mitsuba_spp=2 * spps[0], point_spp=spps[0],
                                        mitsuba_point_spp=2 * spps[0], variant=args.variant, cache=folder)
        prepared = pbr.prepare(case, folder, options, integrator="path", max_depth=MAX_DEPTH)
        job = pbr.mitsuba_job(case, "gltf", prepared, options)
        job.update(max_depth=MAX_DEPTH + 1, samplers=mi_samplers)
        job_path = os.path.join(folder, "mitsuba_job.json")
        with open(job_path, "w") as f:
            json.dump(job, f)
        scene, settings = prepared["scene"], prepared["settings"]
        mitsuba = Mitsuba(job_path, args, folder)
        try:
            configs = {}
            # alternate: rtmesh, Mitsuba, rtmesh, Mitsuba, ...
            for i in range(max(len(rt_samplers), len(mi_samplers))):
                if i < len(rt_samplers):
                    s = rt_samplers[i]
                    configs[f"rtmesh {s}"] = (lambda spp, seed, s=s: rtmesh_render(scene, settings, s, spp, seed,
                                                                                   args.threads), RTMESH_SEEDS)
                if i < len(mi_samplers):
                    s = mi_samplers[i]
                    configs[f"Mitsuba {s}"] = (lambda spp, seed, s=s: mitsuba.render(s, spp, seed), MITSUBA_SEEDS)
            seeds_of = {name: seeds for name, (_, seeds) in configs.items()}
            results = measure(configs, spps, args.runs)
        finally:
            mitsuba.close()
    rows = summarise(results, spps, seeds_of, prepared["mask"], args.size * args.size)
    words = ["python -m benchmarks.bench_equal_error"]
    defaults = {"spp": "16,64", "runs": 3, "threads": 2, "size": 256, "material": "dielectric", "roughness": 0.3,
                "samplers": "jittered,sobol", "mitsuba_samplers": "stratified,independent", "variant": "llvm_ad_rgb"}
    for name, default in defaults.items():
        if getattr(args, name) != default:
            words.append(f"--{name.replace('_', '-')} {getattr(args, name)}")
    words.append(f"--venv {args.venv}")
    context = {"command": " ".join(words), "date": datetime.datetime.now(datetime.timezone.utc).strftime(
                   "%Y-%m-%d %H:%M UTC"),
               "rtmesh": rtmesh_commit(os.path.dirname(os.path.abspath(rtmesh.__file__))),
               "mitsuba": mitsuba.version, "machine": machine_start, "load_start": load_start,
               "load_end": loadavg(), "wall": time.perf_counter() - started,
               "object_pixels": int(prepared["mask"].sum())}
    text, _ = report(rows, [n for n in configs if n.startswith("rtmesh")],
                     [n for n in configs if n.startswith("Mitsuba")], args, context)
    publish(text, SECTION, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
