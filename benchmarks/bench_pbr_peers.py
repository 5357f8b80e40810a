"""rtmesh's glTF metallic-roughness materials against Mitsuba 3, on matched scenes.

What is compared
----------------
Each case is one object with ONE glTF ``pbrMetallicRoughness`` material, lit by one light,
rendered by rtmesh and by Mitsuba 3 (``path`` integrator) from the same camera:

- geometry: ``sphere`` (trimesh icosphere, 5 subdivisions, radius 1, exact unit normals) or
  ``duck`` (the triangles and normals of ``../shared/assets/real/Duck.glb``, a glTF asset with
  one mesh; centred on its bounding box and scaled so its largest half-extent is 1);
- material: ``metal`` (metallic 1, base colour (0.95, 0.64, 0.54): copper-like F0) or
  ``dielectric`` (metallic 0, base colour (0.8, 0.3, 0.2)), each at roughness 0.1, 0.3, 0.7;
  written with trimesh (``PBRMaterial``, GLB export) so rtmesh reads the material exactly as
  a user's file (trimesh stores the base colour in 8 bits: the factors rtmesh reads, e.g.
  0.949 for 0.95, are read back from the file and given to Mitsuba);
- light: ``point`` (intensity 25 W/sr at (2.5, 3, 3), black background) or ``env``
  (``rtmesh/scene/studio.exr``, made by benchmarks/make_studio.py, as background with
  ``lighting = true``, unturned: the key softbox up and to the front-left of the camera; Mitsuba
  ``envmap``).

rtmesh renders a scene file (``lights = []`` or one ``[[lights]]`` point light,
``[environment] ambient = 0``, ``[render] max_depth``, ``cutoff = 0``) that includes the GLB;
rtmesh's ``max_depth`` counts bounces after the camera ray, Mitsuba's ``max_depth`` counts
path segments with the light connection, so Mitsuba gets ``max_depth + 2``: 6 and 8 under the
environment (interreflections of the duck included), 0 and 2 under the point light (direct
light only: the BRDF under a delta light; paths that bounce off a glossy part of the duck
before they reach the point light are caustics neither renderer samples well).

Three Mitsuba models stand for the material:

- ``gltf``: the BRDF of the glTF 2.0 specification's Appendix B written as a Mitsuba BSDF in
  Python (benchmarks/peers_mitsuba_pbr.py, ``GltfBSDF``): GGX with alpha = roughness^2,
  height-correlated Smith visibility, Schlick Fresnel (F0 = base colour for metals, 0.04 for
  the dielectric layer, which takes ``1 - F`` from the Lambert ``base / pi`` below it).  This
  is the model rtmesh implements; the rtmesh-vs-``gltf`` error of a correct implementation
  is at the noise floor.  It tests rtmesh's integration (light units, sampling, MIS, the
  environment's orientation) with the BRDF held fixed;
- ``principled``: Mitsuba's Disney BSDF (``base_color``, ``metallic``, ``roughness``,
  ``specular = 0.5`` i.e. eta 1.5, F0 = 0.04).  At metallic 1 its lobe is GGX (alpha =
  roughness^2) with Schlick Fresnel of F0 = base colour, as glTF's, but with Smith's
  *separable* masking-shadowing ``G1(wi) G1(wo)`` instead of the height-correlated form: a
  little darker at grazing angles and high roughness.  At metallic 0 it differs more: its
  diffuse lobe is Disney's (``(1 - F_i/2)(1 - F_o/2)`` plus a roughness-dependent
  retro-reflection, not ``(1 - F) base / pi``), its specular Fresnel is the exact dielectric
  one of eta 1.5 rather than Schlick's, and the diffuse is not reduced by the specular's
  Fresnel;
- ``roughplastic`` (metallic 0 only): GGX of alpha = roughness^2 with the exact Fresnel of
  ``int_ior = 1.5`` and separable Smith G, over a diffuse base of
  ``base (1 - F_dr)^-1 eta^-2 T(wi) T(wo) / pi`` (``nonlinear = false``: internal reflections
  of the coating, T the rough interface's transmittance): brighter and less saturated at
  normal incidence than glTF's ``(1 - F) base / pi``, darker towards grazing angles.

The column ``peer_vs_gltf`` gives, for ``principled`` and ``roughplastic``, the relative RMSE
between that Mitsuba model and Mitsuba's ``gltf`` on the same case: the model difference
alone, independent of rtmesh.

Checks (they test the set-up, not the material model):

- ``check-background``: the environment alone (rtmesh's scene holds a tiny sphere behind the
  camera, out of view); every pixel counts.  Mitsuba's ``envmap`` reads its image with
  ``u = atan2(d.x, -d.z) / 2 pi`` (texel-centred columns) and ``v = acos(d.y) / pi`` with
  *align-corners* rows (row r at ``theta = r pi / (H - 1)``); rtmesh's lat-long map has
  ``u = 0.5 + atan2(z, x) / 2 pi`` and texel-centred rows (rtmesh/sampling/warps.py,
  docs/SCENE_FORMAT.md).  A rotation of +90 degrees about +Y (``to_world``) turns Mitsuba's
  azimuth into rtmesh's, and Mitsuba is given a ``2 H + 1`` row image sampled from rtmesh's
  own bilinear lookup (its rows fall on rtmesh's texel centres and the edges between them,
  poles included), so both renderers see the same radiance function, not just the same file;
- ``check-mirror``: a perfect mirror sphere (rtmesh ``mirror = 1``, Mitsuba conductor
  ``none``) in the environment: reflection directions and the map together;
- ``check-lambert-point`` and ``check-lambert-env``: a Lambertian sphere (rtmesh scene-file
  material ``diffuse = 0.8``, Mitsuba ``diffuse`` 0.8).  rtmesh's Blinn-Phong model has no
  1/pi (docs/SCENE_FORMAT.md): a point light of intensity I gives ``kd I cos / d^2`` and a sky
  of radiance L gives ``kd pi L``, Mitsuba's ``albedo / pi`` BSDF a pi times smaller value.
  These rows compare rtmesh / pi (``rtmesh_scale``) with Mitsuba: agreement shows that
  rtmesh's incident irradiance is I / d^2 from a point light of intensity I (Mitsuba's
  ``point`` emitter in W/sr) and pi L from a uniform sky, so a 1/pi-normalised glTF BRDF under
  the same light matches Mitsuba's with the same intensity.

Metric
------
Over the object's pixels, the pixels whose 8 x 8 grid of sub-pixel camera rays (rtmesh's
camera, rtmesh's BVH) all hit the object where its shading normal faces the camera
(silhouette pixels, whose value depends on the background, are left out, and so are the
duck's creases, ``creased_pixels``, where rtmesh bends shading normals that face away
toward the viewer and Mitsuba shows black, see :func:`benchmarks.pbr_cases.object_mask`;
``check-background`` uses every pixel), and the three channels:

    rel_rmse   = sqrt(mean((rtmesh - mitsuba)^2)) / mean(mitsuba)
    mean_ratio = mean(rtmesh) / mean(mitsuba)

``mean_ratio`` far from 1 is bias (brightness); ``rel_rmse`` well above ``noise_floor`` with
``mean_ratio`` near 1 is a difference in shape (highlight size, Fresnel falloff, orientation).
Each renderer renders the case twice with half the samples (rtmesh seeds 1 and 2, Mitsuba
seeds 0 and 1); their mean is the image compared, and ``RMSE(half_a - half_b) / 2`` (over
the same pixels, divided by the same mean) estimates the noise of that mean.
``noise_floor = sqrt(rtmesh_noise^2 + mitsuba_noise^2)`` is the ``rel_rmse`` two renders of
the same expected image would show.  rtmesh's ``jittered`` halves are each stratified but not
jointly, so its estimate is a little above the noise of one full-spp render.

Running
-------
Mitsuba runs in its own venv (``sh benchmarks/peers_setup.sh``; ``--venv``, default
``$RTMESH_PEERS_VENV`` or ``/tmp/peers-venv``) through benchmarks/peers_mitsuba_pbr.py, launched
by :func:`benchmarks._lib.run_peer` (HOME in a temporary folder, ``DRJIT_LIBLLVM_PATH``);
variant ``llvm_ad_rgb`` (``scalar_rgb`` when asked: far slower with the Python BSDF).
Mitsuba's images are cached in ``--cache`` (default ``/tmp/rtmesh-pbr-peers``) under a hash
of everything they depend on (job, mesh and environment bytes, the worker's source), so a
rerun after a change to rtmesh renders only rtmesh.  Side-by-side PNGs (rtmesh, Mitsuba's
models, signed difference) go to ``--png-dir``.

Usage::

    python -m benchmarks.bench_pbr_peers [--cases 'sphere-*,check-*'] [--list] [--size 128]
                                    [--spp 256] [--point-spp 8192]
                                    [--mitsuba-spp 2048] [--mitsuba-point-spp 8192]
                                    [--models gltf,principled,roughplastic] [--variant llvm_ad_rgb]
                                    [--cache /tmp/rtmesh-pbr-peers] [--png-dir DIR] [--png-cases GLOBS]
                                    [--out docs/pbr_peers.csv] [--no-write]
    /tmp/peers-venv/bin/python -m benchmarks.peers_mitsuba_pbr --self-test   # checks the glTF BSDF
"""

