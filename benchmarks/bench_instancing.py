"""Meshes placed many times: Embree instances against flattened copies.

Four measurements (results in docs/BENCHMARKS.md, "Instancing"):

``crossover``
    One mesh of ``n`` triangles (an icosphere; ``n`` = 20 .. 20480) placed 400 or 1600
    times over a floor, rendered under the path integrator at 128x96, 16 spp, one thread:
    build (``Integrator``: Embree scenes and tables; the loader's copying not counted) and
    render time, instanced against the flattened copies (medians of 5, interleaved).  This sets ``rtmesh.scene.instances.MIN_TRIANGLES``.
``issue``
    A glTF of 10,000 nodes placing one ~50k-triangle mesh, loaded and rendered at 256x256,
    against a glTF of that mesh alone, each in a fresh process: peak RSS
    (``resource.getrusage``) and the time to load and build.

``loaders``
    The same through the scene-file and USD loaders: a scene file placing the torus by
    ``[[objects]] instances`` (10,000 rows of a ``.npy``) and a USD point instancer of
    10,000 instances of it, against one placement, each in a fresh process.

``passes``
    2,000 placements of a 5,120-triangle icosphere over a floor (the ``crossover`` scene),
    path integrator, 128x96, 4 spp, each in a fresh process after a warm-up run: peak RSS
    and times instanced without passes, instanced with passes and the denoiser, and
    flattened (what passes forced before the batched queries traced instances) with them.

``emitters``, ``glass``
    400 placements of a 1,280-triangle icosphere over a floor (the ``crossover`` scene) that
    glows (every placed face a light) or is glass (nested media), path integrator, 128x96,
    4 spp, each in a fresh process after a warm-up run: peak RSS and times instanced
    against flattened (what both forced before they were traced through placements).

Run from the repository root: ``python -m benchmarks.bench_instancing crossover|issue|loaders|passes|emitters|glass``.
"""

import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
import trimesh


def _scene(triangles, count=400, kind=None):
    from rtmesh.materials.table import Material
    from rtmesh.scene.model import MeshPart, Placement, Scene

    level = int(round(np.log(triangles / 20) / np.log(4)))
    sphere = trimesh.creation.icosphere(level)
    floor = trimesh.creation.box((40, 0.2, 40))
    rng = np.random.default_rng(1)
    transforms = np.tile(np.eye(4), (count, 1, 1))
    transforms[:, 0, 3], transforms[:, 2, 3] = rng.uniform(-18, 18, count), rng.uniform(-18, 18, count)
    transforms[:, 1, 3] = 1.1
    prototype = MeshPart("ball", sphere.vertices, sphere.faces, 1, sphere.vertex_normals)
    materials = [Material(diffuse=np.full(3, 0.6)), Material(diffuse=np.array([0.8, 0.3, 0.2]))]
    if kind == "emitters":
        materials[1].emission = np.full(3, 2.0)
    elif kind == "glass":
        materials[1].transmission, materials[1].ior = np.full(3, 0.9), 1.5
    return len(sphere.faces), Scene.from_parts([MeshPart("floor", floor.vertices, floor.faces, 0)], materials,
                                               physical=True,
                                               placements=[Placement(prototype, transforms,
                                                                     [f"b{j}" for j in range(count)])])


def crossover(repeats=5):
    from rtmesh.rendering.integrator import Integrator
    from rtmesh.rendering.settings import RenderSettings
    from rtmesh.scene import instances

    settings = RenderSettings(width=128, height=96, spp=16, integrator="path", threads=1)
    Integrator(_scene(80)[1], settings).render()  # compile and warm up
    print("placements triangles   build inst/flat ms   render inst/flat ms   both inst/flat ms")
    for count, n in ((400, 20), (400, 80), (400, 320), (400, 1280), (400, 5120), (400, 20480),
                     (1600, 20), (1600, 80), (1600, 320)):
        triangles, scene = _scene(n, count)
        flat = instances.flattened(scene)
        times = {"instanced": ([], []), "flattened": ([], [])}
        for _ in range(repeats):  # interleaved, medians
            for name, s in (("instanced", scene), ("flattened", flat)):
                start = time.perf_counter()
                it = Integrator(s, settings)
                built = time.perf_counter()
                it.render()
                times[name][0].append(built - start)
                times[name][1].append(time.perf_counter() - built)
        med = {k: [1000 * statistics.median(v) for v in pair] for k, pair in times.items()}
        print(f"{count:10d} {triangles:9d}   {med['instanced'][0]:8.1f} {med['flattened'][0]:8.1f}   "
              f"{med['instanced'][1]:8.1f} {med['flattened'][1]:8.1f}   {sum(med['instanced']):8.1f} "
              f"{sum(med['flattened']):8.1f}", flush=True)


