"""Caustics against Mitsuba 3's particle tracer, and the pictures of docs/CAUSTICS.md.

Renders ``assets/effects/caustics.toml`` (a glass ball over a diffuse floor under a point
light) at the reference's size with the photon passes and without, and compares the floor's
8x8 block means with a ``ptracer`` image of the same triangles
(``benchmarks/peers_mitsuba_caustics.py``): blocks that see the ball are left out (a
particle tracer cannot render surfaces seen through glass), the rest must be within 5 %,
the brightest within 10 %, the lit floor within 2 %.  Then the error of the caustic's blocks
as passes go on (convergence), the photon passes' share of the time, and the pictures:
``docs/images/caustics_ball.png`` (photons | caustics off | Mitsuba ptracer) and
``docs/images/caustics_ring.png`` (``assets/effects/caustics_ring.toml``).

Usage (from the repository root; the reference from the peers venv first)::

    /work/peers-venv/bin/python -m benchmarks.peers_mitsuba_caustics assets/effects/caustics.toml \\
        /tmp/caustics_ptracer_320x240.exr --width 320 --height 240 --spp 32768
    python -m benchmarks.bench_caustics /tmp/caustics_ptracer_320x240.exr
"""

import argparse
import os
import time

import numpy as np

from rtmesh import api
from rtmesh.io.colour import tonemap
from rtmesh.io.images import read_image, write_display_image
from rtmesh.rendering.integrator import Integrator

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
BALL = os.path.join(ROOT, "assets", "effects", "caustics.toml")
RING = os.path.join(ROOT, "assets", "effects", "caustics_ring.toml")
LIGHT = np.array([0.5, 4.0, -2.5])
BALL_CENTRE, BALL_RADIUS = np.array([0.0, 0.85, 0.0]), 0.5


def blocks(image, size=8):
    """``size`` x ``size`` block means of an (h, w) image."""
    h, w = image.shape[:2]
    return image[:h // size * size, :w // size * size].reshape(h // size, size, w // size, size).mean(axis=(1, 3))


def render(path, width, height, **settings):
    scene, s = api.load_scene(path, width=width, height=height, **settings)
    t0 = time.perf_counter()
    result = Integrator(scene, s).render()
    return scene, result, time.perf_counter() - t0


def regions(scene, result, width, height):
    """Block masks: the floor alone, and the floor outside the ball's shadow."""
    names = [m.name for m in scene.materials.materials]
    floor = blocks((result.passes["material_id"].reshape(height, width) == names.index("floor")).astype(float)) == 1
    p = result.passes["position_center"].reshape(-1, 3)
    d = LIGHT - p
    length = np.linalg.norm(d, axis=1)
    d = d / length[:, None]
    along = np.clip(((BALL_CENTRE - p) * d).sum(axis=1), 0.0, length)
    gap = np.linalg.norm(p + along[:, None] * d - BALL_CENTRE, axis=1)
    shadow = blocks((gap < BALL_RADIUS + 0.05).reshape(height, width).astype(float)) > 0
    return floor, floor & ~shadow


def display(image):
    """Linear RGB tone-mapped as 8-bit output is (Reinhard), still linear: for write_display_image's sRGB."""
    return tonemap(np.asarray(image, dtype=np.float64), 0.0, "reinhard")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("reference", help="Mitsuba ptracer EXR of assets/effects/caustics.toml")
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--photons", type=int, default=None)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--images", action="store_true", help="write docs/images/caustics_*.png")
    args = parser.parse_args()
    ref = read_image(args.reference)[0][:, :, :3].astype(np.float64)
    height, width = ref.shape[:2]
    labels = ("material_id", "position_center")
    scene, on, t_on = render(BALL, width, height, spp=args.spp, photons=args.photons, threads=args.threads,
                             passes=labels)
    _, off, t_off = render(BALL, width, height, spp=args.spp, caustics="off", threads=args.threads)
    floor, lit = regions(scene, on, width, height)
    caustic = floor & ~lit
    rb = blocks(ref[..., 0])
    for name, result, seconds in (("photons", on, t_on), ("off", off, t_off)):
        ours = blocks(result.image[..., 0].astype(np.float64))
        with np.errstate(divide="ignore", invalid="ignore"):  # blocks of the black background
            rel = np.abs(ours / rb - 1)
        bright = np.unravel_index(np.argmax(np.where(floor, rb, -1.0)), rb.shape)
        st = result.stats
        print(f"{name}: {width}x{height}, {args.spp} spp, {seconds:.1f} s (photon passes {st.photon_seconds:.1f} s: "
              f"{st.photon_passes} x {st.photons} photons, {st.photons_stored / max(st.photon_passes, 1):.0f} "
              f"stored a pass); floor blocks {floor.sum()}: max rel error {rel[floor].max():.4f}, "
              f"caustic blocks {caustic.sum()}: max {rel[caustic].max():.4f}, lit floor {lit.sum()}: "
              f"max {rel[lit].max():.4f}; brightest reference block {rb[bright]:.4f}, ours {ours[bright]:.4f}")
    print("caustic blocks' relative RMSE as passes go on:")
    for spp in (4, 16, 64, args.spp):
        _, result, seconds = render(BALL, width, height, spp=spp, photons=args.photons, threads=args.threads)
        ours = blocks(result.image[..., 0].astype(np.float64))
        error = np.sqrt(np.mean((ours[caustic] / rb[caustic] - 1) ** 2))
        print(f"  {spp:5d} passes: {error:.4f} ({seconds:.1f} s)")
    if args.images:
        out = os.path.join(ROOT, "docs", "images")
        side = np.concatenate([display(on.image), display(off.image), display(ref.astype(np.float32))], axis=1)
        write_display_image(os.path.join(out, "caustics_ball.png"), side, srgb=True)
        _, ring, seconds = render(RING, 480, 360, spp=args.spp, threads=args.threads)
        write_display_image(os.path.join(out, "caustics_ring.png"), display(ring.image), srgb=True)
        print(f"ring: 480x360, {args.spp} spp, {seconds:.1f} s")


if __name__ == "__main__":
    main()