import argparse
import csv
import datetime
import fnmatch
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import rtmesh
from benchmarks._lib import (PEERS_VENV, ROOT, machine, peer_python, publish, relative_rmse, rtmesh_commit,
                             run_peer, write_side_by_side)
from benchmarks.pbr_cases import MAX_DEPTH, MODELS, all_cases, mitsuba_job, prepare, sample_counts

SECTION = "glTF metallic-roughness against Mitsuba 3"
FIELDS = ["case", "geometry", "light", "material", "metallic", "roughness", "mitsuba_bsdf", "rtmesh_spp",
          "mitsuba_spp", "pixels", "creased_pixels", "rel_rmse", "noise_floor", "rtmesh_noise", "mitsuba_noise",
          "mean_ratio", "peer_vs_gltf", "rtmesh_scale", "rtmesh_seconds", "mitsuba_seconds"]


# how to read the table, for docs/BENCHMARKS.md (the module docstring has the details)
NOTES = (
    "How to read it:",
    "",
    "- `gltf` rows test rtmesh against the glTF 2.0 BRDF itself (Appendix B, as a Python BSDF in "
    "Mitsuba, checked by `peers_mitsuba_pbr.py --self-test`: Mitsuba's chi-square test of its sampling, "
    "weight = eval / pdf, and D and F against Mitsuba's `principled`): a correct rtmesh is at the noise "
    "floor with a mean ratio of 1.",
    "- `principled` and `roughplastic` rows say how far Mitsuba's own models are from glTF's (`peer vs "
    "gltf`, Mitsuba against Mitsuba, same seeds): at metallic 1 `principled` differs only by Smith's "
    "separable G (0.1 % or less at roughness 0.1 and 0.3, 1-2 % at 0.7, darker at grazing angles); at "
    "metallic 0 `principled` is 4-12 % off (Disney's diffuse with retro-reflection, the exact "
    "dielectric Fresnel, no `1 - F` on the diffuse) and `roughplastic` 8-16 % at roughness 0.1 and 0.3 "
    "and 56-67 % at 0.7, where its diffuse base, seen through the single-scattering transmittance of "
    "the rough interface, reflects about 0.55 of glTF's `(1 - F) base / pi`.",
    "- The `check-*` rows test the set-up: `check-background` the environment's orientation and "
    "lat-long mapping (+90 degrees about +Y for Mitsuba's `envmap`, and a 2H+1-row resampling of the "
    "image: Mitsuba's rows are align-corners, rtmesh's texel-centred), `check-mirror` reflections "
    "of it, `check-lambert-*` the light units (rtmesh's Blinn-Phong diffuse has no 1/pi: rtmesh / pi "
    "is compared, so a point light of intensity I gives I / d^2 in both and a 1/pi-normalised BRDF "
    "matches Mitsuba's `point` of the same intensity).",
    "- Under the point light only direct light is compared (rtmesh `max_depth` 0, Mitsuba 2); at "
    "roughness 0.1 the metal's highlight is smaller than a pixel, so its noise floor stays high.",
    "- Pixels where a smooth shading normal faces away from the camera (the duck's creases, "
    "`creased_pixels` in the CSV) are left out: rtmesh bends such normals toward the viewer, Mitsuba's "
    "one-sided BSDFs show black there (0.9 % rel. RMSE on the duck under the point light, with any "
    "BRDF, Lambert's included).",
)


