"""Mitsuba 3 side of benchmarks/bench_equal_error.py; runs inside the peers venv, never imports rtmesh.

A render server: it loads one Mitsuba scene per sampler from a job (the JSON of
:func:`benchmarks.peers_mitsuba_pbr.scene_dict`'s jobs: mesh, glTF BSDF, environment, camera,
``max_depth``; plus ``samplers``, the Mitsuba sampler plugins to load it with), sets Dr.Jit's
thread count, prints ``ready VERSION``, then answers one request a line on standard input::

    SAMPLER SPP SEED OUT.npy

by rendering that scene with ``mi.render(scene, spp=SPP, seed=SEED)``, copying the image to
NumPy (the clock covers both: Mitsuba evaluates lazily), saving its RGB as ``OUT.npy`` and
printing ``done SECONDS CPU_SECONDS`` (wall-clock, and the process's CPU time over all its
threads).  The process stays up between requests, so Dr.Jit's kernels
compiled by a first (warm-up) render at a sample count are reused by the timed ones, and the
benchmark can alternate Mitsuba's renders with rtmesh's.  End of input ends it.

Usage, from the repository root (bench_equal_error.py starts it through
:func:`benchmarks._lib.start_peer`)::

    /tmp/peers-venv/bin/python -m benchmarks.peers_mitsuba_equal_error JOB.json VARIANT THREADS
"""

import argparse
import json
import sys
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from benchmarks.peers_mitsuba_pbr import gltf_bsdf_class, scene_dict


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("job", help="JSON job (see the module docstring)")
    parser.add_argument("variant", help="llvm_ad_rgb or scalar_rgb")
    parser.add_argument("threads", type=int, help="Dr.Jit worker threads")
    args = parser.parse_args()

    mi.set_variant(args.variant)
    dr.set_thread_count(args.threads)
    gltf_bsdf = gltf_bsdf_class()
    mi.register_bsdf("gltf_metallic_roughness", lambda props: gltf_bsdf(props))
    with open(args.job) as f:
        job = json.load(f)
    scenes = {}
    for sampler in job["samplers"]:
        spec = scene_dict(job)
        spec["sensor"]["sampler"] = {"type": sampler, "sample_count": 16}
        scenes[sampler] = mi.load_dict(spec)
    print(f"ready {mi.__version__}", flush=True)
    for line in sys.stdin:
        if not line.strip():
            continue
        sampler, spp, seed, out = line.split()
        start, cpu = time.perf_counter(), time.process_time()
        image = np.array(mi.render(scenes[sampler], spp=int(spp), seed=int(seed)), dtype=np.float32)[:, :, :3]
        seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
        np.save(out, image)
        print(f"done {seconds:.6f} {cpu:.6f}", flush=True)


if __name__ == "__main__":
    main()
