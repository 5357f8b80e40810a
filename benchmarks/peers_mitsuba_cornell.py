"""Mitsuba 3 path-traced reference of a scene file of diffuse and emissive meshes (the Cornell box).

Runs inside the peers venv (``sh benchmarks/peers_setup.sh``), from the repository root as a
module; never imports rtmesh. It reads the
rtmesh scene file itself (``assets/cornell_box.toml``), so the reference sees the same
triangles (the same OBJ files, loaded by Mitsuba's ``obj`` plugin with flat normals), the
same camera (position, look-at, up, vertical field of view) and the same values:

- each material's ``diffuse`` becomes a Mitsuba ``diffuse`` BSDF of that reflectance (an
  albedo: Mitsuba's Lambert lobe is reflectance / pi);
- a material's ``emission`` becomes an ``area`` emitter of that radiance on every mesh of
  the material (one-sided, toward the face normal given by the winding: the Cornell light
  faces the floor);
- the integrator is Mitsuba's ``path`` (``max_depth`` -1: unbounded, Russian roulette from
  depth 5, Mitsuba's default; ``max_depth`` 2 is direct light only);
- the camera is :func:`benchmarks.peers_mitsuba.sensor_dict`'s (a ``perspective`` sensor,
  ``fov_axis = "y"``; an RGB ``hdrfilm`` with a box pixel filter: each sample counts in its
  own pixel only, as in rtmesh's film), the sampler ``independent``.

The samples are rendered in passes of ``--pass-spp`` with seeds ``--seed``, ``--seed`` + 1,
... and averaged (one render of thousands of samples a pixel would hold every sample's state
at once in the LLVM variant). The result is a linear float32 RGB EXR, row 0 at the top of
the image; ``--png`` also writes an sRGB preview.

Anything else in the scene file (lights, primitives, transforms, other material keys,
background, depth of field) is refused: the reference would no longer be the same scene.

Usage::

    /work/peers-venv/bin/python -m benchmarks.peers_mitsuba_cornell assets/cornell_box.toml \\
        tests/data/cornell_mitsuba_128.exr --width 128 --height 128 --spp 4096 --max-depth -1
"""

import argparse
import os
import sys
import tempfile
import time
import tomllib
from pathlib import Path

LLVM = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"
# before Dr.Jit starts: LLVM 19 (the system's LLVM 15 cannot compile the llvm variants'
# kernels) and a kernel cache outside the user's home
if os.path.exists(LLVM):
    os.environ.setdefault("DRJIT_LIBLLVM_PATH", LLVM)
os.environ["HOME"] = os.environ.get("RTMESH_PEERS_HOME", os.path.join(tempfile.gettempdir(), "peers-home"))
os.makedirs(os.environ["HOME"], exist_ok=True)

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402
import numpy as np  # noqa: E402

from benchmarks._lib import relative_rmse  # noqa: E402
from benchmarks.peers_mitsuba import sensor_dict  # noqa: E402

CAMERA_KEYS = {"position", "look_at", "up", "fov"}
MATERIAL_KEYS = {"diffuse", "emission"}
OBJECT_KEYS = {"name", "mesh", "material"}
ALLOWED_TOP = {"render", "camera", "environment", "materials", "objects", "lights"}


def _colour(value):
    """An rtmesh colour (one number or three) as a list of three floats."""
    return [float(value)] * 3 if isinstance(value, (int, float)) else [float(v) for v in value]


def _refuse(path, what):
    raise SystemExit(f"{path}: {what}: this reference renders diffuse and emissive meshes only")


def read_scene(path):
    """The parts of an rtmesh scene file this reference can render, checked.

    Parameters
    ----------
    path : str or Path
        A TOML scene file of mesh objects with ``diffuse`` / ``emission`` materials, an
        explicit camera, ``lights = []``, no ambient light and a black background.

    Returns
    -------
    dict
        ``camera`` (``position``, ``look_at``, ``up``, ``fov``), ``materials`` (name ->
        ``diffuse``, ``emission``) and ``objects`` (list of ``name``, ``mesh`` as an
        absolute path, ``material``).
    """
    path = Path(path)
    doc = tomllib.loads(path.read_text())
    for key in doc:
        if key not in ALLOWED_TOP:
            _refuse(path, key)
    if doc.get("lights", []) != []:
        _refuse(path, "lights")
    environment = doc.get("environment", {})
    for key, value in environment.items():
        if key not in ("ambient", "background") or any(_colour(value)):
            _refuse(path, f"environment.{key}")
    camera = doc["camera"]
    if set(camera) - CAMERA_KEYS:
        _refuse(path, "camera." + ",".join(sorted(set(camera) - CAMERA_KEYS)))
    camera = {"position": camera["position"], "look_at": camera["look_at"],
              "up": camera.get("up", [0, 1, 0]), "fov": float(camera.get("fov", 45))}
    materials = {}
    for name, table in doc.get("materials", {}).items():
        if set(table) - MATERIAL_KEYS:
            _refuse(path, f"materials.{name}." + ",".join(sorted(set(table) - MATERIAL_KEYS)))
        materials[name] = {"diffuse": _colour(table.get("diffuse", 0.7)),
                           "emission": _colour(table.get("emission", 0.0))}
    objects = []
    for i, table in enumerate(doc["objects"]):
        if set(table) - OBJECT_KEYS or "mesh" not in table or table.get("material") not in materials:
            _refuse(path, f"objects[{i}]")
        objects.append({"name": table.get("name", f"object{i}"),
                        "mesh": str((path.parent / table["mesh"]).resolve()),
                        "material": table["material"]})
    return {"camera": camera, "materials": materials, "objects": objects}


