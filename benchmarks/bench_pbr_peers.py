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
toward the viewer and Mitsuba shows black, see :func:`object_mask`; ``check-background``
uses every pixel), and the three channels:

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
import dataclasses
import datetime
import fnmatch
import hashlib
import json
import math
import os
import struct
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

import rtmesh
from benchmarks._lib import (PEERS_VENV, ROOT, machine, peer_python, publish, relative_rmse, rtmesh_commit,
                             run_peer, write_ply, write_side_by_side)
from rtmesh.geometry.accel import Accel
from rtmesh.io.images import read_image
from rtmesh.scene.studio import STUDIO_PATH

SECTION = "glTF metallic-roughness against Mitsuba 3"
HERE = Path(__file__).resolve().parent
WORKER = HERE / "peers_mitsuba_pbr.py"
STUDIO = Path(STUDIO_PATH)
DUCK = ROOT.parent / "shared" / "assets" / "real" / "Duck.glb"
if not DUCK.exists():
    DUCK = Path("/work/shared/assets/real/Duck.glb")

CAMERA = {"position": [0.0, 0.6, 3.6], "look_at": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "fov": 36.0}
# the background check looks at the key softbox of studio.exr with a wide lens: its edges
# move with any error in azimuth or elevation (the view of CAMERA shows only the smooth
# grey cyclorama; the mirror sphere shows the rest)
BACKGROUND_CAMERA = {"position": [0.0, 0.0, 0.0], "look_at": [-0.55, 0.65, 0.52], "up": [0.0, 1.0, 0.0], "fov": 90.0}
POINT_LIGHT = {"position": [2.5, 3.0, 3.0], "intensity": 25.0}  # W/sr, both renderers
MATERIALS = {
    "metal": {"base_color": (0.95, 0.64, 0.54), "metallic": 1.0},
    "dielectric": {"base_color": (0.8, 0.3, 0.2), "metallic": 0.0},
}
ROUGHNESS = (0.1, 0.3, 0.7)
GEOMETRIES = ("sphere", "duck")
LIGHTS = ("point", "env")
LAMBERT_ALBEDO = 0.8
CHECKS = ("check-background", "check-mirror", "check-lambert-point", "check-lambert-env")
# rtmesh bounces after the camera ray (Mitsuba: + 2): several under the environment; none
# under the point light, where paths bouncing between glossy parts of the duck before they
# reach the light are caustics that neither renderer can sample well (one such path at
# roughness 0.1 made Mitsuba's mean 500 times rtmesh's at 1024 spp)
MAX_DEPTH = {"env": 6, "point": 0}
MITSUBA_ROTATE_Y = 90.0  # degrees: Mitsuba's envmap frame -> rtmesh's lat-long frame
MODELS = ("gltf", "principled", "roughplastic")
MASK_GRID = 8  # sub-pixel rays per side deciding the object's pixels
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


@dataclasses.dataclass
class Case:
    """One matched scene.

    Attributes
    ----------
    name : str
        ``geometry-light-material-rROUGHNESS`` or a ``check-...`` name.
    geometry : {"sphere", "duck", "none"}
    light : {"point", "env"}
    material : str
        ``metal``, ``dielectric``, ``lambert``, ``mirror`` or ``none``.
    roughness : float or None
    models : tuple of str
        Mitsuba BSDF models rendered for it.
    rtmesh_scale : float
        Factor applied to rtmesh's image before comparing (1 / pi for the Lambert checks).
    camera : dict
        ``position``, ``look_at``, ``up``, ``fov`` (rtmesh's vertical fov, degrees).
    """

    name: str
    geometry: str
    light: str
    material: str
    roughness: float | None
    models: tuple
    rtmesh_scale: float = 1.0
    camera: dict = dataclasses.field(default_factory=lambda: dict(CAMERA))

    @property
    def pbr(self):
        """True for the glTF material cases."""
        return self.material in MATERIALS


def all_cases(models):
    """Every case, checks first, each with the Mitsuba models that apply to it."""
    cases = [Case("check-background", "none", "env", "none", None, ("background",), camera=BACKGROUND_CAMERA),
             Case("check-mirror", "sphere", "env", "mirror", None, ("mirror",)),
             Case("check-lambert-point", "sphere", "point", "lambert", None, ("diffuse",), 1.0 / math.pi),
             Case("check-lambert-env", "sphere", "env", "lambert", None, ("diffuse",), 1.0 / math.pi)]
    for geometry in GEOMETRIES:
        for light in LIGHTS:
            for material, values in MATERIALS.items():
                for roughness in ROUGHNESS:
                    wanted = tuple(m for m in models if m != "roughplastic" or values["metallic"] == 0.0)
                    cases.append(Case(f"{geometry}-{light}-{material}-r{roughness:g}", geometry, light,
                                      material, roughness, wanted))
    return cases


