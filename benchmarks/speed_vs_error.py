"""Speed against error: samplers and adaptive sampling against a high-spp reference.

For scenes shipped in assets/, renders a high-sample reference (Sobol, its own seed), then
sweeps samples per pixel for every sampler and adaptive targets, and measures each image's
error against the reference next to its wall time:

    python -m benchmarks.speed_vs_error --out docs/speed_vs_error.csv --plot docs/images/speed_vs_error.png

Writes a CSV (scene, method, sampler, spp, target, seconds, cpu_seconds, mean_spp, rays, rmse,
relative_error, estimated_error), a log-log plot of RMSE against time (needs matplotlib: the
``bench`` extra), and prints a summary: the time adaptive sampling saves at equal RMSE, what
one of its samples costs against a uniform render's (rays and CPU time per sample), and how
the render's own error estimate compares with the measured error.  Adaptive targets are
display-scale errors (standard error / sqrt(mean + 0.01), what ``target_error`` bounds).

Renders run on one thread by default and are timed by wall clock (``seconds``) and by the
process's CPU time (``cpu_seconds``); on a shared, loaded machine the CPU time of a
one-thread render is the steadier measure of the work, and the ratios use it.

Errors:
- ``rmse``: root mean square of (image - reference) over pixels and channels, linear radiance;
- ``relative_error``: mean over pixels and channels of |image - reference| / (reference +
  0.01), the measured counterpart of the render's estimate;
- ``estimated_error``: the render's own estimate (``RenderStats.relative_error``), the mean of
  each pixel's standard error / (mean + 0.01).  For independent, normal errors the mean
  absolute error is sqrt(2/pi) = 0.80 of the standard error, so an exact estimate gives
  ``relative_error / estimated_error`` = 0.80.

Denoised renders (method ``denoised``, the jittered sweep with ``denoise`` on; needs the
``denoise`` extra): their ``rmse`` is that of the denoised image against the reference, and
the summary gives the time a uniform render needs for the same RMSE.  Denoising is biased:
its error does not fall to zero with more samples, and the render's own estimate (given in
``estimated_error``) still describes the noisy image it started from, not the denoised one.
"""

import argparse
import csv
import dataclasses
import importlib.util
import os
import sys
import time

import numpy as np

from rtmesh.api import load_scene
from rtmesh.rendering.film import ERROR_FLOOR
from rtmesh.rendering.integrator import Integrator

ROOT = os.path.join(os.path.dirname(__file__), "..")
# name: (scene file, width, height, reference spp, largest uniform spp)
SCENES = {
    "glass_edges": ("assets/glass_edges.toml", 160, 120, 1024, 64),
    "showcase": ("assets/showcase.toml", 160, 120, 1024, 64),
    "glossy": ("assets/effects/glossy.toml", 160, 120, 1024, 64),
    # localised noise, what adaptive sampling is for: only the moving objects and their
    # shadows are noisy, the still scene converges in the first round
    "motion_blur": ("assets/effects/motion_blur.toml", 160, 120, 1024, 64),
}
SAMPLERS = ("regular", "random", "jittered", "sobol")
ADAPTIVE_SAMPLERS = ("sobol", "jittered")
# display-scale errors, standard error / sqrt(mean + 0.01) (rtmesh.rendering.film.Film.pixel_display_error)
TARGETS = (0.08, 0.04, 0.02, 0.01)
BASE_SPP = 4
SOBOL_REACH = 4  # the uniform Sobol sweep goes to 4x the scene's largest uniform spp
MAX_SPP = 256
FIELDS = ("scene", "method", "sampler", "spp", "target", "seconds", "cpu_seconds", "mean_spp", "rays", "rmse",
          "relative_error", "estimated_error")


def errors(image, reference):
    """(rmse, relative_error) of a linear image against the reference (see the module doc)."""
    diff = image.astype(np.float64) - reference
    rmse = float(np.sqrt(np.mean(diff ** 2)))
    relative = float(np.mean(np.abs(diff) / (np.abs(reference) + ERROR_FLOOR)))
    return rmse, relative


