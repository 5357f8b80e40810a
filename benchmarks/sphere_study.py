"""Speed against error for icospheres: rtmesh's image against the exact sphere.

For a lit (Blinn-Phong) sphere and an absorbing glass sphere, renders the icosphere at
rising subdivision with rtmesh and compares each image with the exact analytic sphere
(benchmarks/analytic_sphere.py), next to the render time: the trade-off a user picks from.

    python -m benchmarks.sphere_study --out docs/sphere_study.csv --plot docs/images/sphere_study.png
    python -m benchmarks.sphere_study --from-csv docs/sphere_study.csv --plot docs/images/sphere_study.png

Writes a CSV (case, subdivisions, triangles, seconds, rmse, relative_error: the RMSE over the
reference's mean, :func:`benchmarks._lib.relative_rmse`) and, if matplotlib is installed, a
log-log plot of error against time.
"""

import argparse
import csv
import sys
import time

import numpy as np
import trimesh

from benchmarks._lib import relative_rmse
from benchmarks.analytic_sphere import AnalyticSphere, render_analytic_image
from rtmesh.lights.point_lights import PointLight
from rtmesh.materials.table import Material
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import MeshPart, Scene

CASES = {
    "lit": Material("lit", diffuse=[0.7, 0.5, 0.3], specular=0.4, shininess=60),
    "glass": Material("glass", diffuse=0.0, specular=0.5, shininess=200, transmission=1.0,
                      ior=1.5, absorption=[0.8, 0.3, 0.1]),
}
CAMERA = Camera(position=[0.0, -3.2, 0.6], look_at=[0.0, 0.0, 0.0], up=[0.0, 0.0, 1.0], fov=40.0)
LIGHTS = [PointLight([2.0, -2.5, 3.0], 25.0)]
AMBIENT = np.full(3, 0.05)
BACKGROUND = np.array([0.3, 0.4, 0.5])


def icosphere_scene(material, subdivisions):
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    part = MeshPart("sphere", mesh.vertices, mesh.faces, 0, mesh.vertex_normals)
    return Scene.from_parts([part], [material], LIGHTS, CAMERA, ambient=AMBIENT, background=BACKGROUND)


def median_time(fn, runs):
    times, result = [], None
    for _ in range(runs):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256, help="image width and height")
    parser.add_argument("--max-subdivisions", type=int, default=7)
    parser.add_argument("--runs", type=int, default=3, help="timed runs per point (median)")
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--out", default="sphere_study.csv")
    parser.add_argument("--plot", default=None)
    parser.add_argument("--from-csv", default=None,
                        help="plot the rows of an earlier run instead of rendering")
    args = parser.parse_args(argv)

    if args.from_csv:
        with open(args.from_csv, newline="") as f:
            rows = [dict(r, seconds=float(r["seconds"])) for r in csv.DictReader(f)]
        plot(rows, args.plot or "sphere_study.png")
        return 0
    rows = []
    for case, material in CASES.items():
        reference = render_analytic_image(
            AnalyticSphere(np.zeros(3), 1.0, material, LIGHTS, AMBIENT, BACKGROUND),
            CAMERA, args.size, args.size, max_depth=5)
        for subdivisions in range(args.max_subdivisions + 1):
            scene = icosphere_scene(material, subdivisions)
            settings = RenderSettings(width=args.size, height=args.size, spp=1, sampler="regular",
                                      max_depth=5, threads=args.threads)
            integrator = Integrator(scene, settings)
            integrator.render()  # warm-up
            seconds, result = median_time(integrator.render, args.runs)
            rmse = float(np.sqrt(np.mean((result.image.astype(np.float64) - reference) ** 2)))
            relative = relative_rmse(result.image, reference)
            rows.append({"case": case, "subdivisions": subdivisions, "triangles": len(scene.faces),
                         "seconds": round(seconds, 4), "rmse": f"{rmse:.5g}",
                         "relative_error": f"{relative:.5g}"})
            print(f"{case:6s} subdiv {subdivisions}  {len(scene.faces):7d} tris  "
                  f"{seconds:7.3f} s  RMSE {rmse:.4g}  rel {relative:.4g}", flush=True)

    with open(args.out, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    if args.plot:
        plot(rows, args.plot)
    return 0


def plot(rows, path):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot (pip install matplotlib)", file=sys.stderr)
        return
    fig, ax = plt.subplots(figsize=(6, 4))
    for case in CASES:
        sel = [r for r in rows if r["case"] == case]
        ax.loglog([r["seconds"] for r in sel], [float(r["relative_error"]) for r in sel], "o-", label=case)
        for r in sel:
            ax.annotate(str(r["subdivisions"]), (r["seconds"], float(r["relative_error"])), fontsize=7)
    ax.set_xlabel("render time [s]")
    ax.set_ylabel("relative RMSE vs exact sphere")
    ax.set_title("icosphere subdivision: time vs error")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    sys.exit(main())
