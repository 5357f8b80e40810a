"""The matched scenes of rtmesh's glTF metallic-roughness materials against Mitsuba 3.

The cases of benchmarks/bench_pbr_peers.py (its docstring says what is compared and why):
each case's geometry, material, light and camera (:class:`Case`, :func:`all_cases`), the
files rtmesh reads for it (a GLB with one ``pbrMetallicRoughness`` material and a scene
file), Mitsuba's inputs (the PLY of rtmesh's triangles, the environment resampled into
Mitsuba's ``envmap`` layout) and the pixels compared (:func:`object_mask`), prepared
together by :func:`prepare`, and Mitsuba's render job with its cache key
(:func:`mitsuba_job`).  benchmarks/bench_equal_error.py builds its scene from these too.
"""

import dataclasses
import hashlib
import json
import math
import struct
from pathlib import Path

import numpy as np
import trimesh
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

import rtmesh
from benchmarks._lib import ROOT, write_ply
from rtmesh.geometry.accel import Accel
from rtmesh.io.images import read_image
from rtmesh.scene.studio import STUDIO_PATH

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


# ---------------------------------------------------------------- a case, prepared
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