def run_scene(name, threads, quick, denoise=False):
    path, width, height, ref_spp, top_spp = SCENES[name]
    if quick:
        width, height, ref_spp, top_spp = width // 2, height // 2, ref_spp // 4, top_spp // 4
    scene, base = load_scene(os.path.join(ROOT, path), width=width, height=height, threads=threads)
    # the reference has its own seed, so its error is independent of every image's
    settings = dataclasses.replace(base, spp=ref_spp, sampler="sobol", seed=1000)
    ref = Integrator(scene, settings).render()
    reference = ref.image.astype(np.float64)
    print(f"{name}: {width}x{height}, reference {ref_spp} spp sobol in {ref.stats.wall_seconds:.1f} s "
          f"(estimated error {ref.stats.relative_error:.3g})", flush=True)

    # the uniform Sobol curve goes further, so that adaptive renders at low error still
    # have a uniform render of equal RMSE to compare with
    runs = [("uniform", sampler, spp, None) for sampler in SAMPLERS
            for spp in 2 ** np.arange(int(np.log2(top_spp * (SOBOL_REACH if sampler == "sobol" else 1))) + 1)]
    runs += [("adaptive", sampler, BASE_SPP, target) for sampler in ADAPTIVE_SAMPLERS for target in TARGETS]
    if denoise:
        runs += [("denoised", "jittered", spp, None) for spp in 2 ** np.arange(int(np.log2(top_spp)) + 1)]
    rows = []
    for method, sampler, spp, target in runs:
        settings = dataclasses.replace(base, spp=int(spp), sampler=sampler, seed=0, target_error=target,
                                       max_spp=MAX_SPP if target else None, denoise=method == "denoised")
        cpu = time.process_time()
        result = Integrator(scene, settings).render()
        cpu = time.process_time() - cpu
        rmse, relative = errors(result.image, reference)
        st = result.stats
        rows.append({"scene": name, "method": method, "sampler": sampler, "spp": int(spp),
                     "target": "" if target is None else target, "seconds": round(st.wall_seconds, 4),
                     "cpu_seconds": round(cpu, 4),
                     "mean_spp": round(st.mean_spp, 2), "rays": st.total_rays, "rmse": f"{rmse:.5g}",
                     "relative_error": f"{relative:.5g}",
                     "estimated_error": "" if np.isnan(st.relative_error) else f"{st.relative_error:.5g}"})
        label = f"target {target}" if target else f"{int(spp)} spp"
        print(f"  {method:8s} {sampler:8s} {label:12s} {st.wall_seconds:7.3f} s  {cpu:7.3f} s CPU  "
              f"{st.mean_spp:6.1f} spp  "
              f"RMSE {rmse:.4g}  rel {relative:.4g}  est {st.relative_error:.4g}", flush=True)
    return rows


def cost_at_rmse(rows, rmse, cost="cpu_seconds"):
    """The ``cost`` (cpu_seconds or mean_spp) a uniform curve needs to reach ``rmse``,
    interpolated in log-log; None outside the curve's range."""
    pts = sorted((float(r["rmse"]), float(r[cost])) for r in rows)
    e = np.log([p[0] for p in pts])
    t = np.log([p[1] for p in pts])
    x = np.log(rmse)
    if not e[0] <= x <= e[-1]:
        return None
    # RMSE falls as time grows: interpolate time as a function of error
    return float(np.exp(np.interp(x, e, t)))


