"""Write rtmesh/scene/studio.exr: a neutral photo-studio environment for product shots
(256 x 128, linear, half float), made from scratch (no third-party image).

A soft grey cyclorama (darker below the horizon, like a floor), a large key softbox up and to
the front-left, a smaller fill softbox to the right and a strip light behind, each a
rectangle of constant radiance with softened edges, in the lat-long convention of
rtmesh.scene.background (+Y up; the image centre looks along +X, a camera looking down -Z
sees the key light from its upper left).  It is the default light rig of assets with
physically based (glTF metallic-roughness) materials that bring no lights of their own
(:mod:`rtmesh.scene.studio`, which turns it to the camera), and can be named in a scene
file as any environment:

    [background]
    type = "environment"
    file = "/path/to/rtmesh/scene/studio.exr"
    lighting = true

Run from the repository root: ``python -m benchmarks.make_studio``.
"""

import os

import numpy as np

from benchmarks.make_sky import write_environment
from rtmesh.scene.background import latlong_directions

WIDTH, HEIGHT = 256, 128
# softboxes: (unit direction of the centre, half-width and half-height in radians, radiance)
SOFTBOXES = (
    (np.array([-0.55, 0.65, 0.52]), 0.35, 0.28, 9.0),   # key: up, front-left of a camera looking down -Z
    (np.array([0.75, 0.35, 0.56]), 0.22, 0.22, 3.5),    # fill: right
    (np.array([0.0, 0.45, -0.89]), 0.55, 0.08, 5.0),    # strip behind the subject: rim light
)
# how far (radians) a softbox's edge fades: soft enough that the bilinear lookup and the
# importance sampling see a smooth lamp, sharp enough to read as a panel in reflections
EDGE = 0.04


def studio(width=WIDTH, height=HEIGHT):
    """(height, width, 3) float32 linear radiance."""
    d = latlong_directions(width, height)
    y = d[:, :, 1]
    # the cyclorama: 0.5 above the horizon falling to 0.18 below it (a grey floor)
    grey = np.where(y >= 0.0, 0.35 + 0.15 * y, 0.18 + 0.17 * np.exp(6.0 * y))
    radiance = np.repeat(grey[:, :, None], 3, axis=2)
    up = np.array([0.0, 1.0, 0.0])
    for centre, half_w, half_h, power in SOFTBOXES:
        c = centre / np.linalg.norm(centre)
        right = np.cross(up, c)
        right /= np.linalg.norm(right)
        top = np.cross(c, right)
        # angular offsets from the box's centre along its right and top axes
        along = d @ c
        x = np.arctan2(d @ right, along)
        t = np.arctan2(d @ top, along)
        inside = (np.clip((half_w - np.abs(x)) / EDGE + 0.5, 0.0, 1.0)
                  * np.clip((half_h - np.abs(t)) / EDGE + 0.5, 0.0, 1.0))
        radiance += (power * inside * (along > 0.0))[:, :, None]
    return radiance.astype(np.float32)


def main(path=os.path.join(os.path.dirname(__file__), "..", "rtmesh", "scene", "studio.exr")):
    image = studio()
    write_environment(path, image)
    print(f"wrote {path}: {WIDTH}x{HEIGHT}, radiance {image.min():.2f} .. {image.max():.2f}")


if __name__ == "__main__":
    main()