def scene_dict(scene, width, height, max_depth):
    """The Mitsuba scene dictionary of :func:`read_scene`'s result.

    Parameters
    ----------
    scene : dict
        From :func:`read_scene`.
    width, height : int
        Image size in pixels.
    max_depth : int
        Mitsuba's ``max_depth`` (-1 unbounded; rtmesh's path ``max_depth`` + 1).

    Returns
    -------
    dict
        For :func:`mitsuba.load_dict`.
    """
    result = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": max_depth},
        "sensor": sensor_dict(scene["camera"], width, height, {"type": "independent", "sample_count": 1}),
    }
    for obj in scene["objects"]:
        material = scene["materials"][obj["material"]]
        shape = {"type": "obj", "filename": obj["mesh"], "face_normals": True,
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": material["diffuse"]}}}
        if any(material["emission"]):
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": material["emission"]}}
        result[obj["name"]] = shape
    return result


def render(scene, spp, pass_spp, seed):
    """The mean of ``spp`` samples a pixel, rendered in passes of ``pass_spp`` with seeds from ``seed``.

    Returns
    -------
    image : (height, width, 3) float64
        The mean of all passes.
    halves : tuple of two (height, width, 3) float64
        The means of the even and of the odd passes (independent estimates of half the
        samples each, for :func:`noise`); ``None`` with a single pass.
    """
    sums, counts = [0.0, 0.0], [0, 0]
    done, k = 0, 0
    while done < spp:
        n = min(pass_spp, spp - done)
        image = np.array(mi.render(scene, spp=n, seed=seed + k), dtype=np.float64)[:, :, :3]
        sums[k % 2] = sums[k % 2] + image * n
        counts[k % 2] += n
        done += n
        k += 1
    image = (sums[0] + sums[1]) / spp
    halves = (sums[0] / counts[0], sums[1] / counts[1]) if counts[1] else None
    return image, halves


def noise(halves, block=8):
    """Estimated relative RMSE of the full render's pixels and ``block`` x ``block`` block means.

    The difference of two independent half renders has twice the variance of either, four
    times that of their mean: its RMSE / 2, over the image mean, estimates the full render's
    error (:func:`benchmarks._lib.relative_rmse`, as the benchmarks measure error).

    Returns
    -------
    (float, float)
        Per pixel and per block mean.
    """
    a, b = halves
    mean = 0.5 * (a + b).mean()
    return (0.5 * relative_rmse(a, b, mean=mean), 0.5 * relative_rmse(a, b, block=block, mean=mean))


def render_reference(scene, args, what):
    """Render ``args.spp`` samples in passes, write the EXR (and ``args.png``) and print what
    was rendered, its time, mean and estimated error (the arguments of :func:`main`)."""
    start = time.perf_counter()
    image, halves = render(scene, args.spp, args.pass_spp, args.seed)
    seconds = time.perf_counter() - start
    bitmap = mi.Bitmap(image.astype(np.float32), pixel_format=mi.Bitmap.PixelFormat.RGB)
    bitmap.write(args.out)
    if args.png:
        bitmap.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=True).write(args.png)
    means = ", ".join(f"{m:.5f}" for m in image.reshape(-1, 3).mean(axis=0))
    print(f"{args.out}: mitsuba {mi.__version__} {args.variant} {what}, "
          f"{args.width}x{args.height}, {args.spp} spp ({args.pass_spp} a pass, seeds {args.seed}..), "
          f"{args.threads} threads, {seconds:.1f} s; mean RGB {means}", flush=True)
    if halves is not None and args.width % 8 == 0 and args.height % 8 == 0:
        pixel, blocks = noise(halves)
        print(f"estimated relative RMSE (two halves): pixels {pixel:.4f}, 8x8 block means {blocks:.5f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", help="rtmesh scene file (TOML)")
    parser.add_argument("out", help="output EXR (linear float32 RGB)")
    parser.add_argument("--width", type=int, default=128)
    parser.add_argument("--height", type=int, default=128)
    parser.add_argument("--spp", type=int, default=4096)
    parser.add_argument("--pass-spp", type=int, default=256)
    parser.add_argument("--max-depth", type=int, default=-1, help="Mitsuba's (-1: unbounded)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--png", help="also write an sRGB preview")
    args = parser.parse_args()

    mi.set_variant(args.variant)
    dr.set_thread_count(args.threads)
    scene = mi.load_dict(scene_dict(read_scene(args.scene), args.width, args.height, args.max_depth))
    render_reference(scene, args, f"path max_depth {args.max_depth}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