# ---------------------------------------------------------------- running
def run_mitsuba(jobs, args, folder):
    """Render the jobs not in the cache (one worker process); False if the worker failed."""
    todo = [job for job in jobs if not os.path.exists(job["out"])]
    print(f"Mitsuba: {len(jobs) - len(todo)} of {len(jobs)} images cached in {args.cache}", flush=True)
    if not todo:
        return True
    if peer_python(args.venv) is None:
        print(f"bench_pbr_peers: no Mitsuba venv at {args.venv} (run `sh benchmarks/peers_setup.sh`)")
        return False
    spec = Path(folder) / "mitsuba_jobs.json"
    spec.write_text(json.dumps(todo))
    # write into the cache only when complete: the worker writes a temporary name first
    final = {job["name"]: job["out"] for job in todo}
    for job in todo:
        job["out"] = job["out"][:-4] + ".partial.npz"
    spec.write_text(json.dumps(todo))
    done = run_peer("peers_mitsuba_pbr", [spec, args.variant], os.path.join(folder, "home"), args.venv,
                    capture=False)
    for job in todo:
        if os.path.exists(job["out"]):
            os.replace(job["out"], final[job["name"]])
        job["out"] = final[job["name"]]
    if done.returncode != 0:
        print(f"bench_pbr_peers: the Mitsuba worker failed (exit status {done.returncode})")
        return False
    return True


