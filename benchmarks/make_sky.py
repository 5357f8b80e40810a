"""Write assets/environments/sky.exr: a small procedural sky (256 x 128, linear, half float).

A blue zenith fading to a pale horizon, a darker ground, and a sun disk (half-angle 2.5
degrees, radiance 60) with a soft glow, in the lat-long convention of rtmesh.scene.background
(+Y up).  Run from the repository root: ``python -m benchmarks.make_sky``.
"""

import os

import numpy as np
import OpenImageIO as oiio

from rtmesh.scene.background import latlong_directions

WIDTH, HEIGHT = 256, 128
SUN = np.array([0.45, 0.55, -0.70])  # toward the sun: up and behind a camera looking down -Z
SUN_HALF_ANGLE = np.radians(2.5)


def sky(width=WIDTH, height=HEIGHT):
    """(height, width, 3) float32 linear radiance."""
    d = latlong_directions(width, height)
    y = d[:, :, 1:2]
    zenith, horizon, ground = np.array([0.18, 0.35, 0.85]), np.array([0.85, 0.9, 1.0]), np.array([0.25, 0.22, 0.2])
    up = np.clip(y, 0.0, 1.0) ** 0.5
    colour = np.where(y >= 0.0, horizon + (zenith - horizon) * up,
                      ground + (horizon - ground) * np.exp(8.0 * np.minimum(y, 0.0)))
    sun = SUN / np.linalg.norm(SUN)
    cos_angle = d @ sun
    angle = np.arccos(np.clip(cos_angle, -1.0, 1.0))[:, :, None]
    colour = colour + np.where(angle < SUN_HALF_ANGLE, 60.0, 0.0) * np.array([1.0, 0.95, 0.85])
    colour = colour + 0.6 * np.exp(-angle / 0.15) * np.array([1.0, 0.85, 0.6])
    return colour.astype(np.float32)


def write_environment(path, image):
    """Write a linear (h, w, 3) environment image as a half-float, zip-compressed EXR (half's
    11-bit mantissa is ample for light, and keeps the file small); exits with one line if the
    file cannot be written."""
    spec = oiio.ImageSpec(image.shape[1], image.shape[0], 3, oiio.HALF)
    spec.attribute("compression", "zip")
    out = oiio.ImageOutput.create(path)
    if out is None or not out.open(path, spec) or not out.write_image(image):
        raise SystemExit(f"cannot write {path}: {oiio.geterror()}")
    out.close()


def main(path=os.path.join(os.path.dirname(__file__), "..", "assets", "environments", "sky.exr")):
    image = sky()
    write_environment(path, image)
    print(f"{path}: {WIDTH}x{HEIGHT}, max {image.max():.1f}")


if __name__ == "__main__":
    main()
