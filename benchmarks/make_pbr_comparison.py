"""The README's before/after picture of glTF assets: Blinn-Phong mapping against the glTF
metallic-roughness model under the studio environment.

Usage, from the repository root::

    python -m benchmarks.make_pbr_comparison [--spp N] [--size S] [--denoise] [FILE ...]

(default files: Duck.glb, BoxTextured.glb and monkey.glb of ../shared/assets/real).  For
each file, two renders with the file's own camera or the automatic framing:

- **before**: every metallic-roughness material mapped onto Blinn-Phong as rtmesh did
  before it had the glTF model (:func:`blinn_phong_mapping`), lit by the three-light rig
  (:func:`rtmesh.scene.model.default_lights`) with its ambient term;
- **after**: the file as it loads, i.e. the glTF model, lit by the studio environment
  (:mod:`rtmesh.scene.studio`).

The pairs are stacked into ``docs/images/pbr_before_after.png`` (one row per file, before
on the left) and the render times are printed.
"""

import argparse
import dataclasses
import os
import time

import numpy as np

from rtmesh.api import load_scene
from rtmesh.io.images import write_image
from rtmesh.materials.table import MaterialTable
from rtmesh.rendering.integrator import Integrator
from rtmesh.scene.model import default_lights

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
REAL = os.path.join(ROOT, "..", "shared", "assets", "real")
DEFAULT_FILES = ("Duck.glb", "BoxTextured.glb", "monkey.glb")


def roughness_to_shininess(roughness):
    """Blinn-Phong exponent with the highlight width of a GGX lobe of roughness ``r``:
    ``2 / alpha^2 - 2`` with ``alpha = r^2`` (Walter et al. 2007's Beckmann-Phong
    correspondence), clamped to [1, 10000]; ``r`` below 0.05 reads as 0.05."""
    r4 = max(float(roughness), 0.05) ** 4
    return float(np.clip(2.0 / r4 - 2.0, 1.0, 10000.0))


def blinn_phong_mapping(material):
    """A metallic-roughness material as the Blinn-Phong material rtmesh used to map it to
    before it had the glTF model: ``diffuse = b (1 - m)``, ``specular = 0.04
    (1 - m) + b m`` with the GGX-equivalent exponent, ``mirror = b m`` blurred by ``r^2``
    radians, the metallic-roughness texture's mean in place of the texture."""
    if material.model != "metallic_roughness":
        return material
    metallic, roughness = material.metallic, material.perceptual_roughness
    if material.metallic_roughness_texture is not None:
        pixels = material.metallic_roughness_texture.pixels
        mean = pixels.reshape(-1, pixels.shape[2]).mean(axis=0)
        if len(mean) >= 3:
            roughness, metallic = roughness * mean[1], metallic * mean[2]
    base = material.base_color
    return dataclasses.replace(
        material, model="blinn_phong", diffuse=base * (1.0 - metallic), ambient=base * (1.0 - metallic),
        specular=0.04 * (1.0 - metallic) + base * metallic, shininess=roughness_to_shininess(roughness),
        mirror=base * metallic, roughness=roughness ** 2, metallic=metallic,
        metallic_roughness_texture=None, occlusion_texture=None)


def before_scene(scene):
    """The scene with Blinn-Phong materials and the three-light rig (ambient 0.05)."""
    materials = MaterialTable([blinn_phong_mapping(m) for m in scene.materials.materials])
    return dataclasses.replace(scene, materials=materials, lights=default_lights(scene.camera),
                               ambient=np.full(3, 0.05), background=np.zeros(3))


def render(scene, settings):
    start = time.perf_counter()
    result = Integrator(scene, settings).render()
    return result, time.perf_counter() - start


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("files", nargs="*", help="glTF files (default: three of ../shared/assets/real)")
    parser.add_argument("--size", type=int, default=240, help="pixels per side of each render")
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel")
    parser.add_argument("--denoise", action="store_true", help="denoise the after images (rtmesh[denoise])")
    parser.add_argument("--operator", default="pbr-neutral", help="tone mapper of the PNG (default: pbr-neutral)")
    parser.add_argument("-o", "--output", default=os.path.join(ROOT, "docs", "images", "pbr_before_after.png"))
    args = parser.parse_args(argv)
    files = args.files or [os.path.join(REAL, name) for name in DEFAULT_FILES]
    rows = []
    for path in files:
        scene, settings = load_scene(path, width=args.size, height=args.size, spp=args.spp, threads=2)
        before, before_s = render(before_scene(scene), settings)
        after_settings = dataclasses.replace(settings, denoise=args.denoise)
        after, after_s = render(scene, after_settings)
        print(f"{os.path.basename(path)}: before {before_s:.2f} s, after {after_s:.2f} s "
              f"({after.stats.rays['bsdf']} BSDF rays, {after.stats.rays['environment']} environment rays)")
        rows.append(np.concatenate([before.image, after.image], axis=1))
    write_image(args.output, np.concatenate(rows, axis=0), operator=args.operator)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
