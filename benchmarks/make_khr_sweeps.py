"""Parameter sweeps of glTF's KHR layer extensions, as the Khronos ``*ParameterSweep``
sample assets: for each extension a row of five spheres varying one parameter, built in
code and path traced under the studio environment, written to ``docs/images/khr_*.png``
(480 x 96) for docs/MATERIALS.md.

Usage, from the repository root::

    python -m benchmarks.make_khr_sweeps [--spp N] [--out DIR]
"""

import argparse
import os
import time

import numpy as np

from rtmesh.io.images import write_image
from rtmesh.materials.gltf_layered import Layers
from rtmesh.materials.table import Material
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import MeshPart, Scene

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
VALUES = np.linspace(0.0, 1.0, 5)
# one sweep per extension: (base colour, metallic, roughness, the Layers of one value)
SWEEPS = {
    "specular": ((0.6, 0.05, 0.05), 0.0, 0.3, lambda x: dict(specular=x)),
    "clearcoat": ((0.5, 0.02, 0.02), 0.3, 0.7, lambda x: dict(clearcoat=x, clearcoat_roughness=0.05)),
    "sheen": ((0.03, 0.05, 0.25), 0.0, 0.9, lambda x: dict(sheen_colour=np.full(3, x), sheen_roughness=0.4)),
    "anisotropy": ((0.95, 0.93, 0.88), 1.0, 0.4, lambda x: dict(anisotropy=x)),
    "iridescence": ((0.02, 0.02, 0.02), 0.0, 0.25,
                    lambda x: dict(iridescence=1.0, thickness_min=0.0, thickness_max=100.0 + 700.0 * x)),
}
CAPTIONS = {
    "specular": "KHR_materials_specular: specularFactor 0 to 1 (red dielectric, roughness 0.3)",
    "clearcoat": "KHR_materials_clearcoat: clearcoatFactor 0 to 1 (coat roughness 0.05, base roughness 0.7)",
    "sheen": "KHR_materials_sheen: sheenColorFactor 0 to 1 (sheen roughness 0.4, dark blue base)",
    "anisotropy": "KHR_materials_anisotropy: anisotropyStrength 0 to 1 (metal, roughness 0.4, rotation 0)",
    "iridescence": "KHR_materials_iridescence: film thickness 100 to 800 nm (ior 1.3, black dielectric)",
}


def sphere(centre, radius=0.42, rings=48, segments=96):
    """A UV sphere (positions, faces, smooth normals, UVs with u around the equator): the UV
    tangents, which orient anisotropy, run along the parallels."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    normals = np.stack([np.sin(t) * np.cos(p), np.cos(t), -np.sin(t) * np.sin(p)], axis=-1).reshape(-1, 3)
    uv = np.stack([p / (2.0 * np.pi), 1.0 - t / np.pi], axis=-1).reshape(-1, 2)
    i = np.arange(rings)[:, None] * (segments + 1) + np.arange(segments)[None, :]
    quads = np.stack([i, i + segments + 1, i + segments + 2, i + 1], axis=-1).reshape(-1, 4)
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    # the poles' quads are triangles: their degenerate halves dropped
    v = normals[faces]
    faces = faces[np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1) > 1e-12]
    return centre + radius * normals, faces, normals, uv


def sweep_scene(name):
    """The scene of one sweep: five spheres in a row, their materials the sweep's values."""
    base, metallic, roughness, layers = SWEEPS[name]
    parts, materials = [], []
    for k, x in enumerate(VALUES):
        vertices, faces, normals, uv = sphere(np.array([k - 2.0, 0.0, 0.0]))
        parts.append(MeshPart(name=f"{name} {x:.2f}", vertices=vertices, faces=faces, material=k,
                              vertex_normals=normals, uv=uv))
        materials.append(Material(name=f"{name} {x:.2f}", model="gltf_layered", base_color=base, metallic=metallic,
                                  perceptual_roughness=roughness,
                                  layers=Layers(**layers(x), extensions=(f"KHR_materials_{name}",))))
    camera = Camera(position=(0.0, 0.35, 9.0), look_at=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=6.8)
    return Scene.from_parts(parts, materials, camera=camera, source=f"{name} sweep", aspect=5.0, physical=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--out", default=os.path.join(ROOT, "docs", "images"))
    args = parser.parse_args()
    settings = RenderSettings(width=480, height=96, spp=args.spp, integrator="path", sampler="sobol", seed=1)
    for name in SWEEPS:
        start = time.perf_counter()
        result = Integrator(sweep_scene(name), settings).render()
        path = os.path.join(args.out, f"khr_{name}.png")
        write_image(path, result.image, operator="pbr-neutral")
        print(f"{path}: {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
