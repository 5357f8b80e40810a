"""The light tree against the power alias table: error at equal samples, time, and the
equal-error time ratio, on scenes with few and with many emitters.

For each scene, ``light_sampler = "power"`` and ``"tree"`` render at ``--spp`` with three
seeds each (interleaved; render time medians, the scene already built and compiled) and are
compared with one reference of ``--reference-spp`` samples (the power sampler, another
seed): relative RMSE over the image.  Equal-error time ratio, tree over power:
``(error_tree / error_power)^2 x (time_tree / time_power)`` (error falls as one over the
square root of the samples).  The image means are printed beside the reference's (both
samplers are unbiased: they must agree within noise).

Scenes: 400 glowing balls of 80 triangles on a 40 x 40 floor (32,000 emissive triangles,
``benchmarks/bench_instancing.py``'s scene), ``assets/effects/soft_shadow.toml`` and
``assets/cornell_box.toml`` under the path integrator with one light sample.

Usage::

    python -m benchmarks.bench_light_tree [--size 192] [--spp 8] [--reference-spp 256]
"""

import argparse
import dataclasses
import os
import statistics
import time

import numpy as np

from benchmarks.bench_instancing import _scene
from rtmesh.api import load_scene
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings

ASSETS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "assets")


def _scenes(size):
    height = size * 3 // 4
    _, balls = _scene(80, count=400, kind="emitters")
    yield "400 glowing balls", balls, RenderSettings(width=size, height=height, integrator="path", light_samples=1)
    for name in ("effects/soft_shadow", "cornell_box"):
        scene, settings = load_scene(os.path.join(ASSETS, f"{name}.toml"), width=size, height=height,
                                     integrator="path", light_samples=1)
        yield name, scene, settings


def _render(scene, settings, sampler, spp, seed):
    integrator = Integrator(scene, dataclasses.replace(settings, light_sampler=sampler, spp=spp, seed=seed,
                                                       threads=2))
    start = time.perf_counter()
    image = np.asarray(integrator.render().image, np.float64)
    return image, time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=192)
    parser.add_argument("--spp", type=int, default=8)
    parser.add_argument("--reference-spp", type=int, default=256)
    options = parser.parse_args()
    print("scene | sampler | rel. RMSE | render s | mean (reference) | equal-error time, tree / power")
    for name, scene, settings in _scenes(options.size):
        reference, _ = _render(scene, settings, "power", options.reference_spp, 99)
        errors, times, means = {}, {}, {}
        for sampler in ("power", "tree"):
            _render(scene, settings, sampler, 1, 0)  # compile and warm up
        for seed in (1, 2, 3):
            for sampler in ("power", "tree"):
                image, seconds = _render(scene, settings, sampler, options.spp, seed)
                error = float(np.sqrt(np.mean((image - reference) ** 2)) / np.mean(reference))
                errors.setdefault(sampler, []).append(error)
                times.setdefault(sampler, []).append(seconds)
                means.setdefault(sampler, []).append(float(image.mean()))
        e = {k: statistics.mean(v) for k, v in errors.items()}
        t = {k: statistics.median(v) for k, v in times.items()}
        ratio = (e["tree"] / e["power"]) ** 2 * (t["tree"] / t["power"])
        for sampler in ("power", "tree"):
            print(f"{name} | {sampler} | {e[sampler]:.4f} | {t[sampler]:.3f} | "
                  f"{statistics.mean(means[sampler]):.5f} ({reference.mean():.5f}) |"
                  + (f" {ratio:.2f}" if sampler == "tree" else ""), flush=True)


if __name__ == "__main__":
    main()
