"""Mitsuba 3 side of benchmarks/bench_peers.py; runs inside the peers venv, never imports rtmesh.

Reads the scene description bench_peers.py wrote (JSON next to two PLY meshes with vertex
normals), renders it with Mitsuba's ``direct`` integrator in one variant at each requested
sample count, and writes the images and the wall times of every run to an ``.npz`` file.

Each sample count is rendered once untimed first (the LLVM variant compiles its kernels
then), then ``--runs`` times with the clock running; every run uses seed 0, so the runs do
the same work and the image of the last one is kept.

Usage, from the repository root (bench_peers.py runs it through :func:`benchmarks._lib.run_peer`)::

    /tmp/peers-venv/bin/python -m benchmarks.peers_mitsuba SCENE.json VARIANT OUT.npz \
        --spp 1,4,16 --runs 5 [--reference-spp 1024]
"""

import argparse
import json
import time

import mitsuba as mi
import numpy as np


def sensor_dict(camera, width, height, sampler):
    """Mitsuba's pinhole camera matching rtmesh's :class:`rtmesh.scene.camera.Camera`.

    Parameters
    ----------
    camera : dict
        ``position``, ``look_at``, ``up`` (3 numbers each) and ``fov``: rtmesh's vertical
        field of view in degrees (Mitsuba's ``fov`` with ``fov_axis = "y"``).
    width, height : int
        Image size in pixels.
    sampler : dict
        Mitsuba sampler plugin, e.g. ``{"type": "stratified", "sample_count": 4}``.

    Returns
    -------
    dict
        A ``perspective`` sensor with a box pixel filter (each sample counts in its own
        pixel only, like rtmesh's film) and an RGB ``hdrfilm``; ``look_at`` builds the frame
        as rtmesh does (``up`` made orthogonal to the view), image x to the right, row 0 at
        the top.
    """
    return {
        "type": "perspective",
        "fov": camera["fov"],
        "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(origin=camera["position"], target=camera["look_at"],
                                                   up=camera["up"]),
        "film": {"type": "hdrfilm", "width": width, "height": height,
                 "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        "sampler": sampler,
    }


def scene_dict(spec):
    """The Mitsuba scene for the spec: the same meshes, camera, light and Lambert albedo.

    The point light's intensity is already scaled by pi in the spec (Mitsuba's diffuse
    BSDF is albedo / pi; rtmesh's Lambert term is kd cos / d^2 without it).
    """
    bsdf = {"type": "diffuse", "reflectance": {"type": "rgb", "value": spec["albedo"]}}
    return {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
        "sensor": sensor_dict(spec["camera"], spec["width"], spec["height"],
                              {"type": "stratified", "sample_count": 4}),
        "light": {"type": "point", "position": spec["light_position"],
                  "intensity": {"type": "rgb", "value": spec["mitsuba_intensity"]}},
        **{name: {"type": "ply", "filename": path, "face_normals": False, "bsdf": bsdf}
           for name, path in spec["meshes"].items()},
    }


def render(scene, spp):
    """One render, evaluated and copied to the host (so the clock covers all of it)."""
    return np.array(mi.render(scene, spp=spp, seed=0), dtype=np.float32)[:, :, :3]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("spec")
    parser.add_argument("variant")
    parser.add_argument("out")
    parser.add_argument("--spp", default="1,4,16")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--reference-spp", type=int, default=0, help="also render a reference (not timed)")
    args = parser.parse_args()

    mi.set_variant(args.variant)
    with open(args.spec) as f:
        spec = json.load(f)
    scene = mi.load_dict(scene_dict(spec))
    result = {"variant": np.array(args.variant), "version": np.array(mi.__version__)}
    for spp in (int(s) for s in args.spp.split(",")):
        render(scene, spp)  # warm-up: kernel compilation (LLVM), first-touch memory
        times = []
        for _ in range(args.runs):
            start = time.perf_counter()
            image = render(scene, spp)
            times.append(time.perf_counter() - start)
        result[f"image_{spp}"] = image
        result[f"times_{spp}"] = np.array(times)
        print(f"{args.variant} spp {spp}: median {np.median(times):.3f} s", flush=True)
    if args.reference_spp:
        result["reference"] = render(scene, args.reference_spp)
    np.savez(args.out, **result)


if __name__ == "__main__":
    main()
