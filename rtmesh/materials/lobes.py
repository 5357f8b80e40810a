"""What every BSDF model of the path integrator shares: the sample flags, the parameter row,
and the one-row Fresnel, reflection and refraction helpers.

Conventions of the seam (see :mod:`rtmesh.materials.models`)
-------------------------------------------------------------
- Directions are unit vectors in the local shading frame, ``z`` the shading normal, both
  ``wo`` (toward the viewer) and ``wi`` (toward the light, or the sampled direction)
  pointing away from the surface.
- Reflection-only models are evaluated with the frame turned to ``wo``'s side (``wo.z > 0``):
  both sides of a triangle reflect alike.  Transmissive models get the frame of the
  triangle's outward side, so ``wo.z < 0`` means "seen from inside".
- ``eval`` returns ``f(wo, wi) |wi.z|`` per RGB channel (the factor of incident radiance)
  and the solid-angle density with which ``sample`` draws ``wi``; ``sample`` returns the
  direction, its *weight* ``f |wi.z| / pdf`` (for a delta lobe: the lobe's value over its
  choice probability), the density and the flags.
- Radiance is transported from the camera (pbrt's ``TransportMode::Radiance``): refraction
  scales it by ``1 / eta'^2``, ``eta'`` the ratio of the indices across the interface.
"""

import functools
import math

import numpy as np

from rtmesh.core.compiled import row

# sample flags (bits), for MIS (delta lobes have no density to weigh) and the light-path passes
DELTA = 1
DIFFUSE = 2
GLOSSY = 4
TRANSMISSION = 8
# a failed sample (no direction): weight 0 and these flags
FAILED = 0

# every model's parameters fit one float64 row of this width (models.PARAMETER_WIDTH); 32 for
# the glTF model with every KHR layer (gltf_layered.WIDTH, 29)
PARAMETER_WIDTH = 32

# Luminance of linear sRGB (Rec. 709, D65): one number for an RGB weight, to choose lobes
LUMA_R, LUMA_G, LUMA_B = 0.2126, 0.7152, 0.0722
LUMA = np.array([LUMA_R, LUMA_G, LUMA_B])  # the same weights as a vector, for NumPy


@functools.lru_cache(maxsize=None)
def shipped_table(path):
    """A table that ships with the package (``.npy``: the energy tables), read once per process."""
    return np.load(path)


@row
def mixture_sample(wx, wy, wz, fr, fg, fb, pdf, flags, oz):
    """The sample of a mixture model that drew ``wi`` from one lobe and evaluated the whole
    mixture there (``f |cos|`` and its density): ``(wi, weight, pdf, flags)``, failed where
    the density is 0, flagged as a transmission where ``wi`` crossed the surface."""
    if not pdf > 0.0:
        return wx, wy, wz, 0.0, 0.0, 0.0, 0.0, FAILED
    if oz * wz < 0.0:
        flags |= TRANSMISSION
    return wx, wy, wz, fr / pdf, fg / pdf, fb / pdf, pdf, flags


@row
def grid_cell(x, points):
    """Interpolation coordinates of ``x`` in [0, 1] on ``points`` evenly spaced grid points
    from 0 to 1 (clamped): the lower index and the fraction (the energy tables' lookups)."""
    f = min(max(x, 0.0), 1.0) * (points - 1)
    i = min(int(f), points - 2)
    return i, f - i


@row
def bilinear(table, x, y, columns):
    """Bilinear lookup of an energy table sampled on even grids over [0, 1]: ``y`` over its
    rows, ``x`` over its first ``columns`` columns (both clamped)."""
    j, fy = grid_cell(y, table.shape[0])
    i, fx = grid_cell(x, columns)
    low = table[j, i] * (1.0 - fx) + table[j, i + 1] * fx
    high = table[j + 1, i] * (1.0 - fx) + table[j + 1, i + 1] * fx
    return low * (1.0 - fy) + high * fy


@row
def luminance(r, g, b):
    """Rec. 709 luminance of a linear RGB triple."""
    return (LUMA_R * r + LUMA_G * g) + LUMA_B * b


@row
def fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance of a smooth dielectric interface (exact).

    Parameters
    ----------
    cos_i : float
        Cosine of the incident direction with the interface normal; negative from inside.
    eta : float
        Index of the inside over the outside.

    Returns
    -------
    float
        Reflectance in [0, 1]; 1 under total internal reflection.
    """
    if cos_i < 0.0:
        eta = 1.0 / eta
        cos_i = -cos_i
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    if sin2_t >= 1.0:
        return 1.0
    cos_t = math.sqrt(max(0.0, 1.0 - sin2_t))
    r_parallel = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    r_perpendicular = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    return 0.5 * (r_parallel * r_parallel + r_perpendicular * r_perpendicular)


@row
def refract(wx, wy, wz, nx, ny, nz, eta):
    """Refract ``w`` (pointing away from the surface) through the interface of normal ``n``.

    Parameters
    ----------
    wx, wy, wz : float
        Unit direction on either side.
    nx, ny, nz : float
        Unit normal of the interface, pointing to the outside.
    eta : float
        Index of the inside over the outside.

    Returns
    -------
    (tx, ty, tz, eta_ratio, ok)
        The refracted unit direction (on the other side), ``eta'`` (the index of the side
        it enters over that of the side it left) and False under total internal reflection.
    """
    cos_i = (nx * wx + ny * wy) + nz * wz
    if cos_i < 0.0:
        eta = 1.0 / eta
        cos_i = -cos_i
        nx, ny, nz = -nx, -ny, -nz
    sin2_t = max(0.0, 1.0 - cos_i * cos_i) / (eta * eta)
    if sin2_t >= 1.0:
        return 0.0, 0.0, 0.0, eta, False
    cos_t = math.sqrt(1.0 - sin2_t)
    k = cos_i / eta - cos_t
    return -wx / eta + k * nx, -wy / eta + k * ny, -wz / eta + k * nz, eta, True


@row
def schlick(f0, cos):
    """Schlick's Fresnel approximation ``f0 + (1 - f0) (1 - cos)^5``."""
    m = min(max(1.0 - cos, 0.0), 1.0)
    m2 = m * m
    return f0 + (1.0 - f0) * (m2 * m2 * m)
