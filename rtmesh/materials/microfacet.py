"""The isotropic GGX (Trowbridge-Reitz) microfacet distribution, in the local frame, as the
conductor and dielectric models use it: ``D``, Smith's masking ``G1`` and height-correlated
``G2``, and the density of visible normals (Heitz 2018), whose sampling row
(:func:`rtmesh.materials.metallic_roughness.sample_ggx_visible_normal`) the glTF model shares.

Every function takes ``alpha`` (GGX's width, glTF's roughness squared), already floored at
:data:`MIN_ALPHA`, and takes cosines of either sign (a transmissive model's directions lie on
both sides): masking uses ``|cos|``.

The anisotropic rows (``*_anisotropic``: KHR_materials_anisotropy) take whole local vectors
and two widths, ``alpha_x`` along the frame's x axis and ``alpha_y`` along y (Heitz 2014,
"Understanding the Masking-Shadowing Function in Microfacet-Based BRDFs", eqs. 85-86); with
equal widths they are the isotropic functions.
"""

import math

from rtmesh.core.compiled import row
from rtmesh.materials.metallic_roughness import (MIN_ALPHA, sample_ggx_visible_normal,
                                                 sample_ggx_visible_normal_anisotropic)

# Below this alpha a lobe is handled as a perfect mirror or a smooth interface (a delta
# lobe): D's peak 1 / (pi alpha^2) is then beyond what float64 evaluates reliably near the
# peak (see metallic_roughness.MIN_ALPHA), and the image cannot tell the difference.
SMOOTH_ALPHA = MIN_ALPHA


@row
def distribution(cos_h, alpha):
    """GGX ``D(h)`` per unit projected area (0 below the horizon)."""
    if not cos_h > 0.0:
        return 0.0
    a2 = alpha * alpha
    c2 = cos_h * cos_h
    d = c2 * (a2 - 1.0) + 1.0
    return a2 / (math.pi * d * d)


@row
def smith_lambda(cos, alpha):
    """Smith's ``Lambda(w)`` for GGX."""
    c2 = cos * cos
    if not c2 > 0.0:
        return math.inf
    tan2 = max(0.0, 1.0 - c2) / c2
    return 0.5 * (math.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


@row
def masking(cos, alpha):
    """Smith's ``G1(w) = 1 / (1 + Lambda(w))``."""
    return 1.0 / (1.0 + smith_lambda(cos, alpha))


@row
def masking_shadowing(cos_o, cos_i, alpha):
    """Height-correlated ``G2(wo, wi) = 1 / (1 + Lambda(wo) + Lambda(wi))``."""
    return 1.0 / (1.0 + smith_lambda(cos_o, alpha) + smith_lambda(cos_i, alpha))


@row
def visible_normal_pdf(cos_o, cos_h, o_dot_h, alpha):
    """Density of the normals visible from ``wo``: ``G1(wo) |wo.h| D(h) / |wo.z|``."""
    if cos_o == 0.0:
        return 0.0
    return masking(cos_o, alpha) * abs(o_dot_h) * distribution(cos_h, alpha) / abs(cos_o)


@row
def sample_visible_normal(ox, oy, oz, alpha, u1, u2):
    """A microfacet normal (``h.z >= 0``) drawn from the normals visible from ``wo``, on
    either side (a view from below samples as its mirror image above)."""
    if oz < 0.0:
        return sample_ggx_visible_normal(-ox, -oy, -oz, alpha, u1, u2)
    return sample_ggx_visible_normal(ox, oy, oz, alpha, u1, u2)


@row
def distribution_anisotropic(hx, hy, hz, alpha_x, alpha_y):
    """Anisotropic GGX ``D(h)`` per unit projected area, ``h`` a unit local vector (0 below
    the horizon): ``1 / (pi ax ay ((hx/ax)^2 + (hy/ay)^2 + hz^2)^2)``."""
    if not hz > 0.0:
        return 0.0
    x, y = hx / alpha_x, hy / alpha_y
    d = (x * x + y * y) + hz * hz
    return 1.0 / (math.pi * alpha_x * alpha_y * d * d)


@row
def smith_lambda_anisotropic(wx, wy, wz, alpha_x, alpha_y):
    """Smith's ``Lambda(w)`` of anisotropic GGX for a unit local ``w`` (either side)."""
    z2 = wz * wz
    if not z2 > 0.0:
        return math.inf
    a2 = (alpha_x * alpha_x * wx * wx + alpha_y * alpha_y * wy * wy) / z2
    return 0.5 * (math.sqrt(1.0 + a2) - 1.0)


@row
def masking_shadowing_anisotropic(ox, oy, oz, wx, wy, wz, alpha_x, alpha_y):
    """Height-correlated ``G2`` of anisotropic GGX."""
    return 1.0 / (1.0 + smith_lambda_anisotropic(ox, oy, oz, alpha_x, alpha_y)
                  + smith_lambda_anisotropic(wx, wy, wz, alpha_x, alpha_y))


@row
def masking_anisotropic(ox, oy, oz, alpha_x, alpha_y):
    """Smith's ``G1(w)`` of anisotropic GGX."""
    return 1.0 / (1.0 + smith_lambda_anisotropic(ox, oy, oz, alpha_x, alpha_y))


@row
def sample_visible_normal_anisotropic(ox, oy, oz, alpha_x, alpha_y, u1, u2):
    """:func:`sample_visible_normal` of anisotropic GGX (``wo.z > 0``)."""
    return sample_ggx_visible_normal_anisotropic(ox, oy, oz, alpha_x, alpha_y, u1, u2)