def summary(rows):
    """Lines of text: equal-RMSE time savings and how the estimate tracks the true error."""
    lines = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        mine = [r for r in rows if r["scene"] == scene]
        for sampler in ADAPTIVE_SAMPLERS:
            uniform = [r for r in mine if r["method"] == "uniform" and r["sampler"] == sampler]
            for r in mine:
                if r["method"] != "adaptive" or r["sampler"] != sampler:
                    continue
                t_uniform = cost_at_rmse(uniform, float(r["rmse"]))
                spp_uniform = cost_at_rmse(uniform, float(r["rmse"]), "mean_spp")
                saved = "outside the uniform range" if t_uniform is None else (
                    f"uniform needs {t_uniform:.2f} s: {t_uniform / float(r['cpu_seconds']):.2f}x the time, "
                    f"{spp_uniform:.1f} spp: {spp_uniform / float(r['mean_spp']):.2f}x the samples")
                # cost of a sample: rays and CPU time per sample against the largest uniform render
                top = max(uniform, key=lambda u: u["spp"])
                samples, top_samples = float(r["mean_spp"]), float(top["mean_spp"])
                saved += (f"; per sample {r['rays'] / samples / (top['rays'] / top_samples):.2f}x the rays, "
                          f"{float(r['cpu_seconds']) / samples / (float(top['cpu_seconds']) / top_samples):.2f}x "
                          f"the time of uniform {top['spp']} spp")
                lines.append(f"{scene} adaptive {sampler} target {r['target']}: RMSE {r['rmse']} "
                             f"in {r['cpu_seconds']} s CPU ({r['mean_spp']} spp mean); {saved}")
        uniform = [r for r in mine if r["method"] == "uniform" and r["sampler"] == "jittered"]
        for r in mine:
            if r["method"] == "denoised":
                t_uniform = cost_at_rmse(uniform, float(r["rmse"]))
                equal = ("below every uniform render's RMSE" if t_uniform is None
                         else f"uniform jittered needs {t_uniform:.2f} s: {t_uniform / float(r['cpu_seconds']):.2f}x")
                lines.append(f"{scene} denoised {r['spp']} spp: RMSE {r['rmse']} in {r['cpu_seconds']} s CPU; {equal}")
        for sampler in SAMPLERS:
            ratios = [float(r["relative_error"]) / float(r["estimated_error"]) for r in mine
                      if r["sampler"] == sampler and r["method"] == "uniform" and r["estimated_error"]
                      and r["spp"] <= 64]
            if ratios:
                lines.append(f"{scene} {sampler}: measured / estimated relative error, median "
                             f"{np.median(ratios):.2f} (range {min(ratios):.2f}-{max(ratios):.2f}; "
                             f"0.80 is an exact estimate)")
    return lines


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    fig, axes = plt.subplots(1, len(scenes), figsize=(4.2 * len(scenes), 3.8), squeeze=False)
    for ax, scene in zip(axes[0], scenes):
        mine = [r for r in rows if r["scene"] == scene]
        for sampler in SAMPLERS:
            sel = [r for r in mine if r["method"] == "uniform" and r["sampler"] == sampler]
            ax.loglog([r["cpu_seconds"] for r in sel], [float(r["rmse"]) for r in sel], "o-", ms=3,
                      label=f"uniform {sampler}")
        for sampler, style in zip(ADAPTIVE_SAMPLERS, ("s-", "D--")):
            sel = [r for r in mine if r["method"] == "adaptive" and r["sampler"] == sampler]
            ax.loglog([r["cpu_seconds"] for r in sel], [float(r["rmse"]) for r in sel], style, lw=2, ms=4,
                      color="black" if sampler == "sobol" else "grey", label=f"adaptive {sampler}")
        sel = [r for r in mine if r["method"] == "denoised"]
        if sel:
            ax.loglog([r["cpu_seconds"] for r in sel], [float(r["rmse"]) for r in sel], "v:", lw=2, ms=4,
                      color="tab:purple", label="denoised jittered (biased)")
        ax.set_title(scene)
        ax.set_xlabel("render time [s, 1 thread, CPU]")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("RMSE against the reference")
    axes[0][-1].legend(fontsize=7)
    fig.tight_layout()
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default=",".join(SCENES), help="comma-separated: " + ", ".join(SCENES))
    parser.add_argument("--threads", type=int, default=1,
                        help="render threads (default 1: on a shared machine one thread's time is "
                        "the steadiest measure of work)")
    parser.add_argument("--quick", action="store_true", help="half size, fewer samples (a smoke test)")
    parser.add_argument("--out", default="speed_vs_error.csv")
    parser.add_argument("--plot", default=None, help="PNG of RMSE against time")
    parser.add_argument("--no-denoise", action="store_true",
                        help="leave out the denoised sweep (it runs when the denoise extra is installed)")
    args = parser.parse_args(argv)
    denoise = not args.no_denoise and importlib.util.find_spec("pyoidn") is not None
    rows = []
    for name in args.scenes.split(","):
        rows += run_scene(name, args.threads, args.quick, denoise)
    with open(args.out, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    if args.plot:
        plot(rows, args.plot)
    print("\n".join(summary(rows)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
