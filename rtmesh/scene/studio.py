"""The default light rig of physically based assets: a neutral photo studio.

An asset whose materials follow the glTF metallic-roughness model and that brings no lights
of its own is lit by ``studio.exr`` (made from scratch by ``python -m benchmarks.make_studio``: a grey
cyclorama with a key softbox up and to the front-left, a fill to the right and a strip light
behind) as an environment that lights the scene, the way product renderers (f3d, OSPRay
Studio, Blender's look-dev mode) light glTF assets: metals then reflect something, and
the rough and the smooth look different.  The environment is turned about +Y so that the
camera sees the key light from its upper left whatever direction it looks in, as the
three-light rig of :func:`rtmesh.scene.model.default_lights` is placed for Blinn-Phong assets.
"""

import functools
import math
import os

import numpy as np

from rtmesh.io.images import read_image
from rtmesh.scene.background import EnvironmentBackground

STUDIO_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "studio.exr")


def studio_rotation(forward):
    """Degrees about +Y that turn the studio's front (``-Z``) toward a camera's view.

    Parameters
    ----------
    forward : (3,) float
        The camera's unit viewing direction.

    Returns
    -------
    float
        The rotation of :class:`rtmesh.scene.background.EnvironmentBackground` (right-handed
        about +Y) that maps ``-Z`` onto the horizontal part of ``forward``; 0 for a camera
        looking straight up or down.
    """
    fx, fz = float(forward[0]), float(forward[2])
    if math.hypot(fx, fz) < 1e-9:
        return 0.0
    # a right-handed turn by t maps -Z to (-sin t, 0, -cos t)
    return math.degrees(math.atan2(-fx, -fz))


def studio_background(camera):
    """The studio environment, lighting the scene, turned to ``camera``
    (:class:`rtmesh.scene.background.EnvironmentBackground` with ``lighting`` on)."""
    background = EnvironmentBackground(_studio_pixels(), rotation=studio_rotation(np.asarray(camera.frame()[0])),
                                       name=STUDIO_PATH)
    background.lighting = True
    return background


@functools.cache
def _studio_pixels():
    """The studio image (linear radiance, an EXR), read once per process: every view of a
    batch turns it anew."""
    pixels, _ = read_image(STUDIO_PATH)
    pixels.flags.writeable = False  # shared by every background made from it
    return pixels