def _torus():
    """The issue's mesh: a torus of 50,000 triangles."""
    return trimesh.creation.torus(1.0, 0.35, major_sections=250, minor_sections=100)


def _grid(copies):
    """(copies, 4, 4): placements on a square grid 3 apart, each turned about y."""
    side = int(np.ceil(np.sqrt(copies)))
    rng = np.random.default_rng(2)
    return np.array([trimesh.transformations.translation_matrix([3.0 * (j % side), 0.0, 3.0 * (j // side)])
                     @ trimesh.transformations.rotation_matrix(rng.uniform(0, 2 * np.pi), [0, 1, 0])
                     for j in range(copies)])


def write_gltf(path, copies, subdivisions=None):
    """A GLB of ``copies`` nodes placing one mesh on a square grid, each turned about y: a
    torus of 50,000 triangles, or an icosphere of ``subdivisions``."""
    mesh = _torus() if subdivisions is None else trimesh.creation.icosphere(subdivisions)
    scene = trimesh.Scene()
    for j, transform in enumerate(_grid(copies)):
        if j == 0:
            scene.add_geometry(mesh, node_name="n0", geom_name="shape", transform=transform)
        else:  # the same mesh again (add_geometry would store a copy)
            scene.graph.update(frame_to=f"n{j}", frame_from=scene.graph.base_frame, geometry="shape",
                               matrix=transform)
    scene.export(path)
    return len(mesh.faces)


def _measure(path):
    """Load, build and render ``path`` in this process; print JSON."""
    from rtmesh import api
    from rtmesh.rendering.integrator import Integrator

    start = time.perf_counter()
    scene, settings = api.load_scene(path, width=256, height=256, spp=4, caustics="off")
    loaded = time.perf_counter()
    it = Integrator(scene, settings)
    built = time.perf_counter()
    it.render()
    done = time.perf_counter()
    print(json.dumps({"load": loaded - start, "build": built - loaded, "render": done - built,
                      "instanced": it.instances is not None, "faces": len(scene.faces),
                      "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def issue(copies=10_000):
    with tempfile.TemporaryDirectory() as folder:
        results = {}
        for name, count in (("one copy", 1), (f"{copies} placements", copies)):
            path = os.path.join(folder, f"{count}.glb")
            triangles = write_gltf(path, count)
            run = [sys.executable, __file__, "measure", path]
            subprocess.run(run, check=True, capture_output=True)  # warm the kernel cache
            out = subprocess.run(run, check=True, capture_output=True, text=True).stdout
            results[name] = json.loads(out.strip().splitlines()[-1])
            print(name, f"({triangles} triangles a mesh, {os.path.getsize(path) / 1e6:.1f} MB):", results[name])
        one, many = results["one copy"], results[f"{copies} placements"]
        print(f"peak RSS x{many['peak_rss_mb'] / one['peak_rss_mb']:.2f}, load+build "
              f"x{(many['load'] + many['build']) / (one['load'] + one['build']):.2f}, "
              f"render x{many['render'] / one['render']:.2f}")


def write_scene_file(folder, copies):
    """A scene file placing the torus (torus.glb) by ``copies`` rows of ``instances``."""
    mesh = _torus()
    mesh.export(os.path.join(folder, "torus.glb"))
    np.save(os.path.join(folder, f"rows{copies}.npy"), _grid(copies))
    path = os.path.join(folder, f"{copies}.toml")
    with open(path, "w") as f:
        # under path, which traces instances (Whitted would flatten them into copies)
        f.write(f'[render]\nintegrator = "path"\n[[objects]]\nmesh = "torus.glb"\ninstances = "rows{copies}.npy"\n')
    return path, len(mesh.faces)


def write_usd(folder, copies):
    """A USD stage of one point instancer placing the torus ``copies`` times (the grid's
    positions, without the turns)."""
    from pxr import Usd, UsdGeom, Vt

    mesh = _torus()
    path = os.path.join(folder, f"{copies}.usdc")
    stage = Usd.Stage.CreateNew(path)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    prototype = UsdGeom.Mesh.Define(stage, "/World/Tori/Prototypes/Torus")
    prototype.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(mesh.vertices.astype(np.float32)))
    prototype.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(mesh.faces), 3, np.int32)))
    prototype.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(mesh.faces.ravel().astype(np.int32)))
    instancer = UsdGeom.PointInstancer.Define(stage, "/World/Tori")
    instancer.CreatePrototypesRel().SetTargets([prototype.GetPath()])
    instancer.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(np.zeros(copies, np.int32)))
    instancer.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(_grid(copies)[:, :3, 3].astype(np.float32)))
    stage.GetRootLayer().Save()
    return path, len(mesh.faces)


