"""Mitsuba 3 reference of a caustics scene file: glass and diffuse meshes under point lights.

Runs inside the peers venv (``sh benchmarks/peers_setup.sh``), from the repository root as a
module; never imports rtmesh.  It reads the rtmesh scene file itself
(``assets/effects/caustics.toml``), so the reference sees the same triangles (the same OBJ
files, loaded by Mitsuba's ``obj`` plugin with their vertex normals, placed by the objects'
``translate`` and uniform ``scale``), the same camera and the same values:

- ``model = "lambert"`` with ``diffuse`` becomes a ``diffuse`` BSDF of that reflectance;
- ``model = "dielectric"`` with ``ior`` (smooth) becomes a ``dielectric`` of that interior
  index in air;
- a ``point`` light's ``intensity`` (W/sr) becomes a ``point`` emitter of that intensity;
- the integrator is ``ptracer`` (particle tracing: light paths connected to the camera, which
  sees caustics on diffuse surfaces exactly, but not surfaces seen through or in specular
  ones: the camera cannot connect to a delta BSDF) or ``path`` (``--integrator``),
  ``max_depth`` -1;
- the camera is :func:`benchmarks.peers_mitsuba.sensor_dict`'s (box pixel filter), the
  sampler ``independent``.

The samples are rendered in passes and averaged (:func:`benchmarks.peers_mitsuba_cornell.render`);
the result is a linear float32 RGB EXR, row 0 at the top.

Usage::

    /work/peers-venv/bin/python -m benchmarks.peers_mitsuba_caustics assets/effects/caustics.toml \\
        tests/data/caustics_ptracer_64x48.exr --width 64 --height 48 --spp 65536
"""

import argparse
import sys
import tomllib
from pathlib import Path

from benchmarks.peers_mitsuba_cornell import dr, mi, render_reference  # sets up Dr.Jit first
from benchmarks.peers_mitsuba import sensor_dict

OBJECT_KEYS = {"name", "mesh", "material", "translate", "scale"}


def _refuse(path, what):
    raise SystemExit(f"{path}: {what}: this reference renders lambert and smooth dielectric meshes under "
                     "point lights only")


def read_scene(path):
    """The parts of a caustics scene file this reference renders, checked.

    Returns
    -------
    dict
        ``camera``, ``materials`` (name -> ``("lambert", albedo)`` or ``("dielectric", ior)``),
        ``objects`` (``mesh`` absolute path, ``material``, ``translate``, ``scale``) and
        ``lights`` (``position``, ``intensity``).
    """
    path = Path(path)
    doc = tomllib.loads(path.read_text())
    for key in set(doc) - {"render", "camera", "environment", "materials", "objects", "lights"}:
        _refuse(path, key)
    for key, value in doc.get("environment", {}).items():
        if key not in ("ambient", "background") or value != 0:
            _refuse(path, f"environment.{key}")
    camera = doc["camera"]
    camera = {"position": camera["position"], "look_at": camera["look_at"],
              "up": camera.get("up", [0, 1, 0]), "fov": float(camera.get("fov", 45))}
    materials = {}
    for name, table in doc["materials"].items():
        model = table.get("model")
        if model == "lambert" and set(table) <= {"model", "diffuse"}:
            value = table.get("diffuse", 0.7)
            materials[name] = ("lambert", [float(value)] * 3 if isinstance(value, (int, float)) else value)
        elif model == "dielectric" and set(table) <= {"model", "ior"}:
            materials[name] = ("dielectric", float(table.get("ior", 1.5)))
        else:
            _refuse(path, f"materials.{name}")
    objects = []
    for i, table in enumerate(doc["objects"]):
        if set(table) - OBJECT_KEYS or "mesh" not in table or table.get("material") not in materials:
            _refuse(path, f"objects[{i}]")
        objects.append({"name": table.get("name", f"object{i}"),
                        "mesh": str((path.parent / table["mesh"]).resolve()), "material": table["material"],
                        "translate": table.get("translate", [0, 0, 0]), "scale": float(table.get("scale", 1.0))})
    lights = []
    for i, table in enumerate(doc.get("lights", [])):
        if table.get("type") != "point" or set(table) - {"type", "position", "intensity"}:
            _refuse(path, f"lights[{i}]")
        value = table["intensity"]
        lights.append({"position": table["position"],
                       "intensity": [float(value)] * 3 if isinstance(value, (int, float)) else value})
    return {"camera": camera, "materials": materials, "objects": objects, "lights": lights}


def scene_dict(scene, width, height, integrator):
    """The Mitsuba scene dictionary of :func:`read_scene`'s result."""
    result = {
        "type": "scene",
        "integrator": {"type": integrator, "max_depth": -1},
        "sensor": sensor_dict(scene["camera"], width, height, {"type": "independent", "sample_count": 1}),
    }
    for obj in scene["objects"]:
        kind, value = scene["materials"][obj["material"]]
        bsdf = ({"type": "diffuse", "reflectance": {"type": "rgb", "value": value}} if kind == "lambert"
                else {"type": "dielectric", "int_ior": value, "ext_ior": 1.0})
        to_world = mi.ScalarTransform4f().translate(obj["translate"]) @ mi.ScalarTransform4f().scale(obj["scale"])
        result[obj["name"]] = {"type": "obj", "filename": obj["mesh"], "face_normals": False, "bsdf": bsdf,
                               "to_world": to_world}
    for i, light in enumerate(scene["lights"]):
        result[f"light{i}"] = {"type": "point", "position": light["position"],
                               "intensity": {"type": "rgb", "value": light["intensity"]}}
    return result


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", help="rtmesh scene file (TOML)")
    parser.add_argument("out", help="output EXR (linear float32 RGB)")
    parser.add_argument("--width", type=int, default=64)
    parser.add_argument("--height", type=int, default=48)
    parser.add_argument("--spp", type=int, default=65536)
    parser.add_argument("--pass-spp", type=int, default=1024)
    parser.add_argument("--integrator", default="ptracer", choices=("ptracer", "path"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--png", help="also write an sRGB preview")
    args = parser.parse_args()

    mi.set_variant(args.variant)
    dr.set_thread_count(args.threads)
    scene = mi.load_dict(scene_dict(read_scene(args.scene), args.width, args.height, args.integrator))
    render_reference(scene, args, args.integrator)
    return 0


if __name__ == "__main__":
    sys.exit(main())