# ---------------------------------------------------------------- the files rtmesh reads
def geometry_mesh(name, camera):
    """The mesh of a geometry, with its vertex normals, in the scene's frame (+Y up).

    ``camera`` places the background check's hidden sphere.

    Returns
    -------
    trimesh.Trimesh
    """
    if name == "sphere":
        sphere = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
        vertices = np.asarray(sphere.vertices)
        normals = vertices / np.linalg.norm(vertices, axis=1, keepdims=True)
        return trimesh.Trimesh(vertices, sphere.faces, vertex_normals=normals, process=False)
    if name == "duck":
        loaded = trimesh.load(DUCK, force="scene")
        # the node transforms applied, one mesh (Duck.glb has one node and one primitive)
        mesh = loaded.to_geometry() if hasattr(loaded, "to_geometry") else loaded.dump(concatenate=True)
        normals = np.asarray(mesh.vertex_normals)
        low, high = mesh.bounds
        vertices = (np.asarray(mesh.vertices) - 0.5 * (low + high)) / (0.5 * float(np.max(high - low)))
        return trimesh.Trimesh(vertices, mesh.faces, vertex_normals=normals, process=False)
    if name == "none":
        # the background check: a tiny sphere one unit behind the camera, out of view
        eye, target = np.array(camera["position"]), np.array(camera["look_at"])
        back = eye + (eye - target) / np.linalg.norm(eye - target)
        tiny = trimesh.creation.icosphere(subdivisions=1, radius=0.01)
        tiny.apply_translation(back)
        return tiny
    raise ValueError(name)


def write_glb(path, mesh, material):
    """Write ``mesh`` as a GLB with one pbrMetallicRoughness material; return the factors
    the file holds (as rtmesh reads them: trimesh keeps the base colour in 8 bits).

    Returns
    -------
    dict
        ``base_color`` (3 floats), ``metallic``, ``roughness`` read back from the file's JSON.
    """
    values = MATERIALS[material["name"]]
    pbr = PBRMaterial(name=material["name"], baseColorFactor=[*values["base_color"], 1.0],
                      metallicFactor=values["metallic"], roughnessFactor=material["roughness"])
    textured = trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_normals=mesh.vertex_normals,
                               visual=TextureVisuals(material=pbr), process=False)
    data = trimesh.exchange.gltf.export_glb(trimesh.Scene(textured), include_normals=True)
    Path(path).write_bytes(data)
    factors = glb_json(data)["materials"][0]["pbrMetallicRoughness"]
    return {"base_color": [float(c) for c in factors.get("baseColorFactor", [1, 1, 1, 1])[:3]],
            "metallic": float(factors.get("metallicFactor", 1.0)),
            "roughness": float(factors.get("roughnessFactor", 1.0))}


def glb_json(data):
    """The JSON chunk of GLB bytes."""
    length, kind = struct.unpack("<II", data[12:20])
    if kind != 0x4E4F534A:
        raise ValueError("GLB without a JSON first chunk")
    return json.loads(data[20:20 + length])