def render_rtmesh(prepared, spp):
    """Two half-spp rtmesh renders (seeds 1 and 2) and the seconds they took."""
    half = max(spp // 2, 1)
    start = time.perf_counter()
    halves = [rtmesh.render(prepared["scene"], prepared["settings"], spp=half, seed=seed).image
              for seed in (1, 2)]
    return [np.asarray(h, np.float64) for h in halves], time.perf_counter() - start


def compare(rt_halves, mi_halves, mask, scale):
    """The row's numbers: rel_rmse, noise floor parts and mean ratio (see the module notes)."""
    rt = [h * scale for h in rt_halves]
    image, reference = 0.5 * (rt[0] + rt[1]), 0.5 * (mi_halves[0] + mi_halves[1])
    pick = mask[:, :, None].repeat(3, axis=2)
    mean = float(reference[pick].mean())

    def rel(a, b, factor=1.0):
        return relative_rmse(a, b, mask=mask, mean=mean) * factor

    rt_noise, mi_noise = rel(rt[0], rt[1], 0.5), rel(mi_halves[0], mi_halves[1], 0.5)
    return {"rel_rmse": rel(image, reference), "rtmesh_noise": rt_noise, "mitsuba_noise": mi_noise,
            "noise_floor": math.hypot(rt_noise, mi_noise), "mean_ratio": float(image[pick].mean()) / mean,
            "image": image, "reference": reference}


def rtmesh_version():
    """The last commit of the rtmesh package being measured (in the checkout it is imported
    from), with ``+changes`` when its files differ from it; ``?`` outside git."""
    return rtmesh_commit(os.path.dirname(os.path.abspath(rtmesh.__file__)))


def markdown_table(rows):
    """The rows as a markdown table."""
    head = ("| case | Mitsuba BSDF | rel. RMSE | noise floor | mean ratio | peer vs gltf |",
            "|---|---|---:|---:|---:|---:|")
    body = [f"| {r['case']} | {r['mitsuba_bsdf']} | {r['rel_rmse']:.2%} | {r['noise_floor']:.2%} | "
            f"{r['mean_ratio']:.3f} | " + (f"{r['peer_vs_gltf']:.2%}" if r['peer_vs_gltf'] != "" else "") + " |"
            for r in rows]
    return "\n".join(head + tuple(body))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", default="*",
                        help="comma-separated glob patterns of case names, e.g. 'sphere-*,check-*' (default all)")
    parser.add_argument("--list", action="store_true", help="list the case names and exit")
    parser.add_argument("--size", type=int, default=128, help="image width and height")
    parser.add_argument("--spp", type=int, default=256,
                        help="rtmesh samples per pixel under the environment (two halves)")
    parser.add_argument("--point-spp", type=int, default=8192,
                        help="rtmesh samples per pixel under the point light (direct light only: cheap)")
    parser.add_argument("--mitsuba-spp", type=int, default=2048,
                        help="Mitsuba samples per pixel under the environment: twice a square")
    parser.add_argument("--mitsuba-point-spp", type=int, default=8192,
                        help="Mitsuba samples per pixel under the point light: twice a square")
    parser.add_argument("--models", default=",".join(MODELS), help="Mitsuba models for the glTF cases")
    parser.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant (llvm_ad_rgb or scalar_rgb)")
    parser.add_argument("--venv", default=PEERS_VENV, help="the peers' venv (benchmarks/peers_setup.sh)")
    parser.add_argument("--cache", default="/tmp/rtmesh-pbr-peers", help="folder of cached Mitsuba images")
    parser.add_argument("--png-dir", default="/tmp/rtmesh-pbr-peers/png", help="side-by-side PNGs")
    parser.add_argument("--png-cases", default="check-*,*-r0.3",
                        help="glob patterns of the cases that get a side-by-side PNG")
    parser.add_argument("--out", default=str(ROOT / "docs" / "pbr_peers.csv"))
    parser.add_argument("--no-write", action="store_true",
                        help="print only; leave docs/pbr_peers.csv and docs/BENCHMARKS.md alone")
    args = parser.parse_args(argv)
    for name in ("mitsuba_spp", "mitsuba_point_spp"):
        half = getattr(args, name) // 2
        if half < 1 or math.isqrt(half) ** 2 != half:
            parser.error(f"--{name.replace('_', '-')} must be twice a square (two stratified halves), "
                         "e.g. 512, 2048, 8192")
    for name in ("spp", "point_spp"):
        if getattr(args, name) < 2 or getattr(args, name) % 2:
            parser.error(f"--{name.replace('_', '-')} must be even (two halves)")
    models = [m.strip() for m in args.models.split(",") if m.strip()]
    unknown = set(models) - set(MODELS)
    if unknown:
        parser.error(f"unknown models {sorted(unknown)}; choose from {', '.join(MODELS)}")
    patterns = [p.strip() for p in args.cases.split(",") if p.strip()]
    cases = [c for c in all_cases(models) if any(fnmatch.fnmatch(c.name, p) for p in patterns)]
    if args.list:
        print("\n".join(f"{c.name}: {', '.join(c.models)}" for c in cases))
        return 0
    if not cases:
        parser.error(f"no case matches {args.cases!r} (see --list)")
    os.makedirs(args.cache, exist_ok=True)
    os.makedirs(args.png_dir, exist_ok=True)
    machine_at_start = machine()
    started = time.perf_counter()

    with tempfile.TemporaryDirectory(prefix="rtmesh-pbr-peers-") as folder:
        prepared, jobs = {}, {}
        for case in cases:
            prepared[case.name] = prepare(case, folder, args)
            for model in case.models:
                jobs[(case.name, model)] = mitsuba_job(case, model, prepared[case.name], args)
        mitsuba_start = time.perf_counter()
        ok = run_mitsuba(list(jobs.values()), args, folder)
        mitsuba_wall = time.perf_counter() - mitsuba_start
        rows, notes = [], []
        version = variant = "?"
        for case in cases:
            p = prepared[case.name]
            references = {}
            for model in case.models:
                out = jobs[(case.name, model)]["out"]
                if os.path.exists(out):
                    data = np.load(out)
                    references[model] = data
                    version, variant = str(data["version"]), str(data["variant"])
            if not references:
                print(f"{case.name}: no Mitsuba image (skipped)")
                continue
            rt_spp, mi_spp = sample_counts(case, args)
            rt_halves, rt_seconds = render_rtmesh(p, rt_spp)
            gltf = None
            if "gltf" in references:
                g = references["gltf"]
                gltf = 0.5 * (np.asarray(g["half0"], np.float64) + np.asarray(g["half1"], np.float64))
            images = {}
            for model, data in references.items():
                mi_halves = [np.asarray(data["half0"], np.float64), np.asarray(data["half1"], np.float64)]
                result = compare(rt_halves, mi_halves, p["mask"], case.rtmesh_scale)
                images[model] = result["reference"]
                peer = ""
                if gltf is not None and model != "gltf":
                    peer = compare([result["reference"]] * 2, [gltf, gltf], p["mask"], 1.0)["rel_rmse"]
                f = p["factors"] or {}
                rows.append({
                    "case": case.name, "geometry": case.geometry, "light": case.light, "material": case.material,
                    "metallic": f.get("metallic", ""), "roughness": "" if case.roughness is None else case.roughness,
                    "mitsuba_bsdf": model, "rtmesh_spp": rt_spp, "mitsuba_spp": mi_spp, "pixels": int(p["mask"].sum()),
                    "creased_pixels": p["creased"],
                    "rel_rmse": result["rel_rmse"], "noise_floor": result["noise_floor"],
                    "rtmesh_noise": result["rtmesh_noise"], "mitsuba_noise": result["mitsuba_noise"],
                    "mean_ratio": result["mean_ratio"], "peer_vs_gltf": peer,
                    "rtmesh_scale": case.rtmesh_scale, "rtmesh_seconds": rt_seconds,
                    "mitsuba_seconds": float(data["seconds"])})
                r = rows[-1]
                print(f"{case.name:32s} {model:13s} rel RMSE {r['rel_rmse']:8.2%}  noise {r['noise_floor']:6.2%}  "
                      f"(rtmesh {r['rtmesh_noise']:.2%}, Mitsuba {r['mitsuba_noise']:.2%})  "
                      f"mean ratio {r['mean_ratio']:.3f}  "
                      f"rtmesh {rt_seconds:.1f} s", flush=True)
            if any(fnmatch.fnmatch(case.name, pat.strip()) for pat in args.png_cases.split(",") if pat.strip()):
                rt_image = 0.5 * (rt_halves[0] + rt_halves[1]) * case.rtmesh_scale
                notes.append(write_side_by_side(Path(args.png_dir) / f"{case.name}.png", rt_image,
                                                images, p["mask"]))
    total = time.perf_counter() - started
    if not rows:
        print("bench_pbr_peers: nothing compared")
        return 1

    table = markdown_table(rows)
    print()
    print(table)
    print()
    print("\n".join(notes))
    print(f"total {total:.0f} s, of which Mitsuba {mitsuba_wall:.0f} s (cached images cost nothing)")
    if args.no_write:
        return 0 if ok else 1
    with open(args.out, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=FIELDS)
        writer.writeheader()
        for r in rows:
            writer.writerow({k: (f"{v:.5g}" if isinstance(v, float) else v) for k, v in r.items()})
    print(f"written to {args.out}")
    words = ["python -m benchmarks.bench_pbr_peers"]
    for name, default in (("cases", "*"), ("size", 128), ("spp", 256), ("point_spp", 8192), ("mitsuba_spp", 2048),
                          ("mitsuba_point_spp", 8192),
                          ("models", ",".join(MODELS)), ("variant", "llvm_ad_rgb")):
        if getattr(args, name) != default:
            words.append(f"--{name.replace('_', '-')} '{getattr(args, name)}'")
    text = "\n".join([
        f"## {SECTION}",
        "",
        f"Command: `{' '.join(words)}`, rtmesh {rtmesh_version()} (Mitsuba {version} `{variant}` in its own venv, "
        "`sh benchmarks/peers_setup.sh`); "
        f"rows in `docs/pbr_peers.csv`; what is compared, the Mitsuba models and the metric are in the "
        f"tool's docstring.",
        "",
        f"- Machine: {machine_at_start}; date {datetime.date.today().isoformat()}; {total:.0f} s in all",
        f"- {args.size} x {args.size} pixels; spp under the environment / the point light: rtmesh {args.spp} / "
        f"{args.point_spp}, Mitsuba {args.mitsuba_spp} / {args.mitsuba_point_spp} (`path`, stratified; "
        f"max_depth {MAX_DEPTH['env'] + 2} under the environment, "
        f"{MAX_DEPTH['point'] + 2} under the point light); rel. RMSE and mean ratio "
        "over the object's pixels (all 8 x 8 sub-pixel rays hit it, with shading normals facing the camera); "
        "noise floor = the rel. RMSE the two "
        "renders' noise alone would give; peer vs gltf = Mitsuba's model against Mitsuba's exact glTF BRDF",
        "",
        table,
        "",
        *NOTES,
        "",
    ])
    publish(text, SECTION, write=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
