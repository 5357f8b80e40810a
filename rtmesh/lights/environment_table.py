"""The environment (the background that lights a scene) as the path kernel reads it: its
radiance on a latitude-longitude grid and its sampling tables (:class:`EnvironmentTables`),
and the rows that look a direction up in them (:func:`latlong_uv`,
:func:`environment_radiance_uv`, :func:`environment_pdf_uv`).

The environment is one row of the light table (:data:`rtmesh.lights.light_table.ENVIRONMENT`),
chosen among the lights by :meth:`EnvironmentTables.power`; the kernel's rays that leave
the scene take its radiance here.
"""

import math

import numpy as np

from rtmesh.core.compiled import row
from rtmesh.materials.lobes import LUMA


class EnvironmentTables:
    """The background as compiled code reads it: its radiance on a latitude-longitude grid
    (bilinear, as :class:`rtmesh.scene.background.EnvironmentBackground` looks it up) and
    the sampling tables of :class:`rtmesh.lights.environment.EnvironmentLighting` (whose
    row :func:`rtmesh.lights.environment.sample_direction` draws from them).

    Parameters
    ----------
    lighting : EnvironmentLighting
        Its tables (marginal and conditional cdfs, the tabulated density).
    background : background object

    Attributes
    ----------
    pixels : (h, w + 2, 3) float32
        Radiance, one wrapped column on each side (the azimuth's seam); a solid background
        is one row (1, 3, 3) of its colour.  float32, as lookups read it (they compute in
        float64): half the bytes, so that the studio map's 256 x 128 texels (396 KiB) fit a
        512 KiB L2 cache, where the rays that miss an asset (most of a real asset's samples)
        and the map's light samples find them (Duck.glb and monkey.glb 2.5-4 % faster, one
        thread).  The same radiance where the map holds 32-bit or half floats (EXR, HDR); an
        8-bit map's or a colour's values round to float32 (relative 6e-8).
    marginal, conditional, func, mean, cos_rotation, sin_rotation
        As :func:`rtmesh.lights.environment._sample_directions` takes them.
    """

    def __init__(self, lighting, background):
        image = getattr(background, "_texture", None)
        colour = getattr(background, "colour", None)
        if image is None and colour is not None:
            # a solid background: one row of one texel (the kernel reads it without a lookup)
            pixels = np.tile(np.asarray(colour, dtype=np.float64).reshape(1, 1, 3), (1, 3, 1))
        elif image is not None:
            pixels = np.ascontiguousarray(image.pixels[:, :, :3], dtype=np.float64)
        else:
            # a procedural background (a gradient) tabulated finely enough that the bilinear
            # lookup stays within 1e-5 of it (its sampling tables are the lighting's)
            h, w = 256, 512
            v = 1.0 - (np.arange(h) + 0.5) / h
            u = (np.arange(w) + 0.5) / w
            uv = np.stack(np.meshgrid(u, v), axis=2).reshape(-1, 2)
            grid = np.asarray(background.radiance(lighting.directions(uv)), dtype=np.float64).reshape(h, w, 3)
            pixels = np.concatenate([grid[:, -1:], grid, grid[:, :1]], axis=1)
        self.pixels = pixels.astype(np.float32)
        angle = math.radians(getattr(background, "rotation", 0.0))
        self.cos_rotation, self.sin_rotation = math.cos(angle), math.sin(angle)
        self.marginal, self.conditional = lighting._marginal, lighting._conditional
        self.func, self.mean = lighting._func, lighting._mean
        self.mean_luminance = float((pixels[:, 1:-1] @ LUMA).mean())

    def power(self, scene_radius):
        """What the environment sends onto the scene's bounding disk (for choosing lights)."""
        return math.pi * scene_radius * scene_radius * 4.0 * math.pi * self.mean_luminance


@row
def latlong_uv(cos_rotation, sin_rotation, dx, dy, dz):
    """The environment map's ``(u, v)`` of a unit direction: :func:`rtmesh.sampling.warps.direction_to_latlong`
    of the direction turned by the map's rotation."""
    xr = cos_rotation * dx - sin_rotation * dz
    zr = sin_rotation * dx + cos_rotation * dz
    return 0.5 + math.atan2(zr, xr) / (2.0 * math.pi), 0.5 + math.asin(min(max(dy, -1.0), 1.0)) / math.pi


@row
def environment_radiance_uv(pixels, u, v):
    """Background radiance at the map's ``(u, v)``: the clamped bilinear lookup of the padded
    image (r, g, b)."""
    h, w2 = pixels.shape[0], pixels.shape[1]
    w = w2 - 2
    x = (u * w + 1.0) / (w + 2.0) * w2 - 0.5
    y = (1.0 - v) * h - 0.5
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0
    xa, xb = min(max(int(x0), 0), w2 - 1), min(max(int(x0) + 1, 0), w2 - 1)
    ya, yb = min(max(int(y0), 0), h - 1), min(max(int(y0) + 1, 0), h - 1)
    out0 = (pixels[ya, xa, 0] * (1.0 - fx) + pixels[ya, xb, 0] * fx) * (1.0 - fy) + (
        pixels[yb, xa, 0] * (1.0 - fx) + pixels[yb, xb, 0] * fx) * fy
    out1 = (pixels[ya, xa, 1] * (1.0 - fx) + pixels[ya, xb, 1] * fx) * (1.0 - fy) + (
        pixels[yb, xa, 1] * (1.0 - fx) + pixels[yb, xb, 1] * fx) * fy
    out2 = (pixels[ya, xa, 2] * (1.0 - fx) + pixels[ya, xb, 2] * fx) * (1.0 - fy) + (
        pixels[yb, xa, 2] * (1.0 - fx) + pixels[yb, xb, 2] * fx) * fy
    return out0, out1, out2


@row
def environment_pdf_uv(func, mean, u, v, dy):
    """Solid-angle density of :func:`rtmesh.lights.environment.sample_direction` (as
    :meth:`rtmesh.lights.environment.EnvironmentLighting.pdf`) at the map's ``(u, v)``
    (:func:`latlong_uv`) of a unit direction whose ``y`` is ``dy``."""
    h, w = func.shape
    r = min(max(int((1.0 - v) * h), 0), h - 1)
    c = min(max(int(u * w), 0), w - 1)
    sin_theta = math.sqrt(max(1.0 - dy * dy, 0.0))
    if not sin_theta > 0.0:
        return math.inf
    return func[r, c] / mean / (2.0 * math.pi * math.pi * sin_theta)