def scene_text(case, mesh_file, size, spp, integrator="whitted", max_depth=None):
    """The rtmesh scene file (TOML) of a case.

    ``integrator`` and ``max_depth`` (default :data:`MAX_DEPTH` of the case's light) go into
    ``[render]``; ``cutoff = 0`` only under ``whitted`` (``path`` ignores it, with a warning).
    benchmarks/bench_equal_error.py writes its ``path`` scene with this.
    """
    c = case.camera
    depth = MAX_DEPTH[case.light] if max_depth is None else max_depth
    lines = ["lights = []" if case.light == "env" else "",
             "[render]", f"width = {size}", f"height = {size}", f"spp = {spp}",
             f'integrator = "{integrator}"', f"max_depth = {depth}",
             "cutoff = 0" if integrator == "whitted" else "", "",
             "[camera]", f"position = {c['position']}", f"look_at = {c['look_at']}", f"up = {c['up']}",
             f"fov = {c['fov']}", "",
             "[environment]", "ambient = 0", ""]
    if case.light == "env":
        lines += ["[background]", 'type = "environment"', f'file = "{STUDIO.as_posix()}"',
                  f"lighting = {'false' if case.geometry == 'none' else 'true'}", ""]
    else:
        p = POINT_LIGHT
        lines += ["[[lights]]", 'type = "point"', f"position = {p['position']}", f"intensity = {p['intensity']}", ""]
    if case.material == "lambert":
        lines += ["[materials.lambert]", f"diffuse = {LAMBERT_ALBEDO}", "specular = 0", ""]
    if case.material == "mirror":
        lines += ["[materials.mirror]", "diffuse = 0", "specular = 0", "mirror = 1", ""]
    lines += ["[[objects]]", f'mesh = "{Path(mesh_file).name}"']
    if case.material in ("lambert", "mirror"):
        lines.append(f'material = "{case.material}"')
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- Mitsuba's inputs
def mitsuba_environment_image(background, height, width):
    """Mitsuba's ``envmap`` image of rtmesh's environment background.

    Mitsuba samples rows at ``theta = r pi / (H' - 1)`` (align-corners) and columns at
    ``phi = 2 pi (c + 0.5) / W``; with ``H' = 2 H + 1`` its rows fall on rtmesh's texel
    centres (odd rows) and on the edges between them (even rows), where rtmesh's bilinear
    lookup is linear, so Mitsuba's bilinear interpolation of these samples reproduces
    rtmesh's radiance function.  The samples come from rtmesh's own lookup
    (``background.radiance``, rotation and intensity included) along Mitsuba's directions
    turned by ``to_world`` (+90 degrees about +Y: Mitsuba local ``(x, y, z)`` is world
    ``(z, y, -x)``).  Pole rows are taken just off the pole, where rtmesh's clamped lookup
    still depends on the azimuth.

    Parameters
    ----------
    background : rtmesh.scene.background.EnvironmentBackground
    height, width : int
        Rows and columns of rtmesh's image.

    Returns
    -------
    (2 H + 1, W, 3) float32
    """
    rows = 2 * height + 1
    theta = np.clip(np.arange(rows) / (rows - 1) * math.pi, 1e-6, math.pi - 1e-6)
    phi = (np.arange(width) + 0.5) / width * 2.0 * math.pi
    theta, phi = np.meshgrid(theta, phi, indexing="ij")
    local = np.stack([np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)], axis=-1)
    angle = math.radians(MITSUBA_ROTATE_Y)
    c, s = math.cos(angle), math.sin(angle)
    world = np.stack([c * local[..., 0] + s * local[..., 2], local[..., 1],
                      -s * local[..., 0] + c * local[..., 2]], axis=-1)
    radiance = background.radiance(world.reshape(-1, 3))
    return np.asarray(radiance, dtype=np.float32).reshape(rows, width, 3)


def object_mask(scene, size):
    """The pixels compared: those whose ``MASK_GRID`` x ``MASK_GRID`` sub-pixel camera rays all
    hit the scene's geometry at a point whose shading normal faces the camera.

    Where a smooth normal faces away from the viewer (in the creases of the duck: around its
    eyes, where the head meets the bill) rtmesh bends it toward the viewer
    (docs/MATERIALS.md, "Shading normals") and Mitsuba's one-sided BSDFs return black; those
    pixels would measure that convention, not the material (about 0.9 % rel. RMSE on the
    duck under the point light, with any BRDF, Lambert's included).

    Returns
    -------
    mask : (size, size) bool
    creased : int
        Pixels left out for a shading normal facing away (all rays hit).
    """
    n = MASK_GRID
    ys, xs = np.mgrid[0:size, 0:size]
    offsets = (np.arange(n) + 0.5) / n
    oy, ox = np.meshgrid(offsets, offsets, indexing="ij")
    film = np.stack([(xs[:, :, None] + ox.ravel()).ravel(), (ys[:, :, None] + oy.ravel()).ravel()], axis=1)
    origins, directions = scene.camera.generate_rays(film, size, size)
    origins = np.ascontiguousarray(np.broadcast_to(origins, directions.shape))
    directions = np.ascontiguousarray(directions)
    hits = Accel(scene.vertices, scene.faces).intersect(origins, directions)
    hit = hits.prim >= 0
    facing = hit.copy()
    if scene.vertex_normals is not None:
        # the interpolated vertex normal, barycentrics (1 - u - v, u, v) of the hit triangle
        corners = scene.faces[np.where(hit, hits.prim, 0)]
        weights = np.stack([1.0 - hits.u - hits.v, hits.u, hits.v], axis=1)
        ns = np.einsum("kj,kjc->kc", weights, scene.vertex_normals[corners])
        smooth = np.ones(len(hit), bool) if scene.smooth is None else scene.smooth[np.where(hit, hits.prim, 0)]
        facing &= ~smooth | (np.einsum("kc,kc->k", ns, directions) < 0.0)
    covered = hit.reshape(size, size, n * n).all(axis=2)
    mask = facing.reshape(size, size, n * n).all(axis=2)
    return mask, int(covered.sum() - mask.sum())