def loaders(copies=10_000):
    with tempfile.TemporaryDirectory() as folder:
        for kind, write in (("scene file", write_scene_file), ("USD", write_usd)):
            results = {}
            for count in (1, copies):
                path, triangles = write(folder, count)
                run = [sys.executable, __file__, "measure", path]
                subprocess.run(run, check=True, capture_output=True)  # warm the kernel cache
                out = subprocess.run(run, check=True, capture_output=True, text=True).stdout
                results[count] = json.loads(out.strip().splitlines()[-1])
                print(kind, count, f"({triangles} triangles a mesh):", results[count])
            one, many = results[1], results[copies]
            print(f"{kind}: peak RSS x{many['peak_rss_mb'] / one['peak_rss_mb']:.2f}, load+build "
                  f"x{(many['load'] + many['build']) / (one['load'] + one['build']):.2f}, "
                  f"render x{many['render'] / one['render']:.2f}")


# the passes of the ``passes`` measurement (with the denoiser, whose guides are albedo and normal)
PASSES = ("depth", "normal", "albedo", "position", "uv", "alpha", "object_id", "material_id", "instance_id",
          "depth_center", "normal_center", "direct_diffuse")
PASS_MODES = ("instanced", "instanced, passes + denoiser", "flattened, passes + denoiser")


def _measure_passes(mode):
    """Build and render the ``passes`` scene in this process as ``mode`` (an index into
    :data:`PASS_MODES`); print JSON."""
    from rtmesh.rendering.integrator import Integrator
    from rtmesh.rendering.settings import RenderSettings
    from rtmesh.scene import instances

    mode = int(mode)
    _, scene = _scene(5120, 2000)
    settings = RenderSettings(width=128, height=96, spp=4, integrator="path", passes=PASSES if mode else (),
                              denoise=bool(mode))
    start = time.perf_counter()
    if mode == 2:
        scene = instances.flattened(scene)
    it = Integrator(scene, settings)
    built = time.perf_counter()
    result = it.render()
    done = time.perf_counter()
    print(json.dumps({"build": built - start, "render": done - built, "instanced": it.instances is not None,
                      "faces": len(it.scene.faces),
                      "ids": len(np.unique(result.passes["instance_id"])) if result.passes else 0,
                      "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def passes():
    for mode, name in enumerate(PASS_MODES):
        run = [sys.executable, __file__, "measure_passes", str(mode)]
        subprocess.run(run, check=True, capture_output=True)  # warm the kernel cache
        out = subprocess.run(run, check=True, capture_output=True, text=True).stdout
        print(f"{name}:", json.loads(out.strip().splitlines()[-1]))


def _measure_kind(kind, flatten):
    """Build and render the ``emitters`` or ``glass`` scene in this process, flattened or
    not; print JSON."""
    from rtmesh.rendering.integrator import Integrator
    from rtmesh.rendering.settings import RenderSettings
    from rtmesh.scene import instances

    _, scene = _scene(1280, 400, kind)
    settings = RenderSettings(width=128, height=96, spp=4, integrator="path")
    start = time.perf_counter()
    if flatten == "1":
        scene = instances.flattened(scene)
    it = Integrator(scene, settings)
    built = time.perf_counter()
    it.render()
    done = time.perf_counter()
    print(json.dumps({"build": built - start, "render": done - built, "instanced": it.instances is not None,
                      "faces": len(it.scene.faces), "lights": len(it.path_stage.lights),
                      "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def kinds(kind, repeats=3):
    for flatten, name in (("0", "instanced"), ("1", "flattened")):
        run = [sys.executable, __file__, "measure_kind", kind, flatten]
        subprocess.run(run, check=True, capture_output=True)  # warm the kernel cache
        outs = [json.loads(subprocess.run(run, check=True, capture_output=True, text=True).stdout.strip()
                           .splitlines()[-1]) for _ in range(repeats)]
        print(f"{kind}, {name}:", {k: (statistics.median(o[k] for o in outs) if isinstance(outs[0][k], float)
                                       else outs[0][k]) for k in outs[0]})


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "crossover"
    if what == "measure":
        _measure(sys.argv[2])
    elif what == "measure_passes":
        _measure_passes(sys.argv[2])
    elif what == "issue":
        issue()
    elif what == "loaders":
        loaders()
    elif what == "passes":
        passes()
    elif what == "measure_kind":
        _measure_kind(sys.argv[2], sys.argv[3])
    elif what in ("emitters", "glass"):
        kinds(what)
    else:
        crossover()
