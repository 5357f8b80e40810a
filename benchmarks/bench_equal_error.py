"""Equal-error time: rtmesh's path integrator against Mitsuba 3 ``path`` on the Duck (issue 27).

What is rendered
----------------
The scene of benchmarks/bench_pbr_peers.py's ``duck-env-*`` cases, built by their functions
(benchmarks/pbr_cases.py):

- geometry: the triangles and vertex normals of ``Duck.glb`` (``../shared/assets/real/``),
  centred on its bounding box and scaled so its largest half-extent is 1; Mitsuba reads the
  triangles and normals rtmesh built from the file (a float32 PLY);
- material: ONE glTF ``pbrMetallicRoughness`` material of bench_pbr_peers' set written into
  the GLB rtmesh reads, each measured in turn (``--materials``, default both): ``dielectric``
  (metallic 0, base colour (0.8, 0.298, 0.2) as the file stores it) and ``metal`` (metallic
  1, base colour (0.949, 0.639, 0.541): copper-like F0), at roughness 0.3 (``--roughness``).
  Mitsuba renders the same BRDF, the glTF Appendix B model written as a Mitsuba BSDF in Python
  (benchmarks/peers_mitsuba_pbr.py ``GltfBSDF``: traced into Mitsuba's LLVM kernels, it renders
  as fast as Mitsuba's ``principled``, 0.24-0.26 s for both at 16 spp here, so no stand-in is
  needed).  The Duck's own textured material (metallic 0, roughness 1) is not used;
- light: ``rtmesh/scene/studio.exr`` as the only light: rtmesh ``lights = []``,
  ``[environment] ambient = 0``, ``[background]`` the exr with ``lighting = true``; Mitsuba an
  ``envmap`` of the same radiance function (pbr_cases ``mitsuba_environment_image``,
  rotated +90 degrees about +Y), ``hide_emitters = false``: the background is seen in both;
- camera: bench_pbr_peers' (from (0, 0.6, 3.6) toward the origin, +Y up, 36 degree vertical
  field of view), ``--size`` 256 x 256, box filter (each sample counts in its own pixel);
- transport: one indirect bounce, rtmesh ``[render] integrator = "path"``, ``max_depth = 2``
  (segments after the camera ray), Mitsuba ``path`` with ``max_depth = 3``;
- threads: 2 for both (``threads = 2``; Dr.Jit ``set_thread_count(2)``);
- samplers: rtmesh ``jittered`` (its default) and ``sobol`` (``--samplers``); Mitsuba
  ``stratified`` and ``independent`` (its default) (``--mitsuba-samplers``);
- light samples: rtmesh's ``light_samples`` (next-event estimates at a path's first vertex
  that takes light), ``--light-samples`` (default 1, the default under ``path``, as Mitsuba's
  ``path`` takes one; a comma-separated list measures each value as its own configuration,
  ``rtmesh <sampler>, light_samples <n>``, in the same alternating rounds).  Mitsuba is
  unchanged by it.

Error and time
--------------
Each configuration renders the image with two seeds A and B (rtmesh 1 and 2, Mitsuba 1 and 2)
at each of its spp levels: rtmesh ``--spp`` (default 16 and 64 samples a pixel), Mitsuba
``--mitsuba-spp`` (default 16, 64 and 256: squares, which its ``stratified`` sampler needs;
the third level, cheap for Mitsuba, checks how its exponent holds up toward the 2 % target,
where rtmesh's stays 0.5).  The error of one render is

    e = RMSE(A - B) / sqrt(2) / mean((A + B) / 2)

over every pixel and channel of the 256 x 256 image, the duck and the background (the
headline; the column "object" gives the same over the pixels fully covered by the duck,
pbr_cases ``object_mask``, divided by their own mean).  Times are wall-clock seconds of
one render call, scene loading and process start-up excluded (rtmesh: ``rtmesh.render`` on a
loaded scene, its ``Integrator`` construction included, ~0.03 s; Mitsuba: ``mi.render`` plus
the copy of the image to NumPy, in a worker process that stays up,
benchmarks/peers_mitsuba_equal_error.py).
The CPU seconds of the same call (``time.process_time``: every thread of the rendering
process) are recorded beside: the machine is shared, and other jobs' load changes them far
less than the wall time.
Before the clock runs, every configuration renders once at each spp level (Mitsuba compiles
its kernels then, rtmesh loads its compiled ones); then each of ``--runs`` rounds runs through
every spp level, rendering both seeds of every configuration that has the level, rtmesh and
Mitsuba alternating render by render (the load, which swings by 2x within seconds here,
reaches every level and both renderers alike); the time of a configuration at an spp level
is the median of its ``runs x 2`` renders, wall and CPU each.

Extrapolation (:func:`time_to_error`): the error follows ``e = c spp^-k`` through the two
neighbouring levels whose errors bracket the target (log-log interpolation), or through the
last two levels beyond them (extrapolation with the local exponent); ``k`` between each two
levels is reported (0.5 for independent samples; more where a sampler stratifies, less and
less as spp grows); the time follows
``t = a + b spp`` (least squares, ``a >= 0``: a render's fixed cost and its cost per sample).
The spp a target error needs, ``(c / e)^(1/k)``, may be fractional and lie outside the
measured levels (extrapolated).  Ratios are rtmesh / Mitsuba seconds at 8, 4 and 2 % (issue
27's target: the worst of the three <= 0.5), in wall seconds (the target's) and in CPU
seconds (the check); the headline pairs each renderer's faster sampler at 2 %, and every
pairing is in the table.

Usage::

    python -m benchmarks.bench_equal_error [--spp 16,64] [--mitsuba-spp 16,64,256] [--runs 3] [--threads 2] [--size 256]
        [--materials dielectric,metal] [--roughness 0.3] [--samplers jittered,sobol]
        [--mitsuba-samplers stratified,independent] [--light-samples 1[,4]] [--variant llvm_ad_rgb]
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
from benchmarks import pbr_cases as pbr
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
    "- rtmesh's path kernel takes the first vertex's light point and BSDF direction from Owen-scrambled "
    "Sobol pairs of the pixel's sequences (every sampler but `random`; later vertices, the light "
    "choice, lobe and roulette numbers are hashed). Its errors at equal spp then match Mitsuba's "
    "`stratified` sampler (k of about 0.65 between 16 and 64 spp); `jittered` and `sobol` differ only "
    "in the pixel position. Before that change (rtmesh 0f579e8, every number hashed) rtmesh's errors "
    "matched Mitsuba's `independent` sampler (k = 0.50) and the worst ratios were 11.0 (dielectric) "
    "and 30.9 (metal).",
    "- So what is left is the cost of a sample: rtmesh's `M samples/s` against Mitsuba's. At 739a369 "
    "(2026-12-03 11:25) rtmesh drew 1.4-1.8 M samples/s here against Mitsuba's 5.3-8.1 (3.5-4.5x fewer: the "
    "path kernel shades its 16 lanes one at a time, Mitsuba's LLVM back end runs every shading step "
    "vectorised over its lanes; worst ratios 3.52 dielectric and 2.86 metal in CPU seconds, 3.80 and 2.68 "
    "wall); at 5be8397 it draws 0.72-0.75, about 7x fewer, for the same images (the "
    "`light_samples 1` errors and means are those of 739a369 digit for digit). That is not the load: the "
    "same render (dielectric, jittered, 16 spp, 2 threads) alternating the two trees on a quiet machine "
    "(load 1.2-1.6) took 0.78-0.80 CPU s at 739a369 and 1.43-1.45 at 5be8397, 1.83x. A bisection (one "
    "process a commit, cold compile, the min of two renders, load 1.6-3) puts it in two steps: 12e7df7 "
    "(the path and photon kernels share `path_surfaces.hit_parameters`) 0.82 -> 1.20 s, and the merge of "
    "`khrmat` 9b87a94 (the kernels share `hit_frame`; the branch alone stays at 0.82) 1.24 -> 1.47 s. "
    "Issue 27's 0.5x needs a sample about 13x cheaper than today's (about 7x cheaper than 739a369's).",
    "- The noise is mostly direct light (next-event estimation of the map and BSDF sampling, MIS): "
    "with `max_depth = 1` (direct light only) rtmesh's error at 16 spp was 22.3 % against 22.4 % with "
    "one bounce before the Sobol pairs (Mitsuba stratified 12.9 % against 13.7 %).",
    "- `light_samples` (rtmesh's next-event estimates at the first vertex; 1 is the default under `path` "
    "and what Mitsuba's `path` takes). Dielectric: 4 light samples cut the error at 16 spp from 14.0 % to "
    "8.6 % (0.61x; 5.7 % to 3.7 % at 64 spp) for 1.53x the CPU seconds of a render, so the CPU time to "
    "each error falls to 0.74x (8 %), 0.78x (4 %), 0.84x (2 %; the exponent k falls from 0.65 to 0.61): "
    "the worst ratio against Mitsuba stratified goes from 6.60 to 5.09 CPU (6.85 to 5.01 wall), 0.77x, "
    "still 10x from 0.5. Metal (roughness 0.3): the error falls only to 0.85x (19.7 % to 16.7 % at 16 "
    "spp) for the same 1.5x cost, so 4 light samples are slower to every error (5.35 to 7.57 CPU): a "
    "glossy conductor's noise is the BSDF-sampled reflection of the map, which the light samples, weighted "
    "against the BSDF by MIS, hardly reduce. Either way the gap is the cost of a sample (above); "
    "`light_samples` trades within it and makes each sample 1.5x dearer here (0.48 M samples/s; its "
    "shadow rays and light evaluations are not free beside a sample's camera ray, shading and bounce).",
    "- Wall times on this shared machine swing by 2x within seconds (other jobs start and stop): "
    "every round runs through every spp level and the renderers alternate render by render, so both "
    "see the same load, but the fitted fixed cost `a` and the extrapolated seconds move from run to "
    "run; the CPU-second ratios, which the load moves far less, are the check: CPU seconds per "
    "sample stay within 10 % across the spp levels, for both renderers.",
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


def exponents(spps, errors):
    """The exponent ``k`` of ``error = c spp^-k`` between each two neighbouring spp levels."""
    return [power_law(spps[i:i + 2], errors[i:i + 2])[1] for i in range(len(spps) - 1)]


def time_to_error(spps, seconds, errors, target):
    """Seconds and spp to reach a relative error, from measured spp levels.

    The error follows ``c spp^-k`` through the two neighbouring levels whose errors bracket
    ``target`` (log-log interpolation), or, beyond the measured errors, through the two
    levels at that end (extrapolation with the local exponent: a sampler that stratifies
    gains less as spp grows); the time follows :func:`cost_line` through every level.

    Parameters
    ----------
    spps, seconds, errors : sequences of float
        Per measured level, ascending spp: samples a pixel, seconds of one render, its
        relative error.
    target : float
        Relative error to reach.

    Returns
    -------
    dict
        ``spp`` (fractional: ``(c / target)^(1/k)``), ``seconds`` (``a + b spp``),
        ``exponent`` (the ``k`` used), ``extrapolated`` (True when ``spp`` lies outside the
        levels).
    """
    spps, seconds, errors = list(spps), list(seconds), list(errors)
    if len(spps) < 2:
        raise ValueError("the error's exponent needs two or more distinct spp levels")
    # the first two levels whose second reaches the target (the first two when the first
    # does); the last two when none does
    pair = next((i for i in range(len(spps) - 1) if errors[i + 1] <= target), len(spps) - 2)
    c, k = power_law(spps[pair:pair + 2], errors[pair:pair + 2])
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
        wall, cpu = self.answer("done")
        return float(wall), float(cpu), np.load(out)

    def close(self):
        self.process.stdin.close()
        self.process.wait()


def rtmesh_render(scene, settings, sampler, spp, seed, threads, light_samples=1):
    """Wall and CPU seconds of one rtmesh render on a loaded scene (CPU: every thread of this
    process), and its image."""
    start, cpu = time.perf_counter(), time.process_time()
    image = rtmesh.render(scene, settings, spp=spp, seed=seed, threads=threads, sampler=sampler,
                          light_samples=light_samples).image
    return time.perf_counter() - start, time.process_time() - cpu, np.asarray(image)


def measure(configs, runs):
    """Warm up, then time every configuration, alternating them render by render.

    Parameters
    ----------
    configs : dict of str to (callable, seeds, spps)
        ``render(spp, seed) -> (wall seconds, CPU seconds, image)``, the two seeds and the spp
        levels, by name.  Every round renders every level: the load of the shared machine,
        which swings by 2x within seconds, reaches every level alike; within a level the
        configurations that have it alternate.

    Returns
    -------
    dict of str to dict of int to dict
        Per configuration and spp: ``times`` and ``cpu`` (every timed render) and ``images``
        (by seed, from the first round).
    """
    results = {name: {spp: {"times": [], "cpu": [], "images": {}} for spp in spps}
               for name, (_, _, spps) in configs.items()}
    levels = sorted({spp for _, _, spps in configs.values() for spp in spps})
    for spp in levels:
        for name, (render, _, spps) in configs.items():
            if spp in spps:
                seconds, _, _ = render(spp, 0)  # warm-up: kernels compiled or loaded, memory touched
                print(f"  warm-up {name} {spp} spp: {seconds:.2f} s", flush=True)
    for run in range(runs):
        for spp in levels:
            for i in range(2):
                for name, (render, seeds, spps) in configs.items():
                    if spp not in spps:
                        continue
                    seconds, cpu, image = render(spp, seeds[i])
                    results[name][spp]["times"].append(seconds)
                    results[name][spp]["cpu"].append(cpu)
                    if run == 0:
                        results[name][spp]["images"][seeds[i]] = image
                    print(f"  {name} {spp} spp seed {seeds[i]}: {seconds:.3f} s, CPU {cpu:.3f} s", flush=True)
    return results


# ---------------------------------------------------------------- the report
def summarise(results, seeds_of, mask, pixels):
    """Per configuration: the levels' median seconds and errors, the exponents between them and
    the times to each target."""
    rows = {}
    for name, levels in results.items():
        a, b = seeds_of[name]
        level_rows = []
        spps = sorted(levels)
        for spp in spps:
            images = levels[spp]["images"]
            level_rows.append({"spp": spp, "seconds": float(np.median(levels[spp]["times"])),
                               "cpu": float(np.median(levels[spp]["cpu"])),
                               "error": seed_error(images[a], images[b]),
                               "object_error": seed_error(images[a], images[b], mask),
                               "mean": float(0.5 * (images[a].mean() + images[b].mean()))})
        for r in level_rows:
            r["msamples_per_s"] = r["spp"] * pixels / r["seconds"] / 1e6
        errors = [r["error"] for r in level_rows]
        fit = {t: time_to_error(spps, [r["seconds"] for r in level_rows], errors, t) for t in TARGETS}
        fit_cpu = {t: time_to_error(spps, [r["cpu"] for r in level_rows], errors, t) for t in TARGETS}
        rows[name] = {"levels": level_rows, "targets": fit, "targets_cpu": fit_cpu,
                      "exponents": exponents(spps, [r["error"] for r in level_rows])}
    return rows


def material_tables(rows, rt_names, mi_names, rt_groups=None):
    """The three tables of one material: measured levels, time to each error, ratios.

    Parameters
    ----------
    rt_groups : dict of str to list of str, optional
        rtmesh configurations grouped by a label (its ``light_samples``): one headline per
        group.  One group of every rtmesh configuration when None.

    Returns
    -------
    lines : list of str
    headlines : list of (str, dict)
        Per group: its label and ``rtmesh``, ``mitsuba`` (each renderer's faster configuration
        at 2 %), ``worst`` and ``worst_cpu`` (their worst ratio over the targets, wall and CPU
        seconds).
    """
    lines = ["| renderer, sampler | spp | s (median) | CPU s | M samples/s | error | object error | image mean |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for name, row in rows.items():
        for r in row["levels"]:
            lines.append(f"| {name} | {r['spp']} | {r['seconds']:.3f} | {r['cpu']:.3f} | {r['msamples_per_s']:.2f} | "
                         f"{r['error']:.2%} | {r['object_error']:.2%} | {r['mean']:.4f} |")
    lines += ["", "Time to reach each error (spp from `error = c spp^-k` through the two neighbouring levels "
              "that bracket it, or the last two; k between each two levels; seconds from `a + b spp`; `*`: "
              "outside the measured spp):", "",
              "| renderer, sampler | k | " + " | ".join(f"{t:.0%}: spp / s / CPU s" for t in TARGETS) + " |",
              "|---|---:|" + "---:|" * len(TARGETS)]
    for name, row in rows.items():
        cells = [f"{f['spp']:.0f}{'*' if f['extrapolated'] else ''} / {f['seconds']:.2f} / "
                 f"{row['targets_cpu'][t]['seconds']:.2f}" for t, f in row["targets"].items()]
        ks = ", ".join(f"{k:.2f}" for k in row["exponents"])
        lines.append(f"| {name} | {ks} | " + " | ".join(cells) + " |")
    lines += ["", "rtmesh / Mitsuba seconds at equal error, wall (issue 27's target: worst <= 0.5) and CPU:", "",
              "| rtmesh | Mitsuba | " + " | ".join(f"{t:.0%}" for t in TARGETS) + " | worst | "
              + " | ".join(f"CPU {t:.0%}" for t in TARGETS) + " | worst CPU |",
              "|---|---|" + "---:|" * (2 * len(TARGETS) + 2)]

    def ratios(rt, mi_name, key):
        return [rows[rt][key][t]["seconds"] / rows[mi_name][key][t]["seconds"] for t in TARGETS]

    for rt in rt_names:
        for mi_name in mi_names:
            wall, cpu = ratios(rt, mi_name, "targets"), ratios(rt, mi_name, "targets_cpu")
            lines.append(f"| {rt} | {mi_name} | " + " | ".join(f"{x:.2f}" for x in wall)
                         + f" | **{max(wall):.2f}** | " + " | ".join(f"{x:.2f}" for x in cpu) + f" | {max(cpu):.2f} |")
    best_mi = min(mi_names, key=lambda n: rows[n]["targets"][TARGETS[-1]]["seconds"])
    headlines = []
    for label, names in (rt_groups or {"": rt_names}).items():
        best_rt = min(names, key=lambda n: rows[n]["targets"][TARGETS[-1]]["seconds"])
        headlines.append((label, {"rtmesh": best_rt, "mitsuba": best_mi,
                                  "worst": max(ratios(best_rt, best_mi, "targets")),
                                  "worst_cpu": max(ratios(best_rt, best_mi, "targets_cpu"))}))
    return lines, headlines


def report(materials, args, context):
    """The BENCHMARKS.md section.

    Parameters
    ----------
    materials : list of (str, dict, list, list, dict)
        Per material: its name, the rows of :func:`summarise`, the rtmesh and the Mitsuba
        configuration names, the rtmesh names by ``light_samples``.
    """
    lines = [f"## {SECTION}", "",
             f"Command: `{context['command']}` (Mitsuba in its own venv, `sh benchmarks/peers_setup.sh`); "
             "the scene, the error and the extrapolation are in the script's docstring.", "",
             f"- Date {context['date']}; rtmesh {context['rtmesh']}, Mitsuba {context['mitsuba']} "
             f"`{args.variant}`; {context['machine']}",
             f"- /proc/loadavg at the start `{context['load_start']}`, at the end `{context['load_end']}` "
             f"(2 cores shared with other jobs; {context['wall']:.0f} s in all)",
             f"- Duck.glb (unit half-extent) with one glTF material of bench_pbr_peers (roughness "
             f"{args.roughness:g}; Mitsuba: the same BRDF, `GltfBSDF`), studio.exr the only light, "
             f"{args.size} x {args.size}, box filter, {args.threads} threads; rtmesh `path` max_depth {MAX_DEPTH}, "
             f"Mitsuba `path` max_depth {MAX_DEPTH + 1}; rtmesh `light_samples` "
             f"{' and '.join(str(n) for n in context['light_samples'])} (next-event estimates at the first vertex; "
             f"Mitsuba's `path` takes one); seeds rtmesh {RTMESH_SEEDS}, Mitsuba {MITSUBA_SEEDS}; "
             f"times are medians of {args.runs} x 2 renders, alternating renderers, every round through every "
             "spp level; `CPU s`: the process's CPU seconds (all its threads) of a render, which other jobs' "
             "load changes far less than wall time",
             "- error = RMSE(A - B) / sqrt(2) / mean, over all pixels (duck and background); `object`: over "
             f"the {context['object_pixels']} pixels fully on the duck, over their mean",
             ""]
    headlines = []
    for material, rows, rt_names, mi_names, rt_groups in materials:
        values = pbr.MATERIALS[material]
        tables, groups = material_tables(rows, rt_names, mi_names, rt_groups)
        headlines += [(material + (f", light_samples {label}" if len(groups) > 1 else ""), h)
                      for label, h in groups]
        lines += [f"### {material}: metallic {values['metallic']:g}, base colour {values['base_color']} "
                  f"(8 bits in the GLB), roughness {args.roughness:g}", "", *tables, ""]
    lines += ["Headline (each renderer's faster sampler at 2 %, rtmesh's per `light_samples`), worst ratio over "
              "8, 4 and 2 % (target <= 0.5):", ""]
    lines += [f"- {material}: {h['rtmesh']} against {h['mitsuba']}: **{h['worst']:.2f}** wall, "
              f"{h['worst_cpu']:.2f} CPU" for material, h in headlines]
    lines += ["", *NOTES, ""]
    return "\n".join(lines), max(h["worst"] for _, h in headlines)


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


def rtmesh_name(sampler, light_samples, several):
    """A configuration's name: ``rtmesh <sampler>``, with ``, light_samples <n>`` when the run
    measures several values."""
    return f"rtmesh {sampler}" + (f", light_samples {light_samples}" if several else "")


def run_material(material, args, spps, mi_spps, rt_samplers, mi_samplers, light_samples=(1,)):
    """Measure one material: files written, scene loaded, a Mitsuba worker for it, the renders.

    Returns
    -------
    rows : dict
        :func:`summarise`'s.
    names : list of str
        The configurations, in the order they alternate.
    version : str
        Mitsuba's.
    object_pixels : int
    """
    print(f"{material}, roughness {args.roughness:g}", flush=True)
    case = pbr.Case(f"duck-env-{material}-r{args.roughness:g}", "duck", "env", material, args.roughness, ("gltf",))
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
            several = len(light_samples) > 1
            rt_configs = [(s, n) for s in rt_samplers for n in light_samples]
            # alternate: rtmesh, Mitsuba, rtmesh, Mitsuba, ...
            for i in range(max(len(rt_configs), len(mi_samplers))):
                if i < len(rt_configs):
                    s, n = rt_configs[i]
                    configs[rtmesh_name(s, n, several)] = (
                        lambda spp, seed, s=s, n=n: rtmesh_render(scene, settings, s, spp, seed, args.threads, n),
                        RTMESH_SEEDS, spps)
                if i < len(mi_samplers):
                    s = mi_samplers[i]
                    configs[f"Mitsuba {s}"] = (lambda spp, seed, s=s: mitsuba.render(s, spp, seed), MITSUBA_SEEDS,
                                               mi_spps)
            results = measure(configs, args.runs)
        finally:
            mitsuba.close()
    seeds_of = {name: seeds for name, (_, seeds, _) in configs.items()}
    rows = summarise(results, seeds_of, prepared["mask"], args.size * args.size)
    return rows, list(configs), mitsuba.version, int(prepared["mask"].sum())


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spp", default="16,64", help="rtmesh's spp levels, comma-separated (two or more)")
    parser.add_argument("--mitsuba-spp", default="16,64,256", help="Mitsuba's spp levels (two or more)")
    parser.add_argument("--runs", type=int, default=3, help="rounds of timed renders (each renders both seeds)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--size", type=int, default=256, help="image width and height")
    parser.add_argument("--materials", default="dielectric,metal",
                        help=f"bench_pbr_peers materials, comma-separated ({', '.join(pbr.MATERIALS)})")
    parser.add_argument("--roughness", type=float, default=0.3)
    parser.add_argument("--samplers", default="jittered,sobol", help="rtmesh samplers")
    parser.add_argument("--mitsuba-samplers", default="stratified,independent", help="Mitsuba sampler plugins")
    parser.add_argument("--light-samples", default="1",
                        help="rtmesh's light_samples, comma-separated: each value is its own configuration")
    parser.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant")
    parser.add_argument("--venv", default=PEERS_VENV, help="the peers' venv (benchmarks/peers_setup.sh)")
    parser.add_argument("--no-write", action="store_true", help="print only; leave docs/BENCHMARKS.md alone")
    args = parser.parse_args(argv)
    spps, mi_spps = sorted(set(parse_list(args.spp, int))), sorted(set(parse_list(args.mitsuba_spp, int)))
    if min(len(spps), len(mi_spps)) < 2 or min(spps[0], mi_spps[0]) < 1:
        parser.error("--spp and --mitsuba-spp need two or more positive levels each")
    rt_samplers, mi_samplers = parse_list(args.samplers), parse_list(args.mitsuba_samplers)
    try:
        light_samples = sorted(set(parse_list(args.light_samples, int)))
    except ValueError:
        light_samples = []
    if not light_samples or min(light_samples) < 1:
        parser.error("--light-samples: one or more whole numbers >= 1, comma-separated")
    materials_asked = parse_list(args.materials)
    if not materials_asked or set(materials_asked) - set(pbr.MATERIALS):
        parser.error(f"--materials: choose from {', '.join(pbr.MATERIALS)}")
    if set(mi_samplers) & SQUARE_SAMPLERS and any(math.isqrt(s) ** 2 != s for s in mi_spps):
        parser.error(f"Mitsuba's {', '.join(sorted(set(mi_samplers) & SQUARE_SAMPLERS))} sampler rounds spp up "
                     "to a square: give square --mitsuba-spp levels (e.g. 16,64,256)")
    load_start, machine_start, started = loadavg(), machine(), time.perf_counter()
    runtime.tune_process()

    materials, object_pixels, version = [], None, "?"
    for material in materials_asked:
        rows, names, version, object_pixels = run_material(material, args, spps, mi_spps, rt_samplers, mi_samplers,
                                                           light_samples)
        several = len(light_samples) > 1
        groups = {n: [rtmesh_name(s, n, several) for s in rt_samplers] for n in light_samples}
        materials.append((material, rows, [n for n in names if n.startswith("rtmesh")],
                          [n for n in names if n.startswith("Mitsuba")], groups))
    words = ["python -m benchmarks.bench_equal_error"]
    defaults = {"spp": "16,64", "mitsuba_spp": "16,64,256", "runs": 3, "threads": 2, "size": 256,
                "materials": "dielectric,metal", "roughness": 0.3, "samplers": "jittered,sobol",
                "mitsuba_samplers": "stratified,independent", "light_samples": "1", "variant": "llvm_ad_rgb"}
    for name, default in defaults.items():
        if getattr(args, name) != default:
            words.append(f"--{name.replace('_', '-')} {getattr(args, name)}")
    words.append(f"--venv {args.venv}")
    context = {"command": " ".join(words), "date": datetime.datetime.now(datetime.timezone.utc).strftime(
                   "%Y-%m-%d %H:%M UTC"),
               "rtmesh": rtmesh_commit(os.path.dirname(os.path.abspath(rtmesh.__file__))),
               "mitsuba": version, "machine": machine_start, "load_start": load_start,
               "load_end": loadavg(), "wall": time.perf_counter() - started,
               "object_pixels": object_pixels, "light_samples": light_samples}
    text, _ = report(materials, args, context)
    publish(text, SECTION, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