def file_hash(path):
    """sha256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# ---------------------------------------------------------------- running
def sample_counts(case, args):
    """(rtmesh spp, Mitsuba spp) of a case: the point-light cases take more (direct light
    only, one shadow ray a sample) since their small highlights need many samples a pixel
    (the metal's at roughness 0.1 is smaller than a pixel: at 2048 spp one pixel of the duck
    made rtmesh's noise floor 22 %, at 8192 it is 3 %)."""
    if case.light == "point":
        return args.point_spp, args.mitsuba_point_spp
    return args.spp, args.mitsuba_spp


def prepare(case, folder, args, **scene_options):
    """Write a case's files; load it in rtmesh.

    ``args`` needs ``size`` and the spp :func:`sample_counts` reads; ``scene_options``
    (``integrator``, ``max_depth``) go to :func:`scene_text`.

    Returns
    -------
    dict
        ``scene_file``, ``scene`` and ``settings`` (rtmesh), ``factors`` (the material as
        the file holds it, or None), ``ply`` (Mitsuba's mesh, or None), ``envmap`` (Mitsuba's
        environment ``.npy``, or None), ``mask`` and ``creased`` (see :func:`object_mask`).
    """
    case_dir = Path(folder) / case.name
    case_dir.mkdir(parents=True, exist_ok=True)
    mesh = geometry_mesh(case.geometry, case.camera)
    mesh_file = case_dir / "object.glb"
    if case.pbr:
        factors = write_glb(mesh_file, mesh, {"name": case.material, "roughness": case.roughness})
    else:
        # the checks override the file's material with a scene-file one
        factors = None
        mesh_file.write_bytes(trimesh.exchange.gltf.export_glb(trimesh.Scene(mesh), include_normals=True))
    scene_file = case_dir / "scene.toml"
    scene_file.write_text(scene_text(case, mesh_file, args.size, sample_counts(case, args)[0],
                                     **scene_options))
    scene, settings = rtmesh.load_scene(scene_file)
    ply = None
    if case.geometry != "none":
        # Mitsuba gets the triangles and normals rtmesh built from the file
        ply = case_dir / "object_mitsuba.ply"
        normals = scene.vertex_normals
        write_ply(ply, scene.vertices.astype(np.float32).astype(np.float64), scene.faces,
                  None if normals is None else normals.astype(np.float32).astype(np.float64))
    envmap = None
    if case.light == "env":
        envmap = case_dir / "envmap.npy"
        height, width = read_image(STUDIO)[0].shape[:2]
        np.save(envmap, mitsuba_environment_image(scene.background, height, width))
    mask, creased = (object_mask(scene, args.size) if case.geometry != "none"
                     else (np.ones((args.size, args.size), bool), 0))
    return {"scene_file": scene_file, "scene": scene, "settings": settings, "factors": factors, "ply": ply,
            "envmap": envmap, "mask": mask, "creased": creased}


def mitsuba_job(case, model, prepared, args):
    """The worker's job for one case and model, and its cache key."""
    factors = prepared["factors"]
    bsdf = {"model": model}
    if factors is not None:
        bsdf.update(factors)
    elif case.material == "lambert":
        bsdf["base_color"] = [LAMBERT_ALBEDO] * 3
    light = ({"type": "point", **POINT_LIGHT, "intensity": [POINT_LIGHT["intensity"]] * 3} if case.light == "point"
             else {"type": "envmap", "image": str(prepared["envmap"]), "rotate_y": MITSUBA_ROTATE_Y})
    job = {"name": f"{case.name} {model}", "width": args.size, "height": args.size, "camera": case.camera,
           "max_depth": MAX_DEPTH[case.light] + 2, "spp": sample_counts(case, args)[1], "bsdf": bsdf, "light": light,
           "mesh": str(prepared["ply"]) if prepared["ply"] else None}
    identity = dict(job, name=None, mesh=file_hash(job["mesh"]) if job["mesh"] else None,
                    light=dict(light, image=file_hash(light["image"])) if "image" in light else light,
                    variant=args.variant, worker=file_hash(WORKER), shared=file_hash(HERE / "peers_mitsuba.py"))
    key = hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:20]
    job["out"] = str(Path(args.cache) / f"{key}.npz")
    return job


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
